//! The QEMU side of the firmware check: whether the tools are there, building the firmware,
//! and running one binary on the emulated Cortex-M4F.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../estimator-core/firmware")
}

/// Whether the QEMU check must run (`REQUIRE_QEMU=1`, set by CI) instead of being skipped.
pub fn require_qemu() -> bool {
    std::env::var("REQUIRE_QEMU").is_ok_and(|v| v == "1")
}

/// Why the QEMU check cannot run here, if it cannot.
pub fn missing_tools() -> Option<String> {
    let qemu = Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    if !qemu.is_ok_and(|s| s.success()) {
        return Some("qemu-system-arm not found".into());
    }
    if Command::new("timeout").arg("--version").output().is_err() {
        return Some("`timeout` (coreutils) not found".into());
    }
    let sysroot = Command::new("rustc").args(["--print", "sysroot"]).output();
    let has_target = sysroot.is_ok_and(|o| {
        Path::new(String::from_utf8_lossy(&o.stdout).trim())
            .join("lib/rustlib/thumbv7em-none-eabihf")
            .is_dir()
    });
    if !has_target {
        return Some("rust target thumbv7em-none-eabihf not installed".into());
    }
    None
}

/// Builds the firmware (release profile: opt-level "s", LTO, one codegen unit).
pub fn build_firmware() -> PathBuf {
    let dir = firmware_dir();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // Run in the firmware's directory so its .cargo/config.toml (target, linker script)
    // applies; keep the outer build's settings out of it.
    let status = Command::new(cargo)
        .current_dir(&dir)
        .args(["build", "--release", "--bins"])
        .arg("--target-dir")
        .arg(dir.join("target"))
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("CARGO_TARGET_DIR")
        .status()
        .expect("run cargo build for the firmware");
    assert!(status.success(), "firmware build failed");
    dir.join("target/thumbv7em-none-eabihf/release")
}

/// Runs an ELF on the emulated Cortex-M4F under `timeout`, output to a file (a semihosting
/// write to a closed pipe would spin forever). Returns (exit status, output).
pub fn run_qemu(elf: &Path, out: &Path) -> (i32, String) {
    let file = File::create(out).expect("create QEMU output file");
    let status = Command::new("timeout")
        .arg("120")
        .arg("qemu-system-arm")
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::from(file))
        .status()
        .expect("run qemu-system-arm");
    let text = std::fs::read_to_string(out).unwrap_or_default();
    (status.code().unwrap_or(-1), text)
}
