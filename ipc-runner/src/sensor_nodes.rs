//! `demo --sensor-node qemu`: one QEMU Cortex-M4F (`mps2-an386`) per node of the scenario,
//! each running the sensor-node firmware with its UART on a unix socket, which the
//! publisher's gateway (`channel-sim --sensor-node`) connects to (docs/sensor-node.md).
//!
//! The emulators live and die with the demo: each gets SIGKILL from the kernel when the demo
//! goes (`PR_SET_PDEATHSIG`), SIGTERM when the demo ends early, and ends by itself after the
//! gateway's `Finish` otherwise; their sockets are in a directory of their own, removed at the
//! end.

use anyhow::{anyhow, Context, Result};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The sensor nodes' emulators.
#[derive(Debug)]
pub struct QemuNodes {
    children: Vec<Child>,
    dir: PathBuf,
    lines: Vec<String>,
}

/// Where `demo` looks for the node firmware by default (built by `.ci/firmware`, or
/// `cargo build --release --bin sensor-node` in estimator-core/firmware).
pub const DEFAULT_FIRMWARE: &str =
    "estimator-core/firmware/target/thumbv7em-none-eabihf/release/sensor-node";

impl QemuNodes {
    /// Starts `nodes` emulators running `firmware`, QEMU's own messages to
    /// `logs/node-<m>.qemu.log`.
    pub fn start(firmware: &Path, nodes: usize, logs: &Path) -> Result<Self> {
        if !firmware.is_file() {
            return Err(crate::limits::BadInput(format!(
                "--node-firmware {}: no such file; build it with `cargo build --release --bin \
                 sensor-node` in estimator-core/firmware (or run .ci/firmware)",
                firmware.display()
            ))
            .into());
        }
        // Unix socket paths are short (108 bytes): a directory of our own in the temp dir.
        let dir = std::env::temp_dir().join(format!("estpipe-nodes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {dir:?}"))?;
        let mut me = Self {
            children: Vec::with_capacity(nodes),
            dir,
            lines: Vec::with_capacity(nodes),
        };
        for m in 0..nodes {
            let sock = me.dir.join(format!("node-{m}.sock"));
            let _ = std::fs::remove_file(&sock);
            let mut cmd = Command::new("qemu-system-arm");
            cmd.args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
                .args(["-display", "none", "-monitor", "none"])
                .args(["-semihosting-config", "enable=on,target=native"])
                .arg("-chardev")
                .arg(format!(
                    "socket,id=line,path={},server=on,wait=on",
                    sock.display()
                ))
                .args(["-serial", "chardev:line", "-kernel"])
                .arg(firmware)
                .stdin(Stdio::null())
                .stdout(Stdio::null());
            let log = logs.join(format!("node-{m}.qemu.log"));
            match std::fs::File::create(&log) {
                Ok(f) => cmd.stderr(f),
                Err(_) => cmd.stderr(Stdio::null()),
            };
            // SAFETY: prctl(2) in the child between fork and exec, no allocation.
            #[allow(unsafe_code)]
            unsafe {
                use std::os::unix::process::CommandExt;
                cmd.pre_exec(|| {
                    libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                    Ok(())
                });
            }
            let child = cmd.spawn().map_err(|e| {
                anyhow!("cannot start qemu-system-arm for sensor node {m} ({e}); install it (Debian: qemu-system-arm)")
            })?;
            me.children.push(child);
            me.lines.push(format!("unix:{}", sock.display()));
        }
        Ok(me)
    }

    /// The publisher's `--sensor-node` lines, in node order.
    pub fn lines(&self) -> &[String] {
        &self.lines
    }

    /// Waits up to `grace` for every emulator to end by itself (after `Finish`), then ends the
    /// rest; how many ended by themselves with status 0.
    pub fn finish(&mut self, grace: Duration) -> usize {
        let start = Instant::now();
        let mut clean = 0;
        for c in &mut self.children {
            loop {
                match c.try_wait() {
                    Ok(Some(s)) => {
                        clean += usize::from(s.success());
                        break;
                    }
                    Ok(None) if start.elapsed() < grace => {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    _ => break,
                }
            }
        }
        clean
    }
}

impl Drop for QemuNodes {
    fn drop(&mut self) {
        for c in &mut self.children {
            if matches!(c.try_wait(), Ok(None)) {
                let _ = c.kill();
            }
            let _ = c.wait();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
