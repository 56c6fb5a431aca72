//! Shared helpers of the pipeline tests: unique service prefixes, child processes that are
//! killed when a test fails, and dead-node cleanup.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The binary with the product's subcommands.
pub fn node_exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_pipeline-node"))
}

/// A service prefix no other test (or parallel test run) uses: pid + test name + counter.
pub fn prefix(test: &str) -> String {
    format!(
        "estpipe-test-{}-{test}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::SeqCst)
    )
}

/// A scratch directory for one test.
pub fn scratch(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(prefix(test));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A child process, killed (SIGKILL) on drop unless it has been waited for.
pub struct Proc {
    pub child: Option<Child>,
    pub stderr: PathBuf,
    pub stdout: PathBuf,
    pub name: String,
}

impl Proc {
    /// Starts `pipeline-node <args>` with output captured to files in `dir`.
    pub fn start(dir: &Path, name: &str, args: &[&str]) -> Self {
        Self::start_program(dir, name, &node_exe(), args)
    }

    /// Starts `program <args>` (e.g. a Python client) with output captured to files in `dir`.
    pub fn start_program(dir: &Path, name: &str, program: &Path, args: &[&str]) -> Self {
        Self::spawn(dir, name, Command::new(program).args(args), None)
    }

    /// Starts `pipeline-node <args>` in `dir` (relative paths are `dir`'s) with `env` added,
    /// and stdout to `stdout` instead of a file of `dir` when given (`/dev/full`).
    pub fn start_in(
        dir: &Path,
        name: &str,
        args: &[&str],
        env: &[(&str, &str)],
        stdout: Option<std::fs::File>,
    ) -> Self {
        let mut cmd = Command::new(node_exe());
        cmd.args(args).current_dir(dir).envs(env.iter().copied());
        Self::spawn(dir, name, &mut cmd, stdout)
    }

    fn spawn(dir: &Path, name: &str, cmd: &mut Command, out: Option<std::fs::File>) -> Self {
        let stdout = dir.join(format!("{name}.out"));
        let stderr = dir.join(format!("{name}.err"));
        let out = out.unwrap_or_else(|| std::fs::File::create(&stdout).unwrap());
        // Quiet iceoryx2 unless the caller set a level of its own.
        if !cmd.get_envs().any(|(k, _)| k == "IOX2_LOG_LEVEL") {
            cmd.env("IOX2_LOG_LEVEL", "Error");
        }
        let child = cmd
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(std::fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap_or_else(|e| panic!("start {:?}: {e}", cmd.get_program()));
        Self {
            child: Some(child),
            stderr,
            stdout,
            name: name.to_string(),
        }
    }

    pub fn pid(&self) -> i32 {
        self.child.as_ref().unwrap().id() as i32
    }

    /// Sends `sig` (e.g. `libc::SIGKILL`).
    pub fn signal(&self, sig: i32) {
        // SAFETY: kill(2) on our own child's pid.
        #[allow(unsafe_code)]
        let rc = unsafe { libc::kill(self.pid(), sig) };
        assert_eq!(rc, 0, "kill {}", self.name);
    }

    /// Waits until the child catches `sig` (its handler is installed: `SigCgt` in
    /// `/proc/<pid>/status`), so a signal sent next is handled, not the default action
    /// (panics after `secs`).
    pub fn wait_for_handler(&self, sig: i32, secs: u64) {
        let start = Instant::now();
        let bit = 1u64 << (sig - 1);
        loop {
            let status =
                std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap_or_default();
            let caught = status
                .lines()
                .find_map(|l| l.strip_prefix("SigCgt:"))
                .and_then(|h| u64::from_str_radix(h.trim(), 16).ok())
                .unwrap_or(0);
            if caught & bit != 0 {
                return;
            }
            assert!(
                start.elapsed() < Duration::from_secs(secs),
                "{} did not install a handler for signal {sig} within {secs} s\nstderr:\n{}",
                self.name,
                self.err()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits for exit (panics after `secs`, killing the child).
    pub fn wait(&mut self, secs: u64) -> ExitStatus {
        let mut c = self.child.take().expect("not yet waited");
        let start = Instant::now();
        loop {
            if let Some(s) = c.try_wait().unwrap() {
                return s;
            }
            if start.elapsed() > Duration::from_secs(secs) {
                let _ = c.kill();
                let _ = c.wait();
                panic!(
                    "{} did not finish within {secs} s\nstderr:\n{}",
                    self.name,
                    self.err()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    pub fn err(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }

    pub fn out(&self) -> String {
        std::fs::read_to_string(&self.stdout).unwrap_or_default()
    }

    /// Polls stderr until it contains `needle` (panics after `secs`).
    pub fn wait_for_stderr(&self, needle: &str, secs: u64) {
        let start = Instant::now();
        while !self.err().contains(needle) {
            assert!(
                start.elapsed() < Duration::from_secs(secs),
                "{}: {needle:?} not seen within {secs} s; stderr:\n{}",
                self.name,
                self.err()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
        cleanup_dead_nodes();
    }
}

/// Removes what killed processes left in shared memory.
pub fn cleanup_dead_nodes() {
    use iceoryx2::prelude::*;
    set_log_level(LogLevel::Error);
    if let Ok(node) = NodeBuilder::new().create::<ipc::Service>() {
        let _ = node.try_cleanup_dead_nodes();
    }
}

/// Reads a run report written with `--json`.
pub fn report(path: &Path) -> serde_json::Value {
    let s = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read report {path:?}: {e}"));
    serde_json::from_str(&s).unwrap()
}

/// Reads a numeric CSV with a header: (header, rows).
pub fn csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let s = std::fs::read_to_string(path).unwrap();
    let mut lines = s.lines();
    let head = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| {
            l.split(',')
                .map(|v| {
                    if v.is_empty() {
                        f64::NAN
                    } else {
                        v.parse().unwrap()
                    }
                })
                .collect()
        })
        .collect();
    (head, rows)
}

/// Starts `channel-sim` publishing preset `scenario` under `prefix`: `steps` instants at
/// `rate` Hz.
pub fn start_channel_sim(dir: &Path, prefix: &str, scenario: &str, steps: u32, rate: u32) -> Proc {
    let (steps, rate) = (steps.to_string(), rate.to_string());
    Proc::start(
        dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            scenario,
            "--prefix",
            prefix,
            "--rate",
            &rate,
            "--steps",
            &steps,
        ],
    )
}

/// What `run_loop` needs for preset `scenario` over `steps` instants (seed 0, run 0).
pub struct LoopSetup {
    /// Quiet arguments on the prefix, with a slot queue long enough for the whole stream
    /// (an IPC loss would change what the estimators compute).
    pub args: ipc_runner::run::RunArgs,
    pub nx: usize,
    pub nodes: u8,
    pub ny: u8,
    pub spec: std::sync::Arc<estpipe_spec::EstimatorSpec>,
    pub make: ipc_runner::run::select::EstimatorFactory,
}

impl LoopSetup {
    /// Runs the real-time loop in this thread with these arguments and estimators.
    pub fn run(
        &self,
        hooks: ipc_runner::run::Hooks<'_>,
    ) -> anyhow::Result<(ipc_runner::run::RunReport, ipc_runner::run::Trajectories)> {
        ipc_runner::run::run_loop(&self.args, &self.spec, &self.make, hooks)
    }
}

pub fn loop_setup(scenario: &str, prefix: &str, steps: u32) -> LoopSetup {
    use ipc_runner::run::select;
    let sc = channel_sim::scenario::resolve(scenario, None).unwrap();
    let (nx, nodes, ny) = (sc.nx(), sc.nodes() as u8, sc.ny() as u8);
    let exp = select::Experiment {
        seed: 0,
        run: 0,
        horizon: steps,
    };
    let source = std::sync::Arc::new(ipc_runner::source::Source::of_scenario(&*sc, 0, 0));
    let spec = std::sync::Arc::clone(&source.spec);
    let make = select::estimators(source, &[], exp).unwrap();
    let mut args = ipc_runner::run::RunArgs::new(scenario, prefix);
    args.quiet = true;
    args.steps = steps;
    args.buffer = 4096;
    // A test whose publisher never comes ends (`run` alone waits for ever by default).
    args.connect_timeout = 30.0;
    LoopSetup {
        args,
        nx,
        nodes,
        ny,
        spec,
        make,
    }
}
