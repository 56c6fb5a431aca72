//! What every command checks before it works, and the bounds it works within (issue #20;
//! docs/pipeline.md "Exit codes and limits"):
//!
//! * **outputs first** ([`check_output`], [`check_output_dir`]): every file a command will
//!   write is opened for writing (or created and removed again) before any work, so an
//!   unwritable `--json` fails in milliseconds, not after the computation;
//! * **a memory budget** ([`Budget`]): what a command's flags make it hold (eval's per-k
//!   sums over the horizon and its per-run averages, run's trajectory recording, replay's
//!   instants from 1 to the log's last k) is computed from the flags, or while reading, and
//!   refused beyond `--max-memory MIB` (default [`DEFAULT_MAX_MEMORY_MIB`]) with the numbers;
//! * **bounded readers** ([`BoundedLines`]): a line of a CSV or slot log longer than
//!   [`MAX_LINE_BYTES`] or beyond a row limit is an error naming file and line, so
//!   `--input /dev/zero` ends at once instead of growing until memory runs out;
//! * **progress without a terminal** ([`Progress`]): a bar on a terminal, else a line every
//!   few seconds with done/total and ETA, so a long job in a pipe or a log is visibly alive.

use std::io::{BufRead, Read};
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

pub use estpipe_process::flags::BadInput;

/// Default of `--max-memory`, in MiB: a quarter of a small machine's RAM, far above what
/// the papers' experiments need (seed 003's 500 × 300 eval holds a few MiB).
pub const DEFAULT_MAX_MEMORY_MIB: u64 = 2048;

/// Longest line a CSV reader accepts (bytes, without the newline). A slot-log row has
/// 4 + ny ≤ 20 short fields; extra columns are allowed, so the bound is generous.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

const MIB: u64 = 1 << 20;

/// A memory budget (`--max-memory MIB`), never more than this machine has
/// ([`machine_memory`]): a budget above that would let a command allocate what the
/// kernel cannot give, which aborts the process instead of refusing the flags.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// Bytes allowed.
    pub bytes: u64,
    /// Whether `--max-memory` asked for more than the machine has (the message says so).
    pub clamped: bool,
    /// The address-space limit (`ulimit -v`, bytes) when it is what bounds the budget
    /// ([`Budget::within_address_space`]).
    pub address_limit: Option<u64>,
}

impl Budget {
    /// `mib` MiB, or this machine's memory and swap if that is less.
    pub fn mib(mib: u64) -> Self {
        let asked = mib.saturating_mul(MIB);
        match machine_memory() {
            Some(m) if m < asked => Self {
                bytes: m,
                clamped: true,
                address_limit: None,
            },
            _ => Self {
                bytes: asked,
                clamped: false,
                address_limit: None,
            },
        }
    }

    /// The budget within what the address-space limit (`ulimit -v`) leaves this process once
    /// `reserve` bytes are set aside for what the budget does not count (thread stacks, the
    /// estimators' own scratch): beyond it an allocation fails, and Rust aborts the process
    /// where it could have refused the flags. No limit: the budget unchanged. A limit that
    /// leaves no more than `reserve` is refused in one line naming it (`what`: the command).
    pub fn within_address_space(self, reserve: u64, what: &str) -> Result<Self, BadInput> {
        use estpipe_process::address_space as space;
        let Some((limit, left)) = space::headroom() else {
            return Ok(self);
        };
        if left <= reserve {
            return Err(BadInput(format!(
                "{what}: {} leaves {} beside the {} the program has mapped, and it needs at \
                 least {}; raise the limit",
                space::describe(limit),
                human_bytes(left),
                human_bytes(limit - left),
                human_bytes(reserve),
            )));
        }
        Ok(if left - reserve < self.bytes {
            Self {
                bytes: left - reserve,
                clamped: true,
                address_limit: Some(limit),
            }
        } else {
            self
        })
    }

    /// Refuses `need` bytes beyond the budget: `Err` names what was asked (`what`), the
    /// bytes it needs, the budget and the flag that raises it. A `need` that saturated
    /// [`product`] (`u64::MAX`: more than any machine has) is refused whatever the budget.
    pub fn check(&self, what: &str, need: u64) -> Result<(), BadInput> {
        if need < u64::MAX && need <= self.bytes {
            return Ok(());
        }
        let need = if need == u64::MAX {
            "more than 16 EiB".to_string()
        } else {
            format!("about {}", human_bytes(need))
        };
        let budget = human_bytes(self.bytes);
        Err(BadInput(if let Some(limit) = self.address_limit {
            format!(
                "{what} needs {need} of memory; {} leaves {budget} for it (raise the limit)",
                estpipe_process::address_space::describe(limit)
            )
        } else if self.clamped {
            format!(
                "{what} needs {need} of memory; this machine has {budget} (memory and swap, \
                 or the container's limit)"
            )
        } else {
            format!(
                "{what} needs {need} of memory; the budget is {budget} (--max-memory MIB raises it)"
            )
        }))
    }
}

/// This machine's memory and swap in bytes (`MemTotal + SwapTotal` of `/proc/meminfo`), or
/// the container's memory limit when that is less (cgroup v2 `memory.max`, v1
/// `memory.limit_in_bytes`: the kernel ends the process there), read once; `None` where
/// `/proc/meminfo` cannot be read (no cap then).
pub fn machine_memory() -> Option<u64> {
    static MEMORY: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
    *MEMORY.get_or_init(|| {
        let text = std::fs::read_to_string("/proc/meminfo").ok()?;
        let kib = |key: &str| -> Option<u64> {
            let line = text.lines().find(|l| l.starts_with(key))?;
            line[key.len()..]
                .trim()
                .strip_suffix("kB")?
                .trim()
                .parse()
                .ok()
        };
        let total = kib("MemTotal:")?.saturating_add(kib("SwapTotal:").unwrap_or(0));
        let total = total.saturating_mul(1024);
        // "max" (v2) or a page-rounded i64::MAX (v1) mean no limit: `min` keeps the total.
        let limit = [
            "/sys/fs/cgroup/memory.max",
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
        ]
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok()?.trim().parse::<u64>().ok())
        .filter(|&l| l > 0)
        .min();
        let bytes = limit.map_or(total, |l| l.min(total));
        (bytes > 0).then_some(bytes)
    })
}

/// `bytes` in MiB or GiB with three significant digits.
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= (1u64 << 40) as f64 {
        format!("{:.3} TiB", b / (1u64 << 40) as f64)
    } else if b >= (1u64 << 30) as f64 {
        format!("{:.3} GiB", b / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", b / MIB as f64)
    }
}

/// `a · b · …` in u64, saturating (a product of flags must not wrap into a small number).
pub fn product(factors: &[u64]) -> u64 {
    factors.iter().fold(1u64, |p, &f| p.saturating_mul(f))
}

/// The `(flag, path)` pairs of the flags that were given, for [`check_outputs`].
pub fn given<'a>(flags: &[(&'a str, Option<&'a Path>)]) -> Vec<(&'a str, &'a Path)> {
    flags.iter().filter_map(|&(f, p)| Some((f, p?))).collect()
}

/// [`check_output`] for every `(flag, path)` of `outputs`, and that no two of them, and
/// none of them and an input of `inputs`, are the same file: `replay --input log.csv
/// --output log.csv` would replace the log by its estimates, `eval --json r --csv r` keep
/// only the CSV. Compared as files (device and inode when the file exists, so a symlink or
/// `./x` is caught; the canonical directory and name when it does not yet); outputs that
/// are not regular files (`/dev/null`, a FIFO) may be shared.
pub fn check_outputs(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<(), BadInput> {
    for (flag, path) in outputs {
        check_output(flag, path)?;
    }
    let ids = |paths: &[(&str, &Path)]| -> Vec<(String, Option<FileId>)> {
        paths
            .iter()
            .map(|&(flag, path)| (flag.to_string(), FileId::of(path)))
            .collect()
    };
    let (ins, outs) = (ids(inputs), ids(outputs));
    for (i, &(flag, path)) in outputs.iter().enumerate() {
        let Some(id) = &outs[i].1 else { continue };
        if !id.shareable() {
            for (other, other_id) in ins.iter().chain(&outs[..i]) {
                if other_id.as_ref() == Some(id) {
                    let role = if inputs.iter().any(|(f, _)| f == other) {
                        "it would be overwritten"
                    } else {
                        "one would replace the other"
                    };
                    return Err(BadInput(format!(
                        "{flag} {}: the same file as {other} ({role})",
                        path.display()
                    )));
                }
            }
        }
    }
    Ok(())
}

/// What makes two paths one file ([`check_outputs`]).
#[derive(Clone, Debug, PartialEq, Eq)]
enum FileId {
    /// An existing file: device, inode, and whether it is a regular file.
    Inode(u64, u64, bool),
    /// A file not created yet: its canonical directory and its name.
    Path(std::path::PathBuf),
}

impl FileId {
    fn of(path: &Path) -> Option<Self> {
        use std::os::unix::fs::MetadataExt as _;
        if let Ok(m) = std::fs::metadata(path) {
            return Some(Self::Inode(m.dev(), m.ino(), m.is_file()));
        }
        let name = path.file_name()?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        Some(Self::Path(std::fs::canonicalize(dir).ok()?.join(name)))
    }

    /// Device files and FIFOs: writing one twice loses nothing a file would keep.
    fn shareable(&self) -> bool {
        matches!(self, Self::Inode(_, _, false))
    }
}

/// Checks that `path` (the value of `flag`) can be written, before any work: an existing
/// file is opened for writing without truncating it; a missing one is created and removed
/// again (no empty file is left behind if the command fails later).
pub fn check_output(flag: &str, path: &Path) -> Result<(), BadInput> {
    let fail = |why: String| BadInput(format!("{flag} {}: {why}", path.display()));
    if path.as_os_str().is_empty() {
        return Err(fail("empty path".into()));
    }
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(fail("is a directory".into())),
        // Non-blocking: a FIFO without a reader fails at once instead of hanging the check.
        Ok(_) => std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
            .map(drop)
            .map_err(|e| fail(format!("cannot write ({e})"))),
        Err(_) => {
            std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(path)
                .map_err(|e| fail(format!("cannot create ({e})")))?;
            // Created by this check: gone again unless the command writes it.
            let _ = std::fs::remove_file(path);
            Ok(())
        }
    }
}

/// Checks that directory `dir` (the value of `flag`) exists or can be created, and that
/// files can be created in it (it is created if missing: the command fills it).
pub fn check_output_dir(flag: &str, dir: &Path) -> Result<(), BadInput> {
    let fail = |why: String| BadInput(format!("{flag} {}: {why}", dir.display()));
    std::fs::create_dir_all(dir).map_err(|e| fail(format!("cannot create directory ({e})")))?;
    let probe = dir.join(format!(".ipc-runner-write-check-{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(|e| fail(format!("cannot create files in it ({e})")))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// The lines of a text file, each bounded by [`MAX_LINE_BYTES`] and their number by
/// `max_lines`: errors are [`BadInput`] naming the file and the 1-based line.
#[derive(Debug)]
pub struct BoundedLines<R> {
    reader: R,
    file: String,
    max_lines: u64,
    /// Lines read so far (the number of the last line returned).
    pub line: u64,
    buf: Vec<u8>,
}

impl<R: BufRead> BoundedLines<R> {
    /// Lines of `reader`, named `file` in errors, at most `max_lines` of them.
    pub fn new(reader: R, file: &Path, max_lines: u64) -> Self {
        Self {
            reader,
            file: format!("{}", file.display()),
            max_lines,
            line: 0,
            buf: Vec::new(),
        }
    }

    /// The next line's 1-based number and text without its line ending, `None` at the end
    /// of the file.
    pub fn next_line(&mut self) -> Result<Option<(u64, &str)>, BadInput> {
        self.buf.clear();
        let limit = MAX_LINE_BYTES as u64 + 2; // the line, "\r\n"
        let n = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.buf)
            .map_err(|e| {
                BadInput(format!(
                    "{} line {}: cannot read ({e})",
                    self.file,
                    self.line + 1
                ))
            })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        if self.line > self.max_lines {
            return Err(BadInput(format!(
                "{} line {}: more than {} lines (the row limit of the memory budget; \
                 --max-memory MIB raises it, up to this machine's memory)",
                self.file, self.line, self.max_lines
            )));
        }
        while matches!(self.buf.last(), Some(b'\n' | b'\r')) {
            self.buf.pop();
        }
        if self.buf.len() > MAX_LINE_BYTES {
            return Err(BadInput(format!(
                "{} line {}: longer than {MAX_LINE_BYTES} bytes",
                self.file, self.line
            )));
        }
        std::str::from_utf8(&self.buf)
            .map(|s| Some((self.line, s)))
            .map_err(|_| BadInput(format!("{} line {}: not UTF-8 text", self.file, self.line)))
    }
}

/// Progress of a job of `total` units on stderr: indicatif's bar when stderr is a terminal,
/// else a line every `every` (done/total, elapsed, ETA); nothing when `quiet`.
/// Thread-safe: workers call [`Progress::inc`].
#[derive(Debug)]
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    lines: Option<Lines>,
}

#[derive(Debug)]
struct Lines {
    what: String,
    unit: &'static str,
    total: u64,
    every_ns: u64,
    start: Instant,
    done: AtomicU64,
    last_ns: AtomicU64,
}

/// Default interval of the progress lines written when stderr is not a terminal.
pub const PROGRESS_LINE_EVERY: Duration = Duration::from_secs(5);

impl Progress {
    /// Progress of `total` `unit`s of `what`.
    pub fn new(what: String, unit: &'static str, total: u64, quiet: bool, every: Duration) -> Self {
        use std::io::IsTerminal;
        if quiet {
            return Self {
                bar: None,
                lines: None,
            };
        }
        if std::io::stderr().is_terminal() {
            let bar = indicatif::ProgressBar::new(total).with_style(
                indicatif::ProgressStyle::with_template(&format!(
                    "{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
                ))
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_message(what);
            return Self {
                bar: Some(bar),
                lines: None,
            };
        }
        Self {
            bar: None,
            lines: Some(Lines {
                what,
                unit,
                total,
                every_ns: u64::try_from(every.as_nanos()).unwrap_or(u64::MAX).max(1),
                start: Instant::now(),
                done: AtomicU64::new(0),
                last_ns: AtomicU64::new(0),
            }),
        }
    }

    /// `n` more units done.
    pub fn inc(&self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
        let Some(l) = &self.lines else { return };
        let done = l.done.fetch_add(n, Ordering::Relaxed) + n;
        let now = u64::try_from(l.start.elapsed().as_nanos()).unwrap_or(u64::MAX);
        let last = l.last_ns.load(Ordering::Relaxed);
        // One worker wins the interval and prints; the others carry on.
        if now.saturating_sub(last) >= l.every_ns
            && l.last_ns
                .compare_exchange(last, now, Ordering::Relaxed, Ordering::Relaxed)
                .is_ok()
        {
            let secs = now as f64 * 1e-9;
            let eta = if done > 0 {
                secs * (l.total.saturating_sub(done)) as f64 / done as f64
            } else {
                f64::NAN
            };
            estpipe_process::errln!(
                "{}: {done}/{} {} ({:.1} %), {secs:.0} s elapsed, ETA {eta:.0} s",
                l.what,
                l.total,
                l.unit,
                100.0 * done as f64 / l.total.max(1) as f64
            );
        }
    }

    /// Removes the bar (the lines need no clean-up).
    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_are_checked_without_leaving_files_behind() {
        let dir = std::env::temp_dir().join(format!("limits-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let new = dir.join("new.json");
        check_output("--json", &new).unwrap();
        assert!(!new.exists(), "the check left {new:?} behind");
        std::fs::write(&new, "keep").unwrap();
        check_output("--json", &new).unwrap();
        assert_eq!(std::fs::read_to_string(&new).unwrap(), "keep");
        let e = check_output("--json", &dir.join("missing/x.json")).unwrap_err();
        assert!(
            e.0.starts_with("--json ") && e.0.contains("cannot create"),
            "{e}"
        );
        assert!(check_output("--csv", &dir)
            .unwrap_err()
            .0
            .contains("is a directory"));
        // A FIFO nobody reads: refused at once, not a hang.
        let fifo = dir.join("fifo");
        if std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success())
        {
            let e = check_output("--json", &fifo).unwrap_err();
            assert!(e.0.contains("cannot write"), "{e}");
            std::fs::remove_file(&fifo).unwrap();
        }
        check_output_dir("--out", &dir.join("sub")).unwrap();
        assert_eq!(std::fs::read_dir(dir.join("sub")).unwrap().count(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn outputs_are_no_input_and_not_each_other() {
        let dir = std::env::temp_dir().join(format!("limits-same-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let input = dir.join("in.csv");
        std::fs::write(&input, "k\n").unwrap();
        let link = dir.join("link.csv");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let fresh = dir.join("out.json");
        let inputs = [("--input", input.as_path())];
        // The input itself, through a symlink, through `dir/../dir/`.
        let roundabout = dir.join("..").join(dir.file_name().unwrap()).join("in.csv");
        for out in [&input, &link, &roundabout] {
            let e = check_outputs(&[("--output", out)], &inputs).unwrap_err().0;
            assert!(
                e.contains("the same file as --input") && e.contains("overwritten"),
                "{e}"
            );
        }
        // Two outputs, neither existing yet.
        let e = check_outputs(
            &[("--json", &fresh), ("--csv", &dir.join("./out.json"))],
            &[],
        )
        .unwrap_err()
        .0;
        assert!(
            e.starts_with("--csv ") && e.contains("same file as --json"),
            "{e}"
        );
        assert!(!fresh.exists(), "the check left {fresh:?} behind");
        // Distinct files, and /dev/null twice, pass.
        check_outputs(
            &[("--json", &fresh), ("--csv", &dir.join("out.csv"))],
            &inputs,
        )
        .unwrap();
        let null = Path::new("/dev/null");
        check_outputs(&[("--json", null), ("--csv", null)], &[]).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn budget_names_the_numbers_and_the_flag() {
        let b = Budget::mib(1);
        b.check("x", 1 << 20).unwrap();
        let e = b.check("--steps 5", (1 << 20) + 1).unwrap_err().0;
        assert!(e.contains("--steps 5") && e.contains("1.0 MiB") && e.contains("--max-memory"));
        assert_eq!(product(&[u64::MAX, 2]), u64::MAX);
    }

    #[test]
    fn no_budget_exceeds_the_machine_and_a_saturated_need_is_refused() {
        // The helper-found abort: `--max-memory 18446744073709551615` let a 16 GB
        // allocation through on a machine with less.
        let huge = Budget::mib(u64::MAX);
        let machine = machine_memory().expect("/proc/meminfo on Linux");
        assert_eq!((huge.bytes, huge.clamped), (machine, true));
        let e = huge.check("--steps 9", machine + 1).unwrap_err().0;
        assert!(e.contains("this machine has"), "{e}");
        // A product that saturated stands for more than any machine: refused even by a
        // budget of u64::MAX bytes.
        let all = Budget {
            bytes: u64::MAX,
            clamped: false,
            address_limit: None,
        };
        let e = all.check("--particles 18446744073709551615", product(&[u64::MAX, 2]));
        assert!(e.unwrap_err().0.contains("more than 16 EiB"));
    }

    #[test]
    fn lines_are_bounded_in_length_and_number() {
        let p = Path::new("f.csv");
        let mut l = BoundedLines::new(&b"a\r\nb\n\nc"[..], p, 10);
        let mut got = Vec::new();
        while let Some((n, s)) = l.next_line().unwrap() {
            got.push(format!("{n}:{s}"));
        }
        assert_eq!(got, ["1:a", "2:b", "3:", "4:c"]);
        let long = vec![b'0'; MAX_LINE_BYTES + 1];
        let e = BoundedLines::new(&long[..], p, 10)
            .next_line()
            .unwrap_err()
            .0;
        assert_eq!(
            e,
            format!("f.csv line 1: longer than {MAX_LINE_BYTES} bytes")
        );
        let exact = vec![b'0'; MAX_LINE_BYTES];
        assert!(BoundedLines::new(&exact[..], p, 10).next_line().is_ok());
        let mut l = BoundedLines::new(&b"a\nb\nc\n"[..], p, 2);
        l.next_line().unwrap();
        l.next_line().unwrap();
        assert!(l
            .next_line()
            .unwrap_err()
            .0
            .contains("line 3: more than 2 lines"));
    }
}
