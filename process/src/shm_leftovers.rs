//! Data segments a failed port creation left in `/dev/shm`. iceoryx2 0.10 creates a
//! publisher's data segment (`shm_open`, `ftruncate`), then maps it; when the mapping fails
//! (an address-space limit, `ulimit -v`) the file stays, owned by no port and removed by
//! nobody: a run under a tight limit left 16 MB in `/dev/shm` each time (issue #39, item 16;
//! docs/security.md, "Limits of the machine").
//!
//! A data segment is `<prefix><root hash>_<port id><data segment suffix>` in `/dev/shm`, and
//! a live port has a tag `<node dir>/<node id>/<prefix><port id><port tag suffix>` from before
//! its data segment exists until after it is gone. A segment without a tag is no port's: it
//! is an orphan, which is what iceoryx2's own cleanup of dead nodes never finds.

use iceoryx2::config::Config;
use std::os::unix::fs::MetadataExt as _;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// Where POSIX shared memory lives on Linux.
const SHM_DIR: &str = "/dev/shm";

/// Removes the data segments of `config` in `/dev/shm` that belong to this user, were
/// changed at or after `since` and have no port tag in any node's directory. Returns the
/// bytes removed (what the failed creation had asked for).
pub fn remove_orphans(config: &Config, since: SystemTime) -> u64 {
    let g = &config.global;
    let prefix = g.prefix.to_string();
    let suffix = g.service.data_segment_suffix.to_string();
    let tag_suffix = g.node.port_tag_suffix.to_string();
    let nodes = PathBuf::from(g.node_dir().to_string());
    let Ok(entries) = std::fs::read_dir(SHM_DIR) else {
        return 0;
    };
    // SAFETY: geteuid cannot fail and touches no memory.
    #[allow(unsafe_code)]
    let me = unsafe { libc::geteuid() };
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(port) = name
            .to_str()
            .and_then(|n| n.strip_prefix(&prefix)?.strip_suffix(&suffix))
            .and_then(|n| n.rsplit('_').next())
            .filter(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
        else {
            continue;
        };
        let Ok(meta) = e.metadata() else { continue };
        let recent = meta.modified().is_ok_and(|t| t >= since);
        if !meta.is_file() || meta.uid() != me || !recent {
            continue;
        }
        let tag = format!("{prefix}{port}{tag_suffix}");
        if !tagged(&nodes, &tag) && std::fs::remove_file(e.path()).is_ok() {
            removed += meta.len();
        }
    }
    removed
}

/// Whether some node's directory under `nodes` holds the port tag `tag`.
fn tagged(nodes: &Path, tag: &str) -> bool {
    let Ok(entries) = std::fs::read_dir(nodes) else {
        // No node directory to look in: keep the segment rather than guess.
        return true;
    };
    entries.flatten().any(|n| n.path().join(tag).exists())
}

/// Why a port's data segment could not be created, after removing what the attempt left
/// (`since`: just before it): its size, and what bounds it — the address-space limit and
/// what it leaves, or the free space of `/dev/shm`. One line, for `cannot create … : <this>`.
pub fn why_no_data_segment(config: &Config, since: SystemTime) -> String {
    let removed = remove_orphans(config, since);
    let size = if removed > 0 {
        format!("its {:.1} MiB of shared memory", removed as f64 / MIB)
    } else {
        "its shared memory".to_string()
    };
    let free = shm_free().map_or(String::new(), |f| {
        format!("; {SHM_DIR} has {:.1} MiB free", f as f64 / MIB)
    });
    match crate::address_space::headroom() {
        Some((limit, left)) => format!(
            "{size} cannot be mapped: {} leaves {:.1} MiB{free}",
            crate::address_space::describe(limit),
            left as f64 / MIB
        ),
        None => format!("{size} cannot be created or mapped{free}"),
    }
}

const MIB: f64 = (1u64 << 20) as f64;

/// Free bytes of the file system of `/dev/shm`.
fn shm_free() -> Option<u64> {
    let path = std::ffi::CString::new(SHM_DIR).ok()?;
    // SAFETY: statvfs fills the struct we own from a NUL-terminated path.
    #[allow(unsafe_code)]
    let st = unsafe {
        let mut st: libc::statvfs = std::mem::zeroed();
        (libc::statvfs(path.as_ptr(), &mut st) == 0).then_some(st)
    }?;
    Some(st.f_bavail.saturating_mul(st.f_frsize))
}

/// The one line for a publisher of `service` that could not be created (`since`: just
/// before the attempt). Only a full service is blamed on other processes (`crowded`: who
/// they would be); a data segment that could not be created or mapped says what bounds it,
/// after its file was removed ([`why_no_data_segment`]).
pub fn publisher_error(
    e: iceoryx2::port::publisher::PublisherCreateError,
    config: &Config,
    since: SystemTime,
    service: &str,
    crowded: &str,
) -> String {
    use iceoryx2::port::publisher::PublisherCreateError as E;
    match e {
        E::ExceedsMaxSupportedPublishers => {
            format!("cannot publish on {service} ({e:?}): {crowded}")
        }
        E::UnableToCreateDataSegment => {
            format!(
                "cannot publish on {service}: {}",
                why_no_data_segment(config, since)
            )
        }
        e => format!("cannot publish on {service} ({e:?})"),
    }
}
