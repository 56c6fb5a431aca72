//! Part `eval`, its first table: issue #23's command, `ipc-runner eval --scenario occlusion
//! --runs 5000 --horizon 100`, against the same command of commit [`BASELINE`], both binaries
//! alternating in one run. CPU time (user + sys, `/usr/bin/time`) of every repetition and
//! their medians; the instructions of a smaller run under callgrind, twice per binary
//! (deterministic); whether the `estimators` parts of the two JSON files agree; and where the
//! current binary's instructions go.
//!
//! The baseline is exported from git (`git archive`, no worktree) into
//! `target/baseline-<commit>/src` and built there with its own target directory, once.

use crate::command::say;
use crate::opts::Opts;
use crate::prose;
use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The commit issue #23 measured its 1.4 CPU-seconds at.
pub const BASELINE: &str = "b7a974e";
/// The command of the issue (the JSON and the quiet flag added, which do not change the work).
const SCENARIO: &str = "occlusion";
const HORIZON: u32 = 100;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let m = measure(o)?;
    let cmd = format!(
        "ipc-runner eval --scenario {SCENARIO} --runs {} --horizon {HORIZON} --quiet --json FILE",
        m.runs
    );
    let cg_cmd = format!(
        "valgrind --tool=callgrind ipc-runner eval --scenario {SCENARIO} --runs {} \
         --horizon {HORIZON} --quiet --threads 1",
        m.cg_runs
    );
    prose::push(md, &intro(m.reps, &cmd, &cg_cmd));
    write_table(md, &m);
    write_ratios(md, &m);
    write_breakdown(md, &m);
    write_time_split(md, &m);
    Ok(())
}

/// What the part measures of the two binaries (index 0 the baseline, 1 this build).
struct Measured {
    /// Runs of the timed command, its repetitions, runs of the callgrind command.
    runs: u64,
    reps: usize,
    cg_runs: u64,
    /// (CPU s, wall s) of every repetition.
    cpu: [Vec<(f64, f64)>; 2],
    /// Whether the JSON files agree (the sentence).
    same: String,
    /// Instructions of the whole process, and of the runs alone, twice each.
    ir: [[u64; 2]; 2],
    runs_ir: [[u64; 2]; 2],
    /// This build's instructions by part.
    split: Vec<(String, u64)>,
    /// This build's CPU time by part (samples, shares).
    time_split: Result<(u64, Vec<(String, f64)>)>,
}

impl Measured {
    /// The median CPU s (`f = |c| c.0`) or wall s (`|c| c.1`) of binary `which`.
    fn median_of(&self, which: usize, f: fn(&(f64, f64)) -> f64) -> f64 {
        median(self.cpu[which].iter().map(f).collect())
    }
    /// Run-steps of the callgrind command.
    fn cg_run_steps(&self) -> f64 {
        (self.cg_runs * HORIZON as u64) as f64
    }
}

/// Builds the baseline, then times both binaries alternately, compares their JSON, counts
/// their instructions under callgrind and profiles this build.
fn measure(o: &Opts) -> Result<Measured> {
    let base = baseline_binary(o)?;
    let cur = o.target.join("release/ipc-runner");
    if !cur.exists() {
        bail!("{cur:?} missing (benches/run.sh builds it)");
    }
    let (runs, reps, cg_runs) = if o.quick {
        (1000u64, 2usize, 50u64)
    } else {
        (5000, 5, 200)
    };
    let tmp = std::env::temp_dir().join(format!("benches-report-eval23-{}", std::process::id()));
    std::fs::create_dir_all(&tmp)?;
    // CPU time, alternating which binary goes first.
    let mut cpu: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    for rep in 0..reps {
        for which in if rep % 2 == 0 { [0, 1] } else { [1, 0] } {
            let bin = if which == 0 { &base } else { &cur };
            let json = tmp.join(format!("{which}.json"));
            say(&format!(
                "eval {SCENARIO} --runs {runs}: {} (rep {rep})",
                label(which)
            ));
            cpu[which].push(timed(bin, runs, &json, &tmp.join("time"))?);
        }
    }
    let same = compare(&tmp.join("0.json"), &tmp.join("1.json"))?;
    // Instructions, twice each: the whole process, and the runs alone (`run_one`, inclusive),
    // which do not depend on how the threads met.
    let mut ir = [[0u64; 2]; 2];
    let mut runs_ir = [[0u64; 2]; 2];
    for (which, bin) in [&base, &cur].into_iter().enumerate() {
        for r in 0..2 {
            say(&format!(
                "callgrind eval --runs {cg_runs}: {} ({r})",
                label(which)
            ));
            let file = tmp.join(format!("cg.{which}.{r}"));
            ir[which][r] = callgrind(bin, cg_runs, &file)?;
            runs_ir[which][r] = inclusive(&file, &["ipc_runner::eval::run_one ["])?;
        }
    }
    let split = breakdown(&tmp.join("cg.1.0"))?;
    say(&format!(
        "perf cpu-clock eval --runs {runs} --threads 1: this build"
    ));
    let time_split = cpu_profile(&cur, runs, &tmp);
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(Measured {
        runs,
        reps,
        cg_runs,
        cpu,
        same,
        ir,
        runs_ir,
        split,
        time_split,
    })
}

/// The table: each binary's CPU time per repetition, medians and instruction counts.
fn write_table(md: &mut String, m: &Measured) {
    md.push_str(
        "| binary | CPU s (user + sys) of each repetition | median CPU s | median wall s | \
         instructions | again | of which the runs | again | same twice |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---|\n",
    );
    for which in 0..2 {
        let reps: Vec<String> = m.cpu[which].iter().map(|c| format!("{:.2}", c.0)).collect();
        let _ = writeln!(
            md,
            "| {} | {} | {:.2} | {:.2} | {} | {} | {} | {} | {} |",
            label(which),
            reps.join(", "),
            m.median_of(which, |c| c.0),
            m.median_of(which, |c| c.1),
            m.ir[which][0],
            m.ir[which][1],
            m.runs_ir[which][0],
            m.runs_ir[which][1],
            if m.runs_ir[which][0] == m.runs_ir[which][1] {
                "yes (the runs)"
            } else {
                "**no**"
            }
        );
    }
}

/// The ratios against the target (≥ 4×) and whether the JSON files agree.
fn write_ratios(md: &mut String, m: &Measured) {
    let cg_runs = m.cg_runs;
    let cpu_ratio = m.median_of(0, |c| c.0) / m.median_of(1, |c| c.0);
    let per_rep: Vec<f64> = m.cpu[0]
        .iter()
        .zip(&m.cpu[1])
        .map(|(b, c)| b.0 / c.0)
        .collect();
    let ir_ratio = m.ir[0][0] as f64 / m.ir[1][0] as f64;
    let runs_ratio = m.runs_ir[0][0] as f64 / m.runs_ir[1][0] as f64;
    let verdict = |r: f64| if r >= 4.0 { "met" } else { "**missed**" };
    let _ = writeln!(
        md,
        "\nCPU: {} ÷ this build = **{cpu_ratio:.2}×** (ratio of the medians; per repetition {}), \
         target ≥ 4×: {}. Instructions: **{ir_ratio:.2}×** ({:.0} against {:.0} per run-step, \
         the {cg_runs} runs × {HORIZON} instants of one process, start-up included; the runs \
         alone {runs_ratio:.2}×), target ≥ 4×: {}. The whole process's count moves by a few \
         hundred instructions between two runs (the worker threads' hand-offs); the runs' \
         count (`run_one` and all it calls) is the same twice.\n",
        label(0),
        per_rep
            .iter()
            .map(|r| format!("{r:.2}"))
            .collect::<Vec<_>>()
            .join(", "),
        verdict(cpu_ratio),
        m.ir[0][0] as f64 / m.cg_run_steps(),
        m.ir[1][0] as f64 / m.cg_run_steps(),
        verdict(ir_ratio),
    );
    let _ = writeln!(md, "{}\n", m.same);
}

/// Where this build's instructions go (the callgrind run, inclusive costs).
fn write_breakdown(md: &mut String, m: &Measured) {
    md.push_str("Where this build's instructions go (the callgrind run above, inclusive costs):\n\n| part | instructions | share | per run-step |\n|---|---:|---:|---:|\n");
    let total = m.ir[1][0] as f64;
    for (name, v) in &m.split {
        let _ = writeln!(
            md,
            "| {name} | {v} | {:.1} % | {:.0} |",
            100.0 * *v as f64 / total,
            *v as f64 / m.cg_run_steps()
        );
    }
    md.push('\n');
}

/// Where this build's CPU time goes (perf), and what that leaves for the target.
fn write_time_split(md: &mut String, m: &Measured) {
    let runs = m.runs;
    let cur_cpu = m.median_of(1, |c| c.0);
    let base_cpu = m.median_of(0, |c| c.0);
    let (samples, rows) = match &m.time_split {
        Ok(split) => split,
        Err(e) => {
            let _ = writeln!(md, "Where the CPU time goes: not measured ({e:#}).\n");
            return;
        }
    };
    let _ = writeln!(
        md,
        "Where this build's CPU time goes: `perf record -e cpu-clock -F {PERF_HZ}` of \
         the command with `--runs {runs} --threads 1`, {samples} samples, each \
         function's own time (not what it calls; what the compiler inlined counts \
         where it was inlined), grouped. Sampled, so statistical: a share s is known \
         to ±2·√(s(1 − s)/{samples}) (under 2 points here). Instructions are not \
         time: a chain of dependent divisions costs their latency, and the continued \
         fractions of `ln Q` are such chains.\n\n\
         | part | share of the CPU time |\n|---|---:|"
    );
    for (name, share) in rows {
        let _ = writeln!(md, "| {name} | {:.1} % |", 100.0 * share);
    }
    let special = rows.first().map_or(0.0, |r| r.1);
    let rest_cpu = cur_cpu * (1.0 - special);
    let _ = writeln!(
        md,
        "\nWhat this leaves for the target: the special functions alone take {:.2} CPU \
         s here; at this cost (the bit-identical JSON needs the same `erfc`, `exp`, \
         `ln` and continued fractions on the same arguments), the command could at \
         best be {:.1}× faster than `{BASELINE}`, with everything else free. 4× \
         ({:.2} CPU s) leaves {:.2} CPU s for everything else, which takes {:.2} \
         now: {:.0} % of it would have to go. Within the special functions, only \
         work that cannot change a bit can go: terms proved not to count, as the \
         interval sums already skip, and latency hidden by evaluating independent \
         arguments side by side, as `gauss::side_by_side` does for the gaps of one \
         `kf-io` step; more of it needs several runs' steps side by side.\n",
        cur_cpu * special,
        base_cpu / (cur_cpu * special),
        base_cpu / 4.0,
        (base_cpu / 4.0 - cur_cpu * special).max(0.0),
        rest_cpu,
        100.0 * (1.0 - (base_cpu / 4.0 - cur_cpu * special).max(0.0) / rest_cpu),
    );
}

/// Sampling rate of [`cpu_profile`].
const PERF_HZ: u32 = 4999;

/// The groups of [`cpu_profile`], by symbol or library; the first is the special functions.
const TIME_PARTS: &[(&str, &[&str])] = &[
    (
        "special functions (`estimator_core::gauss`: `ln Q` and its continued fractions; \
         the truncated normal's moments; `libm`: `erfc`, `exp`, `ln`, `ln_1p`)",
        &[
            "estimator_core::gauss::",
            "libm::",
            "estimator_core::filter::occlusion::truncnorm",
        ],
    ),
    (
        "the occlusion estimators' own code (interval sums, mixtures, updates)",
        &["estimator_core::filter::occlusion::"],
    ),
    (
        "Kalman steps and linear algebra",
        &[
            "estimator_core::filter::kalman",
            "estimator_core::linalg",
            "nalgebra::",
            "estimator_core::filter::time_update",
        ],
    ),
    (
        "simulation (plant, sensor, channel, random numbers)",
        &["channel_sim::", "rand"],
    ),
    (
        "eval's bookkeeping and the adapters",
        &["ipc_runner::", "<ipc_runner::"],
    ),
    ("allocation and copies (libc)", &["libc.so"]),
];

/// The CPU time of `bin`'s eval by [`TIME_PARTS`] (and the rest): `(samples, shares)`.
fn cpu_profile(bin: &Path, runs: u64, tmp: &Path) -> Result<(u64, Vec<(String, f64)>)> {
    let data = tmp.join("perf.data");
    let st = Command::new("perf")
        .args([
            "record",
            "-q",
            "-e",
            "cpu-clock",
            "-F",
            &PERF_HZ.to_string(),
            "-o",
        ])
        .arg(&data)
        .arg(bin)
        .args(profiled_eval_args(runs))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("perf (apt-get install linux-perf)")?;
    if !st.success() {
        bail!("perf record failed ({st}); kernel.perf_event_paranoid may forbid it");
    }
    let out = Command::new("perf")
        .args([
            "report",
            "--stdio",
            "--no-children",
            "--sort",
            "dso,symbol",
            "--percent-limit",
            "0",
            "-i",
        ])
        .arg(&data)
        .output()
        .context("perf report")?;
    let text = String::from_utf8_lossy(&out.stdout);
    let samples = text
        .lines()
        .find_map(|l| l.strip_prefix("# Samples: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| {
            let (num, mult) = match n.strip_suffix('K') {
                Some(k) => (k, 1000.0),
                None => (n, 1.0),
            };
            num.parse::<f64>().ok().map(|v| (v * mult) as u64)
        })
        .ok_or_else(|| anyhow!("perf report: no sample count"))?;
    Ok((samples, time_shares(&text)))
}

/// [`TIME_PARTS`]' shares of a `perf report --sort dso,symbol` listing, and the rest.
fn time_shares(text: &str) -> Vec<(String, f64)> {
    let mut shares = vec![0.0; TIME_PARTS.len()];
    let mut total = 0.0;
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let Some((pct, rest)) = line.trim_start().split_once('%') else {
            continue;
        };
        let Ok(pct) = pct.parse::<f64>() else {
            continue;
        };
        total += pct;
        // `dso  [.] symbol`: the symbol for the first groups, the library for libc.
        let sym = rest.split_once("] ").map_or("", |(_, s)| s.trim());
        if let Some(g) = TIME_PARTS.iter().position(|(_, pre)| {
            pre.iter()
                .any(|p| sym.starts_with(p) || (p.ends_with(".so") && rest.contains(p)))
        }) {
            shares[g] += pct;
        }
    }
    let seen: f64 = shares.iter().sum();
    let mut rows: Vec<(String, f64)> = TIME_PARTS
        .iter()
        .zip(&shares)
        .map(|((name, _), s)| (name.to_string(), s / 100.0))
        .collect();
    rows.push(("the rest".into(), (total - seen).max(0.0) / 100.0));
    rows
}

fn label(which: usize) -> String {
    if which == 0 {
        format!("`{BASELINE}`")
    } else {
        "this build".into()
    }
}

fn intro(reps: usize, cmd: &str, cg_cmd: &str) -> String {
    prose::fill(
        include_str!("prose/eval_baseline.md"),
        &[
            ("baseline", &BASELINE),
            ("reps", &reps),
            ("cmd", &cmd),
            ("cg_cmd", &cg_cmd),
        ],
    )
}

/// The baseline's `ipc-runner`, exported and built on first use.
fn baseline_binary(o: &Opts) -> Result<PathBuf> {
    let dir = o.target.join(format!("baseline-{BASELINE}"));
    let bin = dir.join("target/release/ipc-runner");
    if bin.exists() {
        return Ok(bin);
    }
    let src = dir.join("src");
    if !src.join("Cargo.toml").exists() {
        say(&format!("exporting {BASELINE} into {src:?}"));
        std::fs::create_dir_all(&src)?;
        let archive = Command::new("git")
            .args(["archive", "--format=tar", BASELINE])
            .current_dir(&o.root)
            .stdout(Stdio::piped())
            .spawn()
            .context("git archive")?;
        let st = Command::new("tar")
            .arg("-x")
            .arg("-C")
            .arg(&src)
            .stdin(
                archive
                    .stdout
                    .ok_or_else(|| anyhow!("git archive: no stdout"))?,
            )
            .status()
            .context("tar")?;
        if !st.success() {
            bail!("exporting {BASELINE} failed");
        }
    }
    say(&format!("building {BASELINE}'s ipc-runner"));
    let st = Command::new("cargo")
        .args(["build", "--release", "-p", "ipc-runner"])
        .current_dir(&src)
        .env("CARGO_TARGET_DIR", dir.join("target"))
        .status()
        .context("cargo build (baseline)")?;
    if !st.success() || !bin.exists() {
        bail!("building {BASELINE}'s ipc-runner failed");
    }
    Ok(bin)
}

/// `(user + sys, wall)` seconds of one run of the command.
fn timed(bin: &Path, runs: u64, json: &Path, out: &Path) -> Result<(f64, f64)> {
    let st = Command::new("/usr/bin/time")
        .args(["-f", "%U %S %e", "-o"])
        .arg(out)
        .arg(bin)
        .args(["eval", "--scenario", SCENARIO, "--quiet"])
        .args([
            "--runs",
            &runs.to_string(),
            "--horizon",
            &HORIZON.to_string(),
        ])
        .arg("--json")
        .arg(json)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("/usr/bin/time")?;
    if !st.success() {
        bail!("{bin:?} eval failed: {st}");
    }
    let text = std::fs::read_to_string(out)?;
    let v: Vec<f64> = text
        .split_whitespace()
        .rev()
        .take(3)
        .map(str::parse)
        .collect::<Result<_, _>>()
        .with_context(|| format!("/usr/bin/time wrote {text:?}"))?;
    // Reversed: wall, sys, user.
    Ok((v[2] + v[1], v[0]))
}

/// The eval's arguments under a profiler (perf, callgrind): one worker thread, `runs` runs.
fn profiled_eval_args(runs: u64) -> Vec<String> {
    let (runs, horizon) = (runs.to_string(), HORIZON.to_string());
    let args = ["eval", "--scenario", SCENARIO, "--quiet", "--threads", "1"];
    let sizes = ["--runs", &runs, "--horizon", &horizon];
    args.iter().chain(&sizes).map(|a| a.to_string()).collect()
}

/// Total instructions of the command under callgrind, `--threads 1`.
fn callgrind(bin: &Path, runs: u64, out: &Path) -> Result<u64> {
    let st = Command::new("valgrind")
        .arg("--tool=callgrind")
        .arg(format!("--callgrind-out-file={}", out.display()))
        .arg(bin)
        .args(profiled_eval_args(runs))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("valgrind")?;
    if !st.success() {
        bail!("callgrind of {bin:?} failed: {st}");
    }
    let text = std::fs::read_to_string(out)?;
    text.lines()
        .find_map(|l| {
            l.strip_prefix("summary: ")
                .or_else(|| l.strip_prefix("totals: "))
        })
        .and_then(|v| v.trim().parse().ok())
        .ok_or_else(|| anyhow!("{out:?}: no summary line"))
}

/// The `estimators` of the two JSON files: every estimator both have, identical or not.
fn compare(base: &Path, cur: &Path) -> Result<String> {
    let read =
        |p: &Path| -> Result<Value> { Ok(serde_json::from_str(&std::fs::read_to_string(p)?)?) };
    let (a, b) = (read(base)?, read(cur)?);
    let (Some(a), Some(b)) = (a["estimators"].as_object(), b["estimators"].as_object()) else {
        bail!("no estimators in the JSON");
    };
    let mut same = Vec::new();
    let mut differ = Vec::new();
    // The role of an estimator (issue 46) is not a result: the baseline's JSON has none.
    let without_role = |v: &Value| {
        let mut v = v.clone();
        if let Some(o) = v.as_object_mut() {
            o.remove("role");
        }
        v
    };
    for (name, va) in a {
        let Some(vb) = b.get(name) else { continue };
        let (va, vb) = (&without_role(va), &without_role(vb));
        if va == vb {
            same.push(format!("`{name}`"));
        } else {
            differ.push(format!(
                "`{name}` (largest relative difference {:.1e})",
                max_rel(va, vb)
            ));
        }
    }
    let only: Vec<String> = b
        .keys()
        .filter(|n| !a.contains_key(*n))
        .map(|n| format!("`{n}`"))
        .collect();
    let mut s = format!(
        "JSON (`estimators`, the last repetition's files): bit-identical for {}",
        if same.is_empty() {
            "none".into()
        } else {
            same.join(", ")
        }
    );
    if !differ.is_empty() {
        let _ = write!(s, "; different for {}", differ.join(", "));
    }
    if !only.is_empty() {
        let _ = write!(s, "; only in this build: {}", only.join(", "));
    }
    s.push('.');
    Ok(s)
}

/// The largest `|a − b| / max(|a|, |b|)` over the numbers of two JSON values of one shape.
fn max_rel(a: &Value, b: &Value) -> f64 {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap_or(0.0), y.as_f64().unwrap_or(0.0));
            let m = x.abs().max(y.abs());
            if m == 0.0 {
                0.0
            } else {
                (x - y).abs() / m
            }
        }
        (Value::Array(x), Value::Array(y)) => x
            .iter()
            .zip(y)
            .map(|(x, y)| max_rel(x, y))
            .fold(0.0, f64::max),
        (Value::Object(x), Value::Object(y)) => x
            .iter()
            .filter_map(|(k, v)| y.get(k).map(|w| max_rel(v, w)))
            .fold(0.0, f64::max),
        _ if a == b => 0.0,
        _ => f64::INFINITY,
    }
}

/// The parts of the run, by the inclusive cost of the functions that do them (symbols of
/// this build; what matches none is "the rest").
const PARTS: &[(&str, &[&str])] = &[
    (
        "simulation (plant, sensor, channel)",
        &["<channel_sim::scenario::composed::ComposedSimulation as channel_sim::sim::Simulation>::next_instant"],
    ),
    ("`kf` and `ikf` steps", &["<estpipe_estimators::kf::NodeByNode<"]),
    ("`cce` steps", &["estimator_core::filter::occlusion::cce::<impl estimator_core::estimator::Estimator<"]),
    ("`kf-io` steps", &["estimator_core::filter::occlusion::kf_io::<impl estimator_core::estimator::Estimator<"]),
    ("`adf` steps", &["estimator_core::filter::occlusion::adf::<impl estimator_core::estimator::Estimator<"]),
    (
        "squared errors and diagnostics per step",
        &["ipc_runner::eval::record_estimate"],
    ),
    (
        "estimators built per run",
        &["estpipe_estimators::registry::build_all"],
    ),
    (
        "accumulating the runs, the report and the JSON",
        &[
            "ipc_runner::eval::report::Accumulator::add",
            "ipc_runner::eval::report::Accumulator::finish",
            "ipc_runner::eval::report::EvalResult::to_json",
            "ipc_runner::eval::report::EvalResult::summary",
        ],
    ),
];

/// `callgrind_annotate --inclusive=yes` of a callgrind file, every function listed.
fn annotate(file: &Path) -> Result<String> {
    let out = Command::new("callgrind_annotate")
        .args(["--inclusive=yes", "--threshold=100"])
        .arg(file)
        .output()
        .context("callgrind_annotate")?;
    if !out.status.success() {
        bail!("callgrind_annotate failed");
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The inclusive instructions of the functions whose symbols start with one of `syms`.
fn inclusive(file: &Path, syms: &[&str]) -> Result<u64> {
    Ok(matching(&annotate(file)?, syms))
}

/// The counts of an annotation's lines: `(count, rest of the line)`.
fn counted(text: &str) -> impl Iterator<Item = (u64, &str)> {
    text.lines().filter_map(|line| {
        let (count, rest) = line.trim_start().split_once(' ')?;
        Some((count.replace(',', "").parse::<u64>().ok()?, rest))
    })
}

/// The summed counts of the functions whose symbols (`???:symbol [binary]`) start with one
/// of `syms`.
fn matching(text: &str, syms: &[&str]) -> u64 {
    counted(text)
        .filter_map(|(count, rest)| {
            let sym = rest.split_once("???:")?.1;
            syms.iter().any(|p| sym.starts_with(p)).then_some(count)
        })
        .sum()
}

/// `PARTS` of a callgrind file, and the rest.
fn breakdown(file: &Path) -> Result<Vec<(String, u64)>> {
    let text = annotate(file)?;
    let total = counted(&text)
        .find(|(_, rest)| rest.contains("PROGRAM TOTALS"))
        .map_or(0, |(c, _)| c);
    let mut rows = Vec::new();
    let mut seen = 0u64;
    for (name, syms) in PARTS {
        let sum = matching(&text, syms);
        seen += sum;
        rows.push((name.to_string(), sum));
    }
    rows.push((
        "the rest (process start-up, threads, the adapters' packet conversion, …)".into(),
        total.saturating_sub(seen),
    ));
    Ok(rows)
}

pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_prose_fills_and_medians_are_medians() {
        let t = intro(5, "A", "B");
        assert!(t.contains(BASELINE) && t.contains("`A`") && t.contains("`B`"));
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
    }

    #[test]
    fn callgrind_lines_are_summed_by_symbol_prefix() {
        let text = "272,664,025 (100.0%)  PROGRAM TOTALS\n\
            \x20 1,000 ( 1.00%)  ???:ipc_runner::eval::run_one [bin]\n\
            \x20   250 ( 0.10%)  ???:ipc_runner::eval::record_estimate [bin]\n\
            \x20    25 ( 0.01%)  ./x.c:libc_thing [libc]\n";
        assert_eq!(matching(text, &["ipc_runner::eval::"]), 1250);
        assert_eq!(matching(text, &["ipc_runner::eval::run_one ["]), 1000);
        assert_eq!(
            counted(text)
                .find(|(_, r)| r.contains("PROGRAM TOTALS"))
                .map(|c| c.0),
            Some(272_664_025)
        );
    }

    #[test]
    fn cpu_time_groups_by_symbol_and_library() {
        let text = "# Samples: 3K of event 'cpu-clock'\n\
            \x20   20.00%  ipc-runner  [.] estimator_core::gauss::ln_sf\n\
            \x20   10.00%  ipc-runner  [.] libm::math::exp::exp\n\
            \x20   30.00%  ipc-runner  [.] estimator_core::filter::occlusion::adf::x\n\
            \x20    5.00%  libc.so.6   [.] __memmove_avx512_unaligned_erms\n\
            \x20   35.00%  ipc-runner  [.] main\n";
        let rows = time_shares(text);
        assert!((rows[0].1 - 0.30).abs() < 1e-12, "{rows:?}");
        assert!((rows[1].1 - 0.30).abs() < 1e-12);
        assert!((rows[5].1 - 0.05).abs() < 1e-12);
        assert!((rows.last().unwrap().1 - 0.35).abs() < 1e-12);
    }

    #[test]
    fn relative_differences_walk_the_json() {
        let a: Value = serde_json::json!({"x": [1.0, 2.0], "y": {"z": 4.0}});
        let b: Value = serde_json::json!({"x": [1.0, 2.0], "y": {"z": 5.0}});
        assert_eq!(max_rel(&a, &a), 0.0);
        assert!((max_rel(&a, &b) - 0.2).abs() < 1e-15);
    }
}
