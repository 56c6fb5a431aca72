//! Part `firmware`: Cortex-M4 instructions per step, from `.ci/firmware` (QEMU TCG plugin).

use crate::command::say;
use crate::opts::Opts;
use crate::prose;
use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::process::Command;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let script = o.root.join(".ci/firmware");
    let csv = o
        .root
        .join("estimator-core/firmware/target/qemu/insn_counts.csv");
    if !script.exists() {
        bail!(".ci/firmware not present");
    }
    say("running .ci/firmware (QEMU instruction counts)");
    let out = Command::new(&script)
        .current_dir(&o.root)
        .output()
        .context(".ci/firmware")?;
    if !out.status.success() {
        bail!(
            ".ci/firmware failed: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        );
    }
    let text = std::fs::read_to_string(&csv).with_context(|| format!("{csv:?}"))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    prose::push(md, include_str!("prose/firmware.md"));
    let _ = writeln!(md, "| {} |", header.join(" | "));
    let _ = writeln!(md, "|{}|", vec!["---"; header.len()].join("|"));
    for l in lines {
        let _ = writeln!(md, "| {} |", l.split(',').collect::<Vec<_>>().join(" | "));
    }
    md.push('\n');
    Ok(())
}
