//! Every command the README and docs/ give runs verbatim from the repository root (issue #38).
//!
//! The test reads every tracked Markdown file (README.md first), takes each fenced block whose
//! info string is `sh`, and runs it with `bash -euo pipefail` from the root of a fresh copy of
//! the working tree (the tracked and untracked, not ignored, files; no `out/`, no `.venv`), in
//! document order, every background job waited for and required to succeed. The copy's
//! `target/` is a directory of its own kept between runs (`target/tmp/docs-test/target`), so
//! the first run builds what a fresh clone builds, by the docs' own commands, and those builds
//! never touch the tree's target directory (whose binaries other tests run). A `console` block
//! (`$ command` lines, each followed by its output) is run and its output compared.
//!
//! A block is marked by an HTML comment on the line before its fence (invisible on GitHub):
//! - `<!-- docs-test: skip REASON -->`: not run (another host, a maintenance command that
//!   rewrites committed files, an install that needs root);
//! - `<!-- docs-test: slow REASON -->`: run only with `ESTPIPE_DOCS_SLOW=1` (a skip line
//!   otherwise);
//! - `<!-- docs-test: needs python -->` / `needs qemu`: skipped with one line where the tool is
//!   absent, unless CI asks for it (`ESTPIPE_PYTHON` set, `REQUIRE_QEMU=1`).
//!
//! Items combine with `;`. A line that is the README's own test command is not run (it is what
//! runs this test). Every block, run or not, is also checked statically: no bare `ipc-runner`
//! or `channel-sim` (not on PATH after the README's build), and every `--flag` given to an
//! `ipc-runner` subcommand is in that subcommand's `--help`.
//!
//! At the end the test prints each block's wall and CPU seconds (children's rusage): on a fresh
//! `target/tmp/docs-test/target` the README's first block is the first demo build, the figure
//! the README states.

#[path = "pipeline_common.rs"]
mod common;
#[path = "firmware_qemu/qemu.rs"]
#[allow(dead_code)]
mod qemu;
#[path = "skip_log.rs"]
mod skip_log;

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The README's test command: the block line that starts with it is what runs this test.
const TEST_COMMAND: &str = "cargo test --workspace --release";

/// How long one block may take: a cold build of the default feature set on a loaded 2-core
/// machine is the longest (about 5 min), the firmware's all-binaries build next.
const BLOCK_TIMEOUT: Duration = Duration::from_secs(1200);

#[derive(Debug, Clone, PartialEq)]
enum Mark {
    Run,
    Skip(String),
    Slow(String),
}

#[derive(Debug, Clone)]
struct Block {
    file: String,
    line: usize,
    console: bool,
    mark: Mark,
    needs: Vec<String>,
    text: String,
}

impl Block {
    fn name(&self) -> String {
        format!("{}:{}", self.file, self.line)
    }
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The directive on the line before a fence, if any: `<!-- docs-test: ITEM; ITEM -->`.
fn directive(prev: &str, file: &str, line: usize) -> (Mark, Vec<String>) {
    let mut mark = Mark::Run;
    let mut needs = Vec::new();
    let Some(body) = prev
        .trim()
        .strip_prefix("<!-- docs-test:")
        .and_then(|s| s.strip_suffix("-->"))
    else {
        return (mark, needs);
    };
    for item in body.split(';').map(str::trim).filter(|s| !s.is_empty()) {
        let (word, rest) = item.split_once(' ').unwrap_or((item, ""));
        match word {
            "skip" => mark = Mark::Skip(rest.trim().to_string()),
            "slow" => mark = Mark::Slow(rest.trim().to_string()),
            "needs" => needs.extend(rest.split_whitespace().map(String::from)),
            _ => panic!("{file}:{line}: unknown docs-test directive `{item}`"),
        }
    }
    for n in &needs {
        assert!(
            ["python", "qemu"].contains(&n.as_str()),
            "{file}:{line}: unknown need `{n}` (python, qemu)"
        );
    }
    (mark, needs)
}

/// The `sh` and `console` blocks of one Markdown file, in order.
fn blocks_of(file: &str, text: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i];
        let Some(info) = l.strip_prefix("```") else {
            i += 1;
            continue;
        };
        let info = info.trim();
        let start = i;
        let mut body = Vec::new();
        i += 1;
        while i < lines.len() && !lines[i].starts_with("```") {
            body.push(lines[i]);
            i += 1;
        }
        i += 1;
        if info != "sh" && info != "console" {
            continue;
        }
        let prev = if start > 0 { lines[start - 1] } else { "" };
        let (mark, needs) = directive(prev, file, start + 1);
        out.push(Block {
            file: file.to_string(),
            line: start + 1,
            console: info == "console",
            mark,
            needs,
            text: body.join("\n"),
        });
    }
    out
}

/// The tracked Markdown files, README.md first, then by path.
fn documents(root: &Path) -> Vec<String> {
    let out = Command::new("git")
        .args(["ls-files", "-co", "--exclude-standard", "*.md"])
        .current_dir(root)
        .output()
        .expect("git ls-files");
    assert!(out.status.success(), "git ls-files failed");
    let mut files: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter(|f| !f.contains("node_modules/"))
        .map(String::from)
        .collect();
    files.sort_by_key(|f| (f != "README.md", f.clone()));
    files
}

/// The shell commands of a block: continuation lines joined, comments dropped, split at
/// `&&`, `||`, `;`, `|` and `&`, each as its words.
fn commands(text: &str) -> Vec<Vec<String>> {
    let joined = text.replace("\\\n", " ");
    let mut out = Vec::new();
    for line in joined.lines() {
        let line = match line.find(" #") {
            Some(p) => &line[..p],
            None => line,
        };
        if line.trim_start().starts_with('#') {
            continue;
        }
        let line = line.trim_start_matches("$ ");
        for part in line.split(['&', ';', '|', '(', ')']) {
            let words: Vec<String> = part.split_whitespace().map(String::from).collect();
            if !words.is_empty() {
                out.push(words);
            }
        }
    }
    out
}

/// The subcommand and flags of an `ipc-runner` invocation (`target/release/ipc-runner SUB …`
/// or `cargo run … -p ipc-runner … -- SUB …`), if the command is one.
fn ipc_runner_args(words: &[String]) -> Option<(String, Vec<String>)> {
    let rest: &[String] = if words[0] == "ipc-runner" || words[0].ends_with("/ipc-runner") {
        &words[1..]
    } else if words[0] == "cargo"
        && words.get(1).is_some_and(|w| w == "run")
        && words
            .windows(2)
            .any(|w| w[0] == "-p" && w[1] == "ipc-runner")
    {
        let dd = words.iter().position(|w| w == "--")?;
        &words[dd + 1..]
    } else {
        return None;
    };
    let sub = rest.first().filter(|s| !s.starts_with('-'))?.clone();
    let flags = rest[1..]
        .iter()
        .filter(|w| w.starts_with("--") && w.len() > 2)
        .map(|w| w.split('=').next().unwrap().to_string())
        .collect();
    Some((sub, flags))
}

/// What is wrong with a block's commands without running them.
fn static_problems(block: &Block, help: &mut dyn FnMut(&str) -> String) -> Vec<String> {
    let mut problems = Vec::new();
    for words in commands(&block.text) {
        let first = words[0].as_str();
        if first == "ipc-runner" || first == "channel-sim" {
            problems.push(format!(
                "calls a bare `{first}`, which is not on PATH after the README's build \
                 (target/release/ipc-runner)"
            ));
        }
        if let Some((sub, flags)) = ipc_runner_args(&words) {
            let text = help(&sub);
            for f in flags {
                if f == "--help" {
                    continue;
                }
                let found = text.match_indices(&f).any(|(p, _)| {
                    !text[p + f.len()..]
                        .chars()
                        .next()
                        .is_some_and(|c| c.is_ascii_alphanumeric() || c == '-')
                });
                if !found {
                    problems.push(format!("`ipc-runner {sub}` has no flag {f}"));
                }
            }
        }
    }
    problems
}

/// Copies the working tree's tracked and untracked, not ignored, files to `to`.
fn copy_tree(root: &Path, to: &Path) {
    let out = Command::new("git")
        .args(["ls-files", "-z", "-co", "--exclude-standard"])
        .current_dir(root)
        .output()
        .expect("git ls-files");
    assert!(out.status.success());
    for f in out.stdout.split(|b| *b == 0).filter(|f| !f.is_empty()) {
        let f = std::str::from_utf8(f).unwrap();
        let src = root.join(f);
        // A file deleted in the working tree is still listed by ls-files.
        let Ok(meta) = std::fs::symlink_metadata(&src) else {
            continue;
        };
        let dst = to.join(f);
        std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
        if meta.file_type().is_symlink() {
            std::os::unix::fs::symlink(std::fs::read_link(&src).unwrap(), &dst).unwrap();
        } else {
            std::fs::copy(&src, &dst).unwrap();
        }
    }
}

/// CPU seconds of this process's waited-for descendants so far.
fn children_cpu_s() -> f64 {
    // SAFETY: getrusage only writes the struct it is given.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(ru.ru_utime) + tv(ru.ru_stime)
}

/// The environment a person's shell has: none of the variables cargo sets for a test.
fn shell_env(cmd: &mut Command) {
    for (k, _) in std::env::vars_os() {
        let k = k.to_string_lossy().to_string();
        let cargo_own = k.starts_with("CARGO_")
            && !matches!(k.as_str(), "CARGO_HOME" | "CARGO_TERM_COLOR")
            && !k.starts_with("CARGO_NET_")
            && !k.starts_with("CARGO_HTTP_")
            && !k.starts_with("CARGO_REGISTRIES_");
        if cargo_own
            || matches!(
                k.as_str(),
                "CARGO" | "OUT_DIR" | "MAKEFLAGS" | "MFLAGS" | "RUST_TEST_THREADS"
            )
        {
            cmd.env_remove(&k);
        }
    }
}

/// Runs `script` with bash in `dir`, in a process group of its own that is killed when the
/// script ends or times out. Returns (success, output).
fn run_script(dir: &Path, script: &str, log: &Path) -> (bool, String) {
    let file = std::fs::File::create(log).unwrap();
    let mut cmd = Command::new("bash");
    cmd.args(["-c", script])
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(file.try_clone().unwrap())
        .stderr(file)
        .process_group(0);
    shell_env(&mut cmd);
    let mut child = cmd.spawn().expect("bash");
    let pgid = child.id() as i32;
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if t0.elapsed() > BLOCK_TIMEOUT {
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    // Whatever the block left behind (a server it started without waiting for it).
    // SAFETY: kill(2) with a negative pid signals that process group and nothing else.
    unsafe { libc::kill(-pgid, libc::SIGKILL) };
    let _ = child.wait();
    let mut out = String::new();
    let _ = std::fs::File::open(log).and_then(|mut f| f.read_to_string(&mut out));
    match status {
        Some(s) => (s.success(), out),
        None => (
            false,
            format!("{out}\n(timed out after {} s)", BLOCK_TIMEOUT.as_secs()),
        ),
    }
}

/// The script a `sh` block runs as: strict, the test command left out, and every background
/// job waited for and required to succeed.
fn script_of(block: &Block) -> String {
    let body: Vec<String> = block
        .text
        .lines()
        .map(|l| {
            if l.trim_start().starts_with(TEST_COMMAND) {
                format!("true # not run: the test command, which runs this test: {l}")
            } else {
                l.to_string()
            }
        })
        .collect();
    format!(
        "set -euo pipefail\n{}\nfor j in $(jobs -p); do wait \"$j\"; done\n",
        body.join("\n")
    )
}

/// Runs a `console` block: each `$ command` and the output it must print.
fn run_console(block: &Block, dir: &Path, log: &Path) -> Result<(), String> {
    let mut entries: Vec<(String, Vec<String>)> = Vec::new();
    for l in block.text.lines() {
        if let Some(c) = l.strip_prefix("$ ") {
            entries.push((c.to_string(), Vec::new()));
        } else if let Some(e) = entries.last_mut() {
            e.1.push(l.to_string());
        } else {
            return Err(format!("output line before any `$ ` command: {l}"));
        }
    }
    for (c, expected) in entries {
        let (ok, out) = run_script(dir, &format!("set -euo pipefail\n{c}"), log);
        if !ok {
            return Err(format!("`{c}` failed:\n{}", tail(&out, 20)));
        }
        let got: Vec<&str> = out.lines().collect();
        if got != expected.iter().map(String::as_str).collect::<Vec<_>>() {
            return Err(format!(
                "`{c}` printed\n{}\ninstead of\n{}",
                out.trim_end(),
                expected.join("\n")
            ));
        }
    }
    Ok(())
}

fn tail(s: &str, n: usize) -> String {
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// Why a need is not met here, or None; panics where CI requires it.
fn unmet(need: &str) -> Option<String> {
    match need {
        "qemu" => {
            let why = qemu::missing_tools()?;
            assert!(!qemu::require_qemu(), "REQUIRE_QEMU=1 but {why}");
            Some(format!("{why} (set REQUIRE_QEMU=1 to fail)"))
        }
        "python" => {
            // The blocks make their own venv from PyPI; CI says it has Python and the
            // registry by setting ESTPIPE_PYTHON (.ci/setup).
            if std::env::var_os("ESTPIPE_PYTHON").is_some() {
                None
            } else {
                Some(
                    "ESTPIPE_PYTHON not set: the block makes a venv from PyPI (.ci/setup and \
                     CI set it)"
                        .into(),
                )
            }
        }
        _ => unreachable!(),
    }
}

#[test]
fn docs_commands_run_verbatim() {
    let root = repo_root();
    if Command::new("git").arg("--version").output().is_err() {
        skip_log::skipped(
            &skip_log::current_test("docs_commands"),
            "git not found (the test copies the tracked files)",
        );
        return;
    }
    let mut blocks = Vec::new();
    for f in documents(&root) {
        let text = std::fs::read_to_string(root.join(&f)).unwrap();
        blocks.extend(blocks_of(&f, &text));
    }
    assert!(
        blocks.len() >= 20,
        "only {} sh/console blocks found",
        blocks.len()
    );

    // Static checks of every block, run or not.
    let exe = common::node_exe();
    let mut helps = std::collections::HashMap::new();
    let mut help = |sub: &str| -> String {
        helps
            .entry(sub.to_string())
            .or_insert_with(|| {
                let o = Command::new(&exe).args([sub, "--help"]).output().unwrap();
                String::from_utf8_lossy(&o.stdout).to_string()
            })
            .clone()
    };
    let mut failures = Vec::new();
    for b in &blocks {
        for p in static_problems(b, &mut help) {
            failures.push(format!("{}: {p}", b.name()));
        }
    }

    // A fresh copy of the tree; its target directory kept between runs.
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("docs-test");
    let tree = base.join("tree");
    let target = base.join("target");
    let logs = base.join("logs");
    let _ = std::fs::remove_dir_all(&tree);
    let _ = std::fs::remove_dir_all(&logs);
    std::fs::create_dir_all(&tree).unwrap();
    std::fs::create_dir_all(&target).unwrap();
    std::fs::create_dir_all(&logs).unwrap();
    let fresh = std::fs::read_dir(&target).unwrap().next().is_none();
    copy_tree(&root, &tree);
    std::os::unix::fs::symlink(&target, tree.join("target")).unwrap();
    // The firmware's own target directory is shared with the tree's: its builds are the same
    // whatever the host features (cargo's fingerprints do not hold the checkout's path), and
    // CI's `.ci/firmware` has built it already.
    let fw = Path::new("estimator-core/firmware/target");
    std::fs::create_dir_all(root.join(fw)).unwrap();
    std::os::unix::fs::symlink(root.join(fw), tree.join(fw)).unwrap();

    let slow = std::env::var("ESTPIPE_DOCS_SLOW").is_ok_and(|v| v == "1");
    let mut timings = Vec::new();
    let (mut ran, mut skipped) = (0, 0);
    for b in &blocks {
        let why = match &b.mark {
            Mark::Skip(_) => {
                skipped += 1;
                continue;
            }
            Mark::Slow(r) if !slow => Some(format!("slow ({r}): set ESTPIPE_DOCS_SLOW=1")),
            _ => b.needs.iter().find_map(|n| unmet(n)),
        };
        if let Some(why) = why {
            skip_log::skipped(&format!("docs_commands_run_verbatim {}", b.name()), &why);
            skipped += 1;
            continue;
        }
        let log = logs.join(format!("{}-{}.log", b.file.replace('/', "_"), b.line));
        let (t0, c0) = (Instant::now(), children_cpu_s());
        let result = if b.console {
            run_console(b, &tree, &log)
        } else {
            let (ok, out) = run_script(&tree, &script_of(b), &log);
            if ok {
                Ok(())
            } else {
                Err(format!("failed:\n{}", tail(&out, 25)))
            }
        };
        let (wall, cpu) = (t0.elapsed().as_secs_f64(), children_cpu_s() - c0);
        eprintln!(
            "docs: {} {} in {wall:.1} s wall, {cpu:.1} CPU-s",
            b.name(),
            if result.is_ok() { "ran" } else { "FAILED" }
        );
        timings.push(format!("{},{wall:.1},{cpu:.1}", b.name()));
        ran += 1;
        if let Err(e) = result {
            failures.push(format!("{} {e}\n(log: {})", b.name(), log.display()));
        }
    }
    let _ = std::fs::write(
        base.join("timings.csv"),
        format!(
            "# block,wall_s,cpu_s (children's rusage){}\n{}\n",
            if fresh {
                "; the target directory was empty"
            } else {
                ""
            },
            timings.join("\n")
        ),
    );
    eprintln!(
        "docs: {ran} blocks ran, {skipped} not run (marked skip, slow or needing a tool); \
         timings in {}",
        base.join("timings.csv").display()
    );
    assert!(
        failures.is_empty(),
        "{} problem(s) with the docs' commands:\n\n{}",
        failures.len(),
        failures.join("\n\n")
    );
}

#[test]
fn the_parser_finds_flags_and_bare_commands() {
    let b = Block {
        file: "x.md".into(),
        line: 1,
        console: false,
        mark: Mark::Run,
        needs: vec![],
        text: "ipc-runner run --scenario linear &\n\
               target/release/ipc-runner eval --scenario occlusion \\\n    --runs 5 --bogus=3\n\
               cargo run --release -p ipc-runner -- demo --steps 5 # --not-a-flag\n"
            .into(),
    };
    let mut asked = Vec::new();
    let mut help = |sub: &str| {
        asked.push(sub.to_string());
        "  --scenario <S>\n  --runs <N>\n  --steps <N>\n  --steps-extra\n".to_string()
    };
    let p = static_problems(&b, &mut help);
    assert_eq!(asked, ["run", "eval", "demo"]);
    assert_eq!(p.len(), 2, "{p:?}");
    assert!(p[0].contains("bare `ipc-runner`"), "{p:?}");
    assert!(p[1].contains("no flag --bogus"), "{p:?}");
    let (m, n) = directive("<!-- docs-test: slow builds zenoh; needs qemu -->", "x", 1);
    assert_eq!(m, Mark::Slow("builds zenoh".into()));
    assert_eq!(n, ["qemu"]);
}
