//! Criterion's medians: running every criterion bench, reading what it wrote, and the tables
//! of all of them.

use crate::command::say;
use crate::format::fmt_ns;
use crate::opts::Opts;
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::SystemTime;

/// One benchmark's median and the 95 % confidence interval of it.
#[derive(Clone, Debug)]
pub struct Crit {
    pub median_ns: f64,
    pub lo_ns: f64,
    pub hi_ns: f64,
}

/// The median with its confidence interval, as one table cell.
pub fn fmt_ci(c: &Crit) -> String {
    format!(
        "{} ({}–{})",
        fmt_ns(c.median_ns),
        fmt_ns(c.lo_ns),
        fmt_ns(c.hi_ns)
    )
}

/// Runs `cargo bench -p benches` on every criterion bench file and returns the medians of this
/// run by criterion's full id.
pub fn medians(o: &Opts) -> Result<BTreeMap<String, Crit>> {
    let started = SystemTime::now();
    // Every criterion target by name (`--benches` would also run the lib's and the bins'
    // test harnesses, which refuse criterion's options).
    let mut names: Vec<String> = std::fs::read_dir(o.root.join("benches/benches"))
        .context("benches/benches")?
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "rs").then(|| p.file_stem()?.to_str().map(str::to_string))?
        })
        .collect();
    names.sort();
    let mut args = vec!["bench", "-p", "benches"];
    for n in &names {
        args.extend(["--bench", n.as_str()]);
    }
    args.push("--");
    if o.quick {
        args.extend(["--warm-up-time", "0.3", "--measurement-time", "0.7"]);
    }
    say(&format!("cargo {}", args.join(" ")));
    let st = Command::new("cargo")
        .args(&args)
        .current_dir(&o.root)
        .stdout(Stdio::null())
        .status()
        .context("cargo bench")?;
    if !st.success() {
        bail!("cargo bench failed ({st})");
    }
    read_estimates(&o.target.join("criterion"), started)
}

/// Criterion's `new/estimates.json` under `dir` written since `started` (earlier ones are of
/// benchmarks this run did not make).
fn read_estimates(dir: &Path, started: SystemTime) -> Result<BTreeMap<String, Crit>> {
    let mut res = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("{d:?}"))? {
            let p = e?.path();
            if p.is_dir() {
                if p.file_name().is_some_and(|n| n == "new") {
                    let est = p.join("estimates.json");
                    let bm = p.join("benchmark.json");
                    let fresh = std::fs::metadata(&est)
                        .and_then(|m| m.modified())
                        .is_ok_and(|t| t >= started);
                    if !fresh {
                        continue;
                    }
                    let e: Value = serde_json::from_str(&std::fs::read_to_string(&est)?)?;
                    let b: Value = serde_json::from_str(&std::fs::read_to_string(&bm)?)?;
                    let id = b["full_id"].as_str().unwrap_or("?").to_string();
                    let m = &e["median"];
                    res.insert(
                        id,
                        Crit {
                            median_ns: m["point_estimate"].as_f64().unwrap_or(f64::NAN),
                            lo_ns: m["confidence_interval"]["lower_bound"]
                                .as_f64()
                                .unwrap_or(f64::NAN),
                            hi_ns: m["confidence_interval"]["upper_bound"]
                                .as_f64()
                                .unwrap_or(f64::NAN),
                        },
                    );
                } else {
                    stack.push(p);
                }
            }
        }
    }
    Ok(res)
}

/// Every median of the run, then each f32 step against the f64 step of the same name.
pub fn tables(md: &mut String, res: &BTreeMap<String, Crit>) {
    md.push_str("\n## Every criterion benchmark (medians)\n\n");
    md.push_str("| benchmark | median | 95 % CI of the median |\n|---|---:|---:|\n");
    for (id, c) in res {
        let _ = writeln!(
            md,
            "| `{id}` | {} | {} – {} |",
            fmt_ns(c.median_ns),
            fmt_ns(c.lo_ns),
            fmt_ns(c.hi_ns)
        );
    }
    md.push('\n');
    // f32 against f64 of the same step, in the same run.
    let mut pairs = String::new();
    for (id, c) in res {
        if let Some(base) = id.strip_suffix("f32") {
            if let Some(d) = res.get(&format!("{base}f64")) {
                let _ = writeln!(
                    pairs,
                    "| `{base}…` | {} | {} | {:.2} |",
                    fmt_ns(c.median_ns),
                    fmt_ns(d.median_ns),
                    c.median_ns / d.median_ns
                );
            }
        }
    }
    if !pairs.is_empty() {
        md.push_str("### f32 against f64 (same step, same run)\n\n| step | f32 | f64 | f32/f64 |\n|---|---:|---:|---:|\n");
        md.push_str(&pairs);
        md.push('\n');
    }
}
