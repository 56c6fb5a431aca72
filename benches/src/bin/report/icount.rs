//! Part `icount`: host instructions per step under valgrind/callgrind, and the history of our
//! KF step against `adskalman`'s.

use crate::command::{say, sh};
use crate::kf_forms::{KF_FORMS, KF_PROBLEMS};
use crate::opts::Opts;
use crate::prose;
use anyhow::{anyhow, bail, Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// What was done about the KF target, and what is proposed (the numbers of the "before"
/// column were measured once, with the previous `kalman.rs`, by the same icount method).
const KF_NOTES: &str = include_str!("prose/kf_notes.md");

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let bin = o.target.join("release/icount");
    let list = sh(bin.to_str().unwrap_or("icount"), &["list"]).ok_or_else(|| {
        anyhow!("{bin:?} list failed (build it: cargo build --release -p benches)")
    })?;
    let n: u64 = if o.quick { 200 } else { 1000 };
    prose::push(md, &intro(n, o.plain_release));
    md.push_str("| kernel | I(N) | I(2N) | I(2N) again | same twice | instructions / step |\n|---|---:|---:|---:|---|---:|\n");
    let mut res = BTreeMap::new();
    // The view's tap has a part of its own (`view`).
    for k in list.lines().filter(|k| !k.starts_with("view/")) {
        say(&format!("callgrind {k}"));
        let a = callgrind_ir(&bin, k, n)?;
        let b = callgrind_ir(&bin, k, 2 * n)?;
        let b2 = callgrind_ir(&bin, k, 2 * n)?;
        let per = (b - a) as f64 / n as f64;
        res.insert(k.to_string(), (b - a) / n);
        let _ = writeln!(
            md,
            "| `{k}` | {a} | {b} | {b2} | {} | {per:.1} |",
            if b == b2 { "yes" } else { "**no**" }
        );
    }
    md.push('\n');
    for (form, _, ads, ours) in KF_FORMS {
        for prob in KF_PROBLEMS {
            if let (Some(a), Some(b)) = (
                res.get(&format!("{ours}/{prob}")),
                res.get(&format!("{ads}/{prob}")),
            ) {
                let _ = writeln!(
                    md,
                    "- KF {prob}, {form}: ours {a} vs adskalman {b} instructions per step, \
                     ratio {:.2}.",
                    *a as f64 / *b as f64
                );
            }
        }
    }
    md.push('\n');
    prose::push(md, KF_NOTES);
    crate::late::host(md, &res);
    Ok(())
}

fn intro(n: u64, plain_release: bool) -> String {
    let build = if plain_release {
        "built by a plain `cargo build --release` in this regeneration (`--plain-release`: no \
         LTO, the workspace's codegen units), not with `profile.bench` as criterion builds"
    } else {
        "built with `profile.bench` like criterion's: thin LTO, one codegen unit"
    };
    prose::fill(
        include_str!("prose/icount.md"),
        &[("n", &n), ("build", &build)],
    )
}

/// Instructions executed by `bin kernel n`, from callgrind's `I refs`.
pub fn callgrind_ir(bin: &Path, kernel: &str, n: u64) -> Result<u64> {
    let out = Command::new("valgrind")
        .args(["--tool=callgrind", "--callgrind-out-file=/dev/null"])
        .arg(bin)
        .args([kernel, &n.to_string()])
        .output()
        .context("valgrind (apt-get install valgrind)")?;
    if !out.status.success() {
        bail!(
            "icount {kernel} {n} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let err = String::from_utf8_lossy(&out.stderr);
    let line = err
        .lines()
        .find(|l| l.contains("refs:"))
        .ok_or_else(|| anyhow!("no 'I refs' in callgrind output"))?;
    let digits: String = line
        .rsplit(':')
        .next()
        .unwrap_or("")
        .chars()
        .filter(char::is_ascii_digit)
        .collect();
    digits.parse().context("I refs")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(1000, false).contains("with N = 1000,"));
    }
}
