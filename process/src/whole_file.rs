//! A report file written whole or not at all. A full disk used to leave the run's `--json`
//! at 0 bytes, or cut mid-object, beside a run that computed everything (issue #39, item 16;
//! docs/security.md, "Limits of the machine"): a reader of the file must see the old
//! content or the new one, never a part.

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Writes `text` to `path`: into a file beside it, synced, then renamed over it. A path that
/// is not a regular file (a FIFO, a device such as `/dev/stdout`, a symlink) is written in
/// place, never replaced; so is a file in a directory where no file can be created (its
/// own permissions allow writing it). The temporary file is removed when anything fails.
/// The error is the system's; the caller names the file.
pub fn write(path: &Path, text: &str) -> std::io::Result<()> {
    let regular = std::fs::symlink_metadata(path).map_or(true, |m| m.file_type().is_file());
    if !regular {
        return std::fs::write(path, text);
    }
    let tmp = temporary(path);
    let mut file = match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            return std::fs::write(path, text);
        }
        Err(e) => return Err(e),
    };
    let written = file
        .write_all(text.as_bytes())
        .and_then(|()| file.sync_all())
        .and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// `<path>.<pid>.tmp`, in the same directory (a rename never crosses file systems).
fn temporary(path: &Path) -> PathBuf {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".{}.tmp", std::process::id()));
    PathBuf::from(tmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("whole-file-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn replaces_a_file_and_leaves_no_temporary() {
        let d = dir("replace");
        let p = d.join("r.json");
        std::fs::write(&p, "old").unwrap();
        write(&p, "new\n").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new\n");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_device_is_written_in_place_and_its_error_comes_back() {
        write(Path::new("/dev/null"), "x").unwrap();
        let e = write(Path::new("/dev/full"), "x").unwrap_err();
        assert_eq!(e.raw_os_error(), Some(libc::ENOSPC), "{e}");
    }
}
