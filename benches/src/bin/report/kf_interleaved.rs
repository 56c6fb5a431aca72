//! The KF comparison interleaved (`kf_interleaved`): both sides alternate in batches of 1 000
//! calls in one process, and the ratio is the median of the per-round ratios. First the binary
//! `cargo bench` built (`profile.bench`), then plain `--release` builds: baseline x86-64 and,
//! where the CPU runs it, `x86-64-v3`.

use crate::command::{run_json, say};
use crate::format::{fmt_ns, verdict};
use crate::kf_forms::KF_TARGET;
use crate::opts::Opts;
use crate::prose;
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Writes the three comparisons in turn; on an error, what was written before it stays in `md`.
pub fn section(o: &Opts, md: &mut String) -> Result<()> {
    let rounds = if o.quick { "400" } else { "8000" };
    let rows = run(&o.target.join("release/kf_interleaved"), rounds)?;
    md.push('\n');
    prose::push(md, &interleaved_prose(rounds));
    table(md, &rows);
    // `cargo bench` builds with `profile.bench` (thin LTO, one codegen unit); a user's
    // `cargo build --release` does not. The two compile the same source differently enough
    // to move the ratio, so both are measured, each in a target directory of its own (the
    // two profiles otherwise overwrite each other's binaries in target/release).
    let plain = build(o, "plain-release", None)?;
    let rows = run(&plain, rounds)?;
    md.push('\n');
    prose::push(md, include_str!("prose/kf_plain_release.md"));
    table(md, &rows);
    if !cpu_has_x86_64_v3() {
        md.push_str("\nThis CPU does not run `x86-64-v3` code: the AVX2 build was not measured.\n");
        return Ok(());
    }
    // Baseline x86-64 is SSE2: a 4-lane f64 column takes two registers. A deployment on a
    // known host builds for it; both libraries get the same flags (no FMA contraction in
    // Rust, so the results stay bit-identical).
    let v3 = build(o, "x86-64-v3", Some("-C target-cpu=x86-64-v3"))?;
    let rows = run(&v3, rounds)?;
    md.push('\n');
    prose::push(md, include_str!("prose/kf_x86_64_v3.md"));
    table(md, &rows);
    Ok(())
}

fn interleaved_prose(rounds: &str) -> String {
    prose::fill(
        include_str!("prose/kf_interleaved.md"),
        &[("rounds", &rounds)],
    )
}

/// Runs `kf_interleaved` and returns its JSON rows.
fn run(bin: &Path, rounds: &str) -> Result<Value> {
    run_json(bin, &["--rounds", rounds])
}

/// The table of `kf_interleaved`'s rows.
fn table(md: &mut String, rows: &Value) {
    md.push_str(
        "| problem | covariance form | ours median | adskalman median | ratio: median of rounds (p10–p90) | target ≤ 0.8 |\n\
         |---|---|---:|---:|---:|---|\n",
    );
    for r in rows.as_array().into_iter().flatten() {
        let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
        let ratio = f("ratio_median");
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {ratio:.2} ({:.2}–{:.2}) | {} |",
            r["problem"].as_str().unwrap_or("?"),
            r["form"].as_str().unwrap_or("?"),
            fmt_ns(f("ours_median_ns")),
            fmt_ns(f("ads_median_ns")),
            f("ratio_p10"),
            f("ratio_p90"),
            verdict(ratio <= KF_TARGET)
        );
    }
}

/// Whether this CPU runs `x86-64-v3` code (AVX2, FMA, BMI1/2, F16C, LZCNT, MOVBE).
fn cpu_has_x86_64_v3() -> bool {
    let Ok(info) = std::fs::read_to_string("/proc/cpuinfo") else {
        return false;
    };
    let Some(flags) = info.lines().find(|l| l.starts_with("flags")) else {
        return false;
    };
    let have: Vec<&str> = flags.split_whitespace().collect();
    [
        "avx", "avx2", "fma", "bmi1", "bmi2", "f16c", "abm", "movbe", "xsave",
    ]
    .iter()
    .all(|f| have.contains(f))
}

/// Builds `kf_interleaved` with `cargo build --release` into `target/<dir>` (with `rustflags`
/// if given) and returns the binary's path.
fn build(o: &Opts, dir: &str, rustflags: Option<&str>) -> Result<PathBuf> {
    let target = o.target.join(dir);
    say(&format!(
        "building kf_interleaved into {} (release profile{})",
        target.display(),
        rustflags
            .map(|f| format!(", RUSTFLAGS={f}"))
            .unwrap_or_default()
    ));
    let mut cmd = Command::new("cargo");
    cmd.args([
        "build",
        "--release",
        "-p",
        "benches",
        "--bin",
        "kf_interleaved",
    ])
    .env("CARGO_TARGET_DIR", &target)
    .env_remove("RUSTFLAGS")
    .current_dir(&o.root)
    .stdout(Stdio::null())
    .stderr(Stdio::null());
    if let Some(f) = rustflags {
        cmd.env("RUSTFLAGS", f);
    }
    let st = cmd.status().context("cargo build")?;
    if !st.success() {
        bail!("cargo build of kf_interleaved into {dir} failed ({st})");
    }
    Ok(target.join("release/kf_interleaved"))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::interleaved_prose("8000").contains("`kf_interleaved --rounds 8000`"));
    }
}
