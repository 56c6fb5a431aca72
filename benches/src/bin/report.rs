//! Regenerates `BENCHMARKS.md`: runs every benchmark of the product on this machine and writes
//! the tables. Run through `benches/run.sh` (which builds what it needs first).
//!
//! Parts, in order (each can be skipped with `--skip PART,…`):
//!
//! - `criterion`: `cargo bench -p benches` (every criterion bench file), medians with their
//!   95 % confidence intervals, our KF against `adskalman` as ratios of the same run;
//! - `icount`: host instructions per step under valgrind/callgrind, `(I(2N) − I(N)) / N`, each
//!   2N run done twice to show the count is deterministic;
//! - `firmware`: Cortex-M4 instructions per step from `.ci/firmware` (QEMU TCG plugin);
//! - `ipc`: `ipc_latency` (raw iceoryx2 and Unix socket ping-pong);
//! - `pipeline`: `ipc-runner demo` end to end (slot sent → estimates published), spin and
//!   blocking, and a sustained 100 000 slots/s run;
//! - `eval`: Monte-Carlo throughput of `ipc-runner eval` per scenario preset.
//!
//! `--quick` shortens every part (for trying the script; the committed file uses the full run).

use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Instant, SystemTime};

struct Opts {
    quick: bool,
    skip: Vec<String>,
    out: PathBuf,
    root: PathBuf,
    target: PathBuf,
}

impl Opts {
    fn runs(&self, part: &str) -> bool {
        !self.skip.iter().any(|s| s == part)
    }
}

fn sh(cmd: &str, args: &[&str]) -> Option<String> {
    let o = Command::new(cmd).args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// A note printed to stderr as the run goes.
fn say(msg: &str) {
    eprintln!("report: {msg}");
}

// ---------------------------------------------------------------------------- criterion

#[derive(Clone, Debug)]
struct Crit {
    median_ns: f64,
    lo_ns: f64,
    hi_ns: f64,
}

fn criterion(o: &Opts, md: &mut String) -> Result<BTreeMap<String, Crit>> {
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
    let mut res = BTreeMap::new();
    let dir = o.target.join("criterion");
    let mut stack = vec![dir.clone()];
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
    let get = |id: &str| res.get(id).cloned();
    md.push_str("## Kalman step: ours against `adskalman` (criterion, same run)\n\n");
    md.push_str(
        "One predict + Joseph-form update from the same converged prior, same model and \
         measurement, matrices converted to `adskalman`'s nalgebra 0.35 once at setup \
         (`benches/src/problems.rs`, `benches/src/ads.rs`; agreement of the two posteriors is \
         tested in `benches/tests/agreement.rs`). Target: ours ≤ 0.8× `adskalman`. The \
         verdict is on the Joseph form, the default of both; the optimal-gain form \
         (`CovarianceUpdate::Standard`, `P − K Gᵀ` on the upper triangle, against `adskalman`'s \
         `OptimalKalmanForcedSymmetric`, `(I − KH) P` then its symmetric part) is shown below \
         it, like for like.\n\n",
    );
    md.push_str("| problem | covariance form | ours median (95 % CI) | adskalman median (95 % CI) | ratio ours/adskalman | target ≤ 0.8 |\n|---|---|---:|---:|---:|---|\n");
    for (form, ours, ads, _) in KF_FORMS {
        for prob in ["3x2_f64", "4x2_f32"] {
            if let (Some(a), Some(b)) = (
                get(&format!("kf_vs_adskalman/{ours}/{prob}")),
                get(&format!("kf_vs_adskalman/{ads}/{prob}")),
            ) {
                let r = a.median_ns / b.median_ns;
                let _ = writeln!(
                    md,
                    "| {prob} | {form} | {} | {} | {r:.2} | {} |",
                    fmt_ci(&a),
                    fmt_ci(&b),
                    if r <= 0.8 { "met" } else { "**missed**" }
                );
            }
        }
    }
    if let Err(e) = kf_interleaved(o, md) {
        say(&format!("kf_interleaved: {e:#}"));
        let _ = writeln!(md, "\nThe interleaved comparison did not run: {e:#}.");
    }
    md.push_str("\n## Every criterion benchmark (medians)\n\n");
    md.push_str("| benchmark | median | 95 % CI of the median |\n|---|---:|---:|\n");
    for (id, c) in &res {
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
    for (id, c) in &res {
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
    Ok(res)
}

/// Runs `kf_interleaved` and returns its JSON rows.
fn run_kf_interleaved(bin: &Path, rounds: &str) -> Result<Value> {
    run_json(bin, &["--rounds", rounds])
}

/// Runs one of the benchmark binaries with `args` and `--json`, and parses its stdout.
fn run_json(bin: &Path, args: &[&str]) -> Result<Value> {
    say(&format!("{} {} --json", bin.display(), args.join(" ")));
    let out = Command::new(bin)
        .args(args)
        .arg("--json")
        .env("IOX2_LOG_LEVEL", "Error")
        .output()
        .with_context(|| format!("{bin:?}"))?;
    if !out.status.success() {
        bail!("{}", String::from_utf8_lossy(&out.stderr).trim());
    }
    serde_json::from_slice(&out.stdout).with_context(|| format!("{bin:?}: JSON on stdout"))
}

/// The table of `kf_interleaved`'s rows.
fn kf_interleaved_table(md: &mut String, rows: &Value) {
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
            if ratio <= 0.8 { "met" } else { "**missed**" }
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

/// The same comparison, interleaved (`kf_interleaved`): both sides alternate in batches of
/// 1 000 calls in one process, and the ratio is the median of the per-round ratios. First the
/// binary `cargo bench` built (`profile.bench`), then plain `--release` builds: baseline
/// x86-64 and, where the CPU runs it, `x86-64-v3`.
fn kf_interleaved(o: &Opts, md: &mut String) -> Result<()> {
    let rounds = if o.quick { "400" } else { "8000" };
    let rows = run_kf_interleaved(&o.target.join("release/kf_interleaved"), rounds)?;
    let _ = write!(
        md,
        "\n**Interleaved, same process** (`kf_interleaved --rounds {rounds}`, \
         `benches/src/bin/kf_interleaved.rs`): criterion times each benchmark for seconds before \
         the next, and on this VM the speed of the whole machine drifts by 10–20 % over such \
         spans, which lands in the ratio of two sequential medians. Here each round times 1 000 \
         of our steps and 1 000 of `adskalman`'s back to back (alternating which goes first), \
         the ratio is taken per round, and the table gives the median of the per-round ratios \
         and their 10th–90th percentiles. The steps are the same non-inlined functions \
         (`benches/src/compare.rs`) that criterion and callgrind run.\n\n"
    );
    kf_interleaved_table(md, &rows);
    // `cargo bench` builds with `profile.bench` (thin LTO, one codegen unit); a user's
    // `cargo build --release` does not. The two compile the same source differently enough
    // to move the ratio, so both are measured, each in a target directory of its own (the
    // two profiles otherwise overwrite each other's binaries in target/release).
    let plain = build_kf_interleaved(o, "plain-release", None)?;
    let rows = run_kf_interleaved(&plain, rounds)?;
    let _ = write!(
        md,
        "\n**The same, built by plain `cargo build --release`** (the workspace's release profile: \
         no LTO, default codegen units; the tables above are of `profile.bench`, thin LTO and one \
         codegen unit, as criterion builds). What a user's release build of the same code gets. \
         The two builds have the same instruction counts within 1 % but not the same timing: \
         LLVM vectorises and schedules the two differently.\n\n"
    );
    kf_interleaved_table(md, &rows);
    if !cpu_has_x86_64_v3() {
        md.push_str("\nThis CPU does not run `x86-64-v3` code: the AVX2 build was not measured.\n");
        return Ok(());
    }
    // Baseline x86-64 is SSE2: a 4-lane f64 column takes two registers. A deployment on a
    // known host builds for it; both libraries get the same flags (no FMA contraction in
    // Rust, so the results stay bit-identical).
    let v3 = build_kf_interleaved(o, "x86-64-v3", Some("-C target-cpu=x86-64-v3"))?;
    let rows = run_kf_interleaved(&v3, rounds)?;
    let _ = write!(
        md,
        "\n**The same plain release build, both libraries built for `x86-64-v3`** \
         (`RUSTFLAGS=\"-C target-cpu=x86-64-v3\"`: AVX2, what this host runs, instead of the \
         SSE2 baseline, where a 4-lane f64 column takes two registers). Not the verdict — the \
         product's default build is baseline x86-64 — but what a deployment built for its host \
         gets. Rust does not contract `a·b + c` into FMA, so the results are the same bits (the \
         lanes' bit-identity test passes in this build too).\n\n"
    );
    kf_interleaved_table(md, &rows);
    Ok(())
}

/// Builds `kf_interleaved` with `cargo build --release` into `target/<dir>` (with `rustflags`
/// if given) and returns the binary's path.
fn build_kf_interleaved(o: &Opts, dir: &str, rustflags: Option<&str>) -> Result<PathBuf> {
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

fn fmt_ns(ns: f64) -> String {
    if ns >= 1e6 {
        format!("{:.2} ms", ns / 1e6)
    } else if ns >= 1e3 {
        format!("{:.2} µs", ns / 1e3)
    } else {
        format!("{ns:.0} ns")
    }
}

fn fmt_ci(c: &Crit) -> String {
    format!(
        "{} ({}–{})",
        fmt_ns(c.median_ns),
        fmt_ns(c.lo_ns),
        fmt_ns(c.hi_ns)
    )
}

// ------------------------------------------------------------------------------- icount

fn callgrind_ir(bin: &Path, kernel: &str, n: u64) -> Result<u64> {
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

fn icount(o: &Opts, md: &mut String) -> Result<BTreeMap<String, u64>> {
    let bin = o.target.join("release/icount");
    let list = sh(bin.to_str().unwrap_or("icount"), &["list"]).ok_or_else(|| {
        anyhow!("{bin:?} list failed (build it: cargo build --release -p benches)")
    })?;
    let n: u64 = if o.quick { 200 } else { 1000 };
    md.push_str("## Instructions per step on the host (valgrind/callgrind, deterministic)\n\n");
    let _ = writeln!(
        md,
        "`icount KERNEL N` builds the problem, then runs N steps from a fixed state; \
         instructions per step = (I(2N) − I(N)) / N with N = {n}, which cancels process \
         start-up and setup exactly. The 2N run is made twice: the two counts must be equal \
         (\"same count twice\"). The binary is `target/release/icount` (x86-64, built \
         with `profile.bench` like criterion's: thin LTO, one codegen unit); counts are of that \
         binary and change when inlining changes.\n"
    );
    md.push_str("| kernel | I(N) | I(2N) | I(2N) again | same twice | instructions / step |\n|---|---:|---:|---:|---|---:|\n");
    let mut res = BTreeMap::new();
    for k in list.lines() {
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
        for prob in ["3x2_f64", "4x2_f32"] {
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
    md.push_str(KF_NOTES);
    Ok(res)
}

/// The covariance forms compared with `adskalman`: (label, our criterion id, adskalman's id
/// (criterion and callgrind), our callgrind kernel).
const KF_FORMS: [(&str, &str, &str, &str); 2] = [
    ("Joseph", "ours", "adskalman", "kf"),
    (
        "optimal gain",
        "ours_standard",
        "adskalman_symmetric",
        "kf_standard",
    ),
];

/// What was done about the KF target, and what is proposed (the numbers of the "before"
/// column were measured once, with the previous `kalman.rs`, by the same icount method).
const KF_NOTES: &str = "### Our KF step: what was changed\n\n\
Same Joseph form as adskalman's, plus what adskalman skips: the measurement's and the \
posterior's finiteness, a positive-definiteness and singularity test of S, exactly \
symmetric covariances, and the NIS. The first measurement was 1404 instructions per 3x2 f64 \
step against adskalman's 704 (criterion ratio 1.98). What brought it down, each step \
measured by the same icount method:\n\n\
1. one factorisation of S per update, shared by the gain and the NIS; `step` predicts and \
updates into locals and commits once (no saved copy, no rollback);\n\
2. a Cholesky entry point without the asymmetry test, for a matrix symmetrised one line \
earlier (since replaced by 3's `L D Lᵀ`);\n\
3. `linalg_small` (`estimator-core/src/linalg_small.rs`): products as plain loops over const \
dimensions (fully unrolled at these sizes), each symmetric result computed on its upper \
triangle and mirrored (exactly symmetric, no symmetrisation pass), `(I − KC) P` associated as \
`P − K (C P)`, a square-root-free `L D Lᵀ` factorisation of S with reciprocal pivots (the \
factor-and-solve chain is about half as long as `L Lᵀ`'s: no square root and one division \
per pivot), and a one-pass branch-free finiteness test.\n\n\
| instructions / step (binaries of the time) | first | 1 | 1 + 2 | 1 + 2 + 3 | 1 – 4 (`simd`) | adskalman |\n|---|---:|---:|---:|---:|---:|---:|\n\
| kf 3x2 f64 | 1404 | 1119 | 1054 | 770 | 847 | 678 |\n\
| kf 4x2 f32 | 1432 | 1258 | 1247 | 1143 | 721 | 814 |\n\n\
Counts depend on inlining, which changes with the binary: the current ones are in the table \
above (same method).\n\n\
The time ratio fell more than the instruction ratio (the shorter dependency chain of \
`L D Lᵀ` matters more than the instruction count at these sizes), but the ≤ 0.8× target is \
not met: adskalman's unvalidated nalgebra code vectorises the 4×4 f32 products into full \
SIMD registers, which the triangle-wise products here do not (a column-wise variant was \
tried: it made 4x2 f32 slower, 170 ns against 120 ns, and left 3x2 f64 unchanged). \
Two experiments (2026-11-23, same benches, idle machine; not in the product) show what \
the rest of the gap is made of. Without the validation of inputs and outputs (no finiteness \
tests, no NIS; the pivot test kept, as `adskalman`'s Cholesky has one): 617 / 913 \
instructions, 0.93× / 1.10×. With that *and* the expanded Joseph form \
`P − K Gᵀ − G Kᵀ + K S Kᵀ` (algebraically equal for any gain, first-order insensitive to gain \
errors, but no longer a sum of two congruences, so positive semi-definiteness under rounding \
is not preserved the same way): 499 / 653 instructions — far fewer than `adskalman`'s 680 / \
815 — and still 0.91× / 0.95×. At these sizes the step is bound by its dependency chain \
(predict → `C P Cᵀ` → two pivots with a division each → gain → covariance), not by the \
instruction count, and that chain is as long in `adskalman`. So neither dropping the \
validation (which the core's promise — never panic, return an error, keep the last good \
state — forbids) nor a cheaper Joseph variant would reach 0.8×. Shortening the chain with a \
closed-form 2 × 2 inverse of S (one division instead of two, validation kept) was tried too \
and gained nothing: 98 vs 102 ns and 126 vs 95 ns in one run (0.96× / 1.32×), with more \
instructions (885 / 1 189). \
What the vectoriser does was measured last (2026-11-23 06:30 UTC, one run each, same \
benches): with LLVM's SLP vectoriser switched off for the whole build \
(`RUSTFLAGS=\"-C llvm-args=-vectorize-slp=false\"`), our 3x2 f64 step took 89 ns against \
104 ns with it (886 against 773 instructions: the SLP code has fewer instructions but its \
shuffles lengthen the chain), and `adskalman`'s 4x2 f32 step took 158 ns against 93 ns \
(1 998 against 815 instructions). The ratios of that build, 0.79× and 0.82×, do not count: \
the flag meets the target by slowing `adskalman` down. What they show is where the gap is: \
LLVM vectorises nalgebra's column-wise products well and our triangle-wise ones badly. Two \
column-wise rewrites were tried the same morning (not in the product): `mul` alone (4x2 f32 \
1 370 instructions, 151 ns: worse), and the whole step on `[T; N]` columns in axpy form, \
exact symmetry by mirroring (825 / 1 388 instructions; 98 vs 89 ns and 111 vs 102 ns, then \
105 vs 94 ns and 108 vs 95 ns: 1.10–1.12× and 1.08–1.14×). The second brings 4x2 f32 from \
about 1.3× to about 1.1× but leaves 3x2 f64 where it was, and the disassembly shows why it \
stops there: LLVM rebuilds the 4-float columns from scalar loads and shuffles (224 `shufps` \
against 141 `mulps`) instead of keeping them in registers. Neither is near 0.8×. \
Explicit SIMD types came next. A first experiment (the same step and validation on \
`wide::f32x4` / `wide::f64x4` columns, NX ≤ 4 padded to 4 lanes, free summation order) \
measured 0.77× / 0.75× on 4x2 f32 and 0.86× / 0.75× on 3x2 f64 in two runs (07:00–07:10 \
UTC; `adskalman`'s 3x2 f64 median was unusually noisy in the second). What went into the \
core is the constrained version of it, 4. below.\n\n\
4. `linalg_lanes` (feature `simd`, off by default, on x86-64 and AArch64; `ipc-runner` and \
these benches turn it on): the predict and the update, fused in `KalmanFilter::step`, on \
4-lane columns, computing **the same IEEE operations in the same order** as `linalg_small` \
(sums from the first product over `k` ascending, symmetric results from the upper triangle, \
the same `L D Lᵀ` factor). The results are the same bits: tested against the scalar kernels \
on 2 000 random problems (NX 1–4, NY 1–4, f32 and f64, both covariance forms), and by the \
firmware check, whose host side now takes the lanes while the Cortex-M4 keeps the scalar \
code. First measurements (07:30 UTC, one run each): 4x2 f32 83–86 ns against \
`adskalman`'s 82–89 ns (0.95–1.02×; 117–168 ns before), 3x2 f64 92–96 ns against 91–92 ns \
(1.01–1.04×; 99–107 ns before).\n\n\
5. The lanes' step inlined into `KalmanFilter::step`, the scalar fallback out of line and \
`#[cold]` (only with `simd`; scalar targets keep it inline). Before, `step` called the lanes \
as a function that returned `(x⁺, P⁺, NIS)` through memory, copied it, and carried the whole \
scalar path (predict, update, error classification) inline beside it. Found by timing the \
lanes' entry point alone beside the full step (interleaved, 2026-11-23 09:00 UTC): the call \
and copy cost 11 ns of 94 (3x2 f64) and 17 ns of 87 (4x2 f32). In the same scratch harness \
the change took the full step from 94 to 77 ns (3x2 f64, `adskalman` 91 ns) and from 87 to \
71 ns (4x2 f32, `adskalman` 102 ns); same bits (the lanes test). The same session corrected \
an earlier reading of the free-order experiment above: a copy of it constrained to the \
scalar order, same structure otherwise, ran as fast on 3x2 f64 (73–78 against 74–81 ns) \
and about 8 % slower on 4x2 f32 (the sequential 4-term sum of S and ν), so most of that \
experiment's lead over 4. was the call structure fixed here, not the summation order. \
Whether the ratio reaches 0.8 still depends on the minute on this VM: the tables above give \
this run's criterion and interleaved figures, and under load our step slows more than \
`adskalman`'s (interleaved ratios measured between 0.86 and 0.98 on 3x2 f64 and between 0.68 \
and 0.90 on 4x2 f32, Joseph form, 09:00–09:40 UTC). Since then criterion, callgrind and \
`kf_interleaved` call the same eight non-inlined step functions (`benches/src/compare.rs`): \
inlined into each harness's loop, the same source had compiled differently per harness \
(`adskalman`'s step took 661 instructions on both problems inlined into `icount`'s loop; as \
a function of its own it takes 717 on 3x2 f64 and 814 on 4x2 f32 in a plain release build, \
672 and 668 in the `profile.bench` build, ours 758 / 632 and 756 / 628). The figures of 5. \
above are of plain release builds. The `profile.bench` build (thin LTO, one codegen unit, as \
`cargo bench` builds) is slower for our step and faster for `adskalman`'s with nearly the \
same instruction counts (2026-11-23 09:35 UTC, interleaved, the two binaries alternated, \
two runs each: ours 3x2 f64 75 ns plain against 91 ns LTO, `adskalman` 92 against 92 ns; \
ours 4x2 f32 67–68 against 70–71 ns, `adskalman` 103–105 against 81–82 ns); aligning every \
function to 64 bytes did not change the LTO figures, and the LTO build's disassembly has \
more packed and fewer scalar operations in the same step (LLVM's SLP vectoriser again). So \
the interleaved comparison is reported for both builds.\n\n";

// ----------------------------------------------------------------------------- firmware

fn firmware(o: &Opts, md: &mut String) -> Result<()> {
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
    md.push_str("## Instructions per step on the emulated Cortex-M4F (QEMU TCG plugin)\n\n");
    md.push_str(
        "From `.ci/firmware` (QEMU 7.2 `mps2-an386` run with an \
         instruction-counting TCG plugin, f32, `opt-level = \"s\"`): the same binary gives \
         the same count twice (the script fails otherwise).\n\n",
    );
    let _ = writeln!(md, "| {} |", header.join(" | "));
    let _ = writeln!(md, "|{}|", vec!["---"; header.len()].join("|"));
    for l in lines {
        let _ = writeln!(md, "| {} |", l.split(',').collect::<Vec<_>>().join(" | "));
    }
    md.push('\n');
    Ok(())
}

// ---------------------------------------------------------------------------------- ipc

#[derive(Clone, Copy, Debug, Default)]
struct Pct {
    count: u64,
    p50: f64,
    p90: f64,
    p99: f64,
    p999: f64,
    max: f64,
}

impl Pct {
    /// Reads `ipc_runner::latency::Percentiles` as serialised (`report.json`, `ipc_latency
    /// --json`). A missing or non-numeric field is an error, not a NaN in a table.
    fn from_json(v: &Value) -> Result<Self> {
        let f = |k: &str| {
            v[k].as_f64()
                .with_context(|| format!("latency percentiles without a numeric {k:?}: {v}"))
        };
        Ok(Self {
            count: v["count"]
                .as_u64()
                .with_context(|| format!("latency percentiles without \"count\": {v}"))?,
            p50: f("p50_us")?,
            p90: f("p90_us")?,
            p99: f("p99_us")?,
            p999: f("p999_us")?,
            max: f("max_us")?,
        })
    }
    fn row(&self, name: &str) -> String {
        format!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} |",
            self.count, self.p50, self.p90, self.p99, self.p999, self.max
        )
    }
}

impl Pct {
    fn percentiles(&self) -> ipc_runner::latency::Percentiles {
        ipc_runner::latency::Percentiles {
            count: self.count,
            p50_us: self.p50,
            p90_us: self.p90,
            p99_us: self.p99,
            p999_us: self.p999,
            max_us: self.max,
        }
    }
}

/// `benches/` next to the report, where its plots go (created if missing).
fn plots_dir(o: &Opts) -> PathBuf {
    let dir = o
        .out
        .parent()
        .map_or_else(|| PathBuf::from("benches"), |d| d.join("benches"));
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Draws the latency ladders next to the report (`<out dir>/benches/latency-{spin,block}.svg`)
/// and links them from `md`. A plot that cannot be drawn is reported, not fatal.
fn ladders(o: &Opts, md: &mut String, spin: &[(String, Pct)], block: &[(String, Pct)]) {
    let dir = plots_dir(o);
    for (name, title, rows) in [
        (
            "latency-spin.svg",
            "One-way latency, spin (busy-poll) receivers",
            spin,
        ),
        (
            "latency-block.svg",
            "One-way latency, sleeping receivers",
            block,
        ),
    ] {
        let rows: Vec<_> = rows
            .iter()
            .map(|(l, p)| (l.clone(), p.percentiles()))
            .collect();
        match ipc_runner::plot_latency::plot_ladder(title, &rows, &dir.join(name)) {
            Ok(()) => {
                let _ = writeln!(md, "![{title}](benches/{name})\n");
            }
            Err(e) => say(&format!("{name}: {e:#}")),
        }
    }
}

const PCT_HEAD: &str =
    "| path | samples | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs |\n|---|---:|---:|---:|---:|---:|---:|\n";

/// The rate of the pipeline runs, and of the paced raw runs they are compared with.
const PIPELINE_RATE: f64 = 10_000.0;

/// Runs `ipc_latency` and returns `(one-way, round trip)` per mode.
fn ipc_latency(
    o: &Opts,
    samples: u32,
    rate: f64,
    modes: &str,
) -> Result<BTreeMap<String, (Pct, Pct)>> {
    let bin = o.target.join("release/ipc_latency");
    let json = std::env::temp_dir().join(format!(
        "benches-report-ipc-{}-{rate}.json",
        std::process::id()
    ));
    say(&format!(
        "ipc_latency --samples {samples} --rate {rate} --modes {modes}"
    ));
    let st = Command::new(&bin)
        .args(["--samples", &samples.to_string(), "--warmup", "5000"])
        .args(["--rate", &rate.to_string(), "--modes", modes, "--json"])
        .arg(&json)
        .stdout(Stdio::null())
        .status()
        .context("ipc_latency")?;
    if !st.success() {
        bail!("ipc_latency failed ({st})");
    }
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&json)?)?;
    let _ = std::fs::remove_file(&json);
    let mut res = BTreeMap::new();
    for (mode, m) in v.as_object().context("ipc_latency JSON")? {
        res.insert(
            mode.clone(),
            (
                Pct::from_json(&m["one_way"]).with_context(|| format!("{mode} one-way"))?,
                Pct::from_json(&m["round_trip"]).with_context(|| format!("{mode} round trip"))?,
            ),
        );
    }
    Ok(res)
}

/// Raw transports, back to back and paced at the pipeline's rate. Keys: `MODE` (back to
/// back) and `MODE paced` (one ping every 1/[`PIPELINE_RATE`] s).
fn ipc(o: &Opts, md: &mut String) -> Result<BTreeMap<String, (Pct, Pct)>> {
    let samples = if o.quick { 10_000 } else { 30_000 };
    let all = "iox-spin,iox-block,uds-spin,uds-block";
    let mut res = ipc_latency(o, samples, 0.0, all)?;
    for (mode, v) in ipc_latency(o, samples, PIPELINE_RATE, all)? {
        res.insert(format!("{mode} paced"), v);
    }
    md.push_str("## IPC latency: raw transports (ping-pong between two processes)\n\n");
    let _ = writeln!(
        md,
        "`ipc_latency` spawns itself as the peer. Each round sends a 128-byte message carrying \
         its `CLOCK_MONOTONIC` send time; the peer stamps the receive time and answers. \
         **One-way** = ping sent → ping received by the peer (the quantity the pipeline's \
         \"slot sent → estimate published\" is compared with); round trip = ping sent → pong \
         back. Spin = busy-poll on both sides; block = iceoryx2 pub/sub + event service with \
         the receiver asleep in a `WaitSet`, or a blocking `read` on the socket.\n\n\
         Two schedules, {samples} rounds each: **back to back** (the next ping as soon as the \
         pong is in: the whole run lasts a fraction of a second and rarely meets a timer tick \
         or another process) and **paced** at {PIPELINE_RATE} pings/s (`--rate`), sleeping \
         between pings exactly as `channel-sim` sleeps between slots. The paced run is the \
         like-for-like baseline of the pipeline below: same rate, same sleeping sender, same \
         exposure to the rest of the machine.\n"
    );
    md.push_str("### One-way\n\n");
    md.push_str(PCT_HEAD);
    for (mode, (ow, _)) in &res {
        let _ = writeln!(md, "{}", ow.row(mode));
    }
    md.push_str("\n### Round trip\n\n");
    md.push_str(PCT_HEAD);
    for (mode, (_, rt)) in &res {
        let _ = writeln!(md, "{}", rt.row(mode));
    }
    md.push('\n');
    Ok(res)
}

// ----------------------------------------------------------------------------- pipeline

/// The scenario of the pipeline runs: `linear` (stable plant, cheap KF/IKF), so that the
/// figures measure the pipeline rather than an estimator. Seed 001's plant is unstable: over
/// 10⁵ instants its state overflows and the steps turn into rejections.
fn demo_scenario() -> &'static str {
    "linear"
}

/// A demo's report JSON, the process's wall time, and its per-instant end-to-end latencies
/// (`latency.csv`: seconds since the first send, transport µs, end to end µs).
struct DemoRun {
    report: Value,
    secs: f64,
    trace: Vec<ipc_runner::plot_trace::Point>,
}

/// Reads `latency.csv` as written by `ipc-runner demo`.
fn read_trace(path: &Path) -> Result<Vec<ipc_runner::plot_trace::Point>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{path:?}"))?;
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .skip(2)
                .map(str::parse)
                .collect::<Result<_, _>>()
                .with_context(|| format!("{path:?}: {l:?}"))?;
            anyhow::ensure!(f.len() == 3, "{path:?}: {l:?}");
            Ok((f[0], f[1], f[2]))
        })
        .collect()
}

/// Runs `ipc-runner demo`. `latest` adds `--latest-estimates` (estimates on the blackboard
/// instead of the queue).
fn demo(o: &Opts, wait: &str, rate: f64, steps: u32, latest: bool) -> Result<DemoRun> {
    let bin = o.target.join("release/ipc-runner");
    let out = std::env::temp_dir().join(format!(
        "benches-report-demo-{}-{wait}-{rate}",
        std::process::id()
    ));
    say(&format!(
        "ipc-runner demo --wait {wait} --rate {rate} --steps {steps}"
    ));
    let t = Instant::now();
    let res = Command::new("timeout")
        .arg("300")
        .arg(&bin)
        .args([
            "demo",
            "--quiet",
            "--wait",
            wait,
            "--scenario",
            demo_scenario(),
        ])
        .args(["--rate", &rate.to_string(), "--steps", &steps.to_string()])
        .args(latest.then_some("--latest-estimates"))
        .args([
            "--prefix",
            &format!("benches-report-{}-{wait}", std::process::id()),
        ])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("ipc-runner demo");
    let secs = t.elapsed().as_secs_f64();
    let read = || -> Result<DemoRun> {
        let st = res?;
        if !st.success() {
            bail!("ipc-runner demo --wait {wait} --rate {rate} failed ({st})");
        }
        Ok(DemoRun {
            report: serde_json::from_str(&std::fs::read_to_string(out.join("report.json"))?)?,
            secs,
            trace: read_trace(&out.join("latency.csv"))?,
        })
    };
    let v = read();
    let _ = std::fs::remove_dir_all(&out);
    v
}

/// What the spin tails were made of: per queue run of the triples, the slowest 1 % of
/// instants split into isolated ones and episodes (`ipc_runner::tail`), and the median
/// triple's run drawn over time (`benches/latency-trace-spin.svg`).
fn tail_section(
    o: &Opts,
    md: &mut String,
    traces: &[Vec<ipc_runner::plot_trace::Point>],
    median: usize,
) {
    use ipc_runner::tail::{TailBreakdown, EPISODE_MIN};
    let _ = write!(
        md,
        "**What the tail is made of.** Every demo also writes `latency.csv` (one row per \
         instant, in send order) and `latency-trace.svg`. Per queue run above, the slowest \
         1 % of instants by end-to-end latency, split into isolated slow instants and \
         episodes of ≥ {EPISODE_MIN} consecutive ones (≥ {} µs of slots: longer than any \
         one send or step, so a process kept off its core, or both on one core):\n\n\
         | triple | slowest 1 % from µs | instants | runs | in episodes | longest episode |\n\
         |---:|---:|---:|---:|---:|---|\n",
        (EPISODE_MIN as f64 * 1e6 / PIPELINE_RATE) as u64
    );
    for (i, tr) in traces.iter().enumerate() {
        let e2e: Vec<f64> = tr.iter().map(|p| p.2).collect();
        let b = TailBreakdown::of(&e2e, 0.99);
        let at = tr.get(b.longest_at).map_or(0.0, |p| p.0);
        let _ = writeln!(
            md,
            "| {}{} | {:.2} | {} | {} | {} ({:.0} %) | {} instants at {:.2} s |",
            i + 1,
            if i == median { " (median)" } else { "" },
            b.threshold_us,
            b.tail,
            b.runs,
            b.in_episodes,
            100.0 * b.episode_share(),
            b.longest,
            at
        );
    }
    md.push('\n');
    let Some(tr) = traces.get(median) else {
        return;
    };
    let dir = plots_dir(o);
    let name = "latency-trace-spin.svg";
    let title = format!(
        "Pipeline spin, {PIPELINE_RATE} Hz, median triple: end-to-end latency over the run"
    );
    match ipc_runner::plot_trace::plot_trace(&title, tr, &dir.join(name)) {
        Ok(()) => {
            let _ = writeln!(md, "![{title}](benches/{name})\n");
        }
        Err(e) => say(&format!("{name}: {e:#}")),
    }
}

/// How many (raw, queue, blackboard) triples the spin verdict is the median of.
const TRIPLES: usize = 5;

/// The spin target: pipeline p99 ≤ this × raw iceoryx2's.
const SPIN_TARGET: f64 = 1.5;

/// One back-to-back triple of the spin comparison: p99s measured within the same minute.
#[derive(Clone, Copy, Debug)]
struct Triple {
    /// Raw iceoryx2, paced at the pipeline's rate (one-way).
    raw: Pct,
    /// The pipeline end to end, estimates on the queue (the default, the verdict).
    queue: Pct,
    /// The queue run's own iceoryx2 hop (slot sent → received).
    hop: Pct,
    /// The pipeline end to end, estimates on the blackboard.
    board: Pct,
}

impl Triple {
    fn ratio(&self) -> f64 {
        self.queue.p99 / self.raw.p99
    }
    fn board_ratio(&self) -> f64 {
        self.board.p99 / self.raw.p99
    }
    fn own_hop(&self) -> f64 {
        self.queue.p99 / self.hop.p99
    }
}

/// The triple the verdict is read from: the median by the queue's ratio (the upper one of an
/// even count).
fn median_triple(t: &[Triple]) -> usize {
    let mut order: Vec<usize> = (0..t.len()).collect();
    order.sort_by(|&a, &b| t[a].ratio().total_cmp(&t[b].ratio()));
    order[order.len() / 2]
}

/// Range, median and count within a target of some ratios.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Spread {
    lo: f64,
    median: f64,
    hi: f64,
    within: usize,
    n: usize,
}

impl Spread {
    fn of(ratios: impl Iterator<Item = f64>, target: f64) -> Self {
        let mut r: Vec<f64> = ratios.collect();
        r.sort_by(f64::total_cmp);
        Self {
            lo: r[0],
            median: r[r.len() / 2],
            hi: r[r.len() - 1],
            within: r.iter().filter(|&&x| x <= target).count(),
            n: r.len(),
        }
    }
    /// Every ratio on the same side of the target.
    fn unanimous(&self) -> bool {
        self.within == 0 || self.within == self.n
    }
}

fn pipeline(o: &Opts, md: &mut String, raw: &BTreeMap<String, (Pct, Pct)>) -> Result<()> {
    let steps: u32 = if o.quick { 10_000 } else { 30_000 };
    md.push_str("## IPC latency: the full pipeline end to end\n\n");
    md.push_str(
        "`ipc-runner demo` (scenario given below): `channel-sim` publishes slots from its \
         own process, `ipc-runner` receives them, runs every estimator that applies and \
         publishes the estimates. **End to end** = slot's send time (stamped just before \
         `send()`) → all estimates of that instant published; transport = send → received by \
         the runner. Both from the runner's own histograms (`report.json`).\n\n",
    );
    let _ = writeln!(
        md,
        "Scenario `{}`, {steps} instants per run at {PIPELINE_RATE} Hz.\n",
        demo_scenario()
    );
    // The spin target is a ratio of two tails measured minutes apart on a shared VM, so it
    // is measured as triples run back to back (paced raw iceoryx2, the pipeline publishing
    // on the queue, the pipeline publishing on the blackboard), three times; the verdict is
    // on the median triple (by the queue's ratio).
    let mut pairs = Vec::new();
    let mut traces = Vec::new();
    for _ in 0..TRIPLES {
        let raw_now = ipc_latency(o, steps, PIPELINE_RATE, "iox-spin")?;
        let iox = raw_now.get("iox-spin").context("iox-spin row")?.0;
        let queue = demo(o, "spin", PIPELINE_RATE, steps, false)?;
        let lat = &queue.report["latency"];
        let v = demo(o, "spin", PIPELINE_RATE, steps, true)?.report;
        pairs.push(Triple {
            raw: iox,
            queue: Pct::from_json(&lat["end_to_end"])?,
            hop: Pct::from_json(&lat["transport"])?,
            board: Pct::from_json(&v["latency"]["end_to_end"])?,
        });
        traces.push(queue.trace);
    }
    let median = median_triple(&pairs);
    let block = demo(o, "block", PIPELINE_RATE, steps, false)?.report;
    let block_e2e = Pct::from_json(&block["latency"]["end_to_end"])?;
    let block_tr = Pct::from_json(&block["latency"]["transport"])?;
    md.push_str(PCT_HEAD);
    let Triple {
        raw: iox,
        queue: e2e,
        hop: tr,
        board,
    } = pairs[median];
    let hz = PIPELINE_RATE;
    let _ = writeln!(
        md,
        "{}",
        e2e.row(&format!("pipeline spin, {hz} Hz: end to end"))
    );
    let _ = writeln!(
        md,
        "{}",
        tr.row(&format!("pipeline spin, {hz} Hz: transport"))
    );
    let _ = writeln!(
        md,
        "{}",
        board.row(&format!(
            "pipeline spin, {hz} Hz, `--latest-estimates`: end to end"
        ))
    );
    let _ = writeln!(
        md,
        "{}",
        iox.row(&format!("raw iceoryx2 spin paced, {hz} Hz: one-way"))
    );
    let _ = writeln!(
        md,
        "{}",
        block_e2e.row(&format!("pipeline block, {hz} Hz: end to end"))
    );
    let _ = writeln!(
        md,
        "{}",
        block_tr.row(&format!("pipeline block, {hz} Hz: transport"))
    );
    let _ = write!(
        md,
        "\nThe spin rows are the median of {TRIPLES} triples, each = paced raw iceoryx2 \
         (`ipc_latency --modes iox-spin --rate`) immediately followed by the pipeline with \
         estimates on the queue (default) and on the blackboard (`--latest-estimates`). The \
         last two columns compare the queue run with its own iceoryx2 hop (its transport \
         histogram, slot sent → received, measured in the same seconds by the same \
         processes): not the verdict, which is against the ping-pong, but free of the \
         minute-to-minute drift between two runs:\n\n\
         | triple | raw iceoryx2 paced p99 µs | pipeline p99 µs (queue) | ratio | pipeline p99 µs (blackboard) | ratio | its own hop p99 µs | pipeline / own hop |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    for (i, t) in pairs.iter().enumerate() {
        let _ = writeln!(
            md,
            "| {}{} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            i + 1,
            if i == median { " (median)" } else { "" },
            t.raw.p99,
            t.queue.p99,
            t.ratio(),
            t.board.p99,
            t.board_ratio(),
            t.hop.p99,
            t.own_hop()
        );
    }
    md.push('\n');
    let own = Spread::of(pairs.iter().map(Triple::own_hop), SPIN_TARGET);
    let _ = writeln!(
        md,
        "Against its own hop, the pipeline's p99 was {:.2}–{:.2}× (median {:.2}×): the share of \
         the tail that the runner's work (steps, publishing) adds to the IPC it rides on.\n",
        own.lo, own.hi, own.median
    );
    let r_paced = pairs[median].ratio();
    let verdict = |ok: bool| if ok { "met" } else { "**missed**" };
    let queue = Spread::of(pairs.iter().map(Triple::ratio), SPIN_TARGET);
    let _ = writeln!(
        md,
        "Spin mode, p99, target pipeline ≤ {SPIN_TARGET}× raw iceoryx2: **{r_paced:.2}×** against \
         raw iceoryx2 paced at the same rate ({}, median triple). The {TRIPLES} triples ranged \
         {:.2}–{:.2}×, {} of {TRIPLES} within {SPIN_TARGET}×: {}.",
        verdict(r_paced <= SPIN_TARGET),
        queue.lo,
        queue.hi,
        queue.within,
        if queue.unanimous() {
            "the verdict held in every triple"
        } else {
            "on this VM the verdict depends on the minute it is measured in"
        }
    );
    let board_r = Spread::of(pairs.iter().map(Triple::board_ratio), SPIN_TARGET);
    let _ = writeln!(
        md,
        "With the estimates on the blackboard (`--latest-estimates`: one entry per estimator, \
         overwritten in place) the median of the {TRIPLES} ratios is {:.2}× ({} of {TRIPLES} \
         within {SPIN_TARGET}×, range {:.2}–{:.2}×). The verdict above stays on the queue, the \
         default.",
        board_r.median, board_r.within, board_r.lo, board_r.hi,
    );
    if let Some((b2b, _)) = raw.get("iox-spin") {
        let _ = writeln!(
            md,
            "Against the back-to-back ping-pong ({:.2} µs p99) it is {:.2}× ({}): that run \
             lasts a fraction of a second and never sleeps, so its tail is the transport's \
             alone, while a paced sender wakes from a sleep before every message and a \
             5-second run meets timer ticks and the other processes of a 2-core VM.",
            b2b.p99,
            e2e.p99 / b2b.p99,
            verdict(e2e.p99 / b2b.p99 <= 1.5)
        );
    }
    for (key, what) in [("uds-spin paced", "paced"), ("uds-spin", "back to back")] {
        if let Some((uds, _)) = raw.get(key) {
            let _ = writeln!(
                md,
                "Unix socket spin one-way p99 {what}: {:.2} µs = {:.2}× the pipeline's \
                 (target ≥ 10: {}).",
                uds.p99,
                uds.p99 / e2e.p99,
                verdict(uds.p99 / e2e.p99 >= 10.0)
            );
        }
    }
    if let (Some((iox_b, _)), Some((uds_b, _))) = (raw.get("iox-spin"), raw.get("uds-spin")) {
        let _ = writeln!(
            md,
            "The two spin targets together ask for raw iceoryx2 to be ≥ 15× below the \
             socket, because the pipeline contains one iceoryx2 hop; here raw iceoryx2 is \
             {:.2}× below it back to back.",
            uds_b.p99 / iox_b.p99
        );
    }
    md.push('\n');
    tail_section(o, md, &traces, median);
    let raw_row = |key: &str, label: &str| raw.get(key).map(|(ow, _)| (label.to_string(), *ow));
    let spin: Vec<(String, Pct)> = [
        raw_row("iox-spin", "raw iceoryx2, back to back"),
        raw_row("iox-spin paced", &format!("raw iceoryx2, paced {hz} Hz")),
        raw_row("uds-spin", "Unix socket, back to back"),
        raw_row("uds-spin paced", &format!("Unix socket, paced {hz} Hz")),
        Some((format!("pipeline end to end, queue, {hz} Hz"), e2e)),
        Some((format!("pipeline end to end, blackboard, {hz} Hz"), board)),
    ]
    .into_iter()
    .flatten()
    .collect();
    let blocking: Vec<(String, Pct)> = [
        raw_row("iox-block", "raw iceoryx2 (WaitSet), back to back"),
        raw_row(
            "iox-block paced",
            &format!("raw iceoryx2 (WaitSet), paced {hz} Hz"),
        ),
        raw_row("uds-block", "Unix socket (blocking read), back to back"),
        raw_row(
            "uds-block paced",
            &format!("Unix socket (blocking read), paced {hz} Hz"),
        ),
        Some((format!("pipeline end to end, block, {hz} Hz"), block_e2e)),
    ]
    .into_iter()
    .flatten()
    .collect();
    ladders(o, md, &spin, &blocking);
    // Sustained rate: 100 000 slots/s for a few seconds, zero loss required.
    let steps: u32 = if o.quick { 100_000 } else { 1_000_000 };
    let DemoRun {
        report: v, secs, ..
    } = demo(o, "spin", 100_000.0, steps, false)?;
    let c = &v["counts"];
    let lost = c["lost_in_ipc"].as_u64().unwrap_or(u64::MAX);
    let received = c["received"].as_u64().unwrap_or(0);
    let _ = writeln!(
        md,
        "Sustained: channel-sim asked for {steps} slots at 100 000 slots/s, runner in spin \
         mode: {received} received, {lost} lost in the IPC ({}); {:.0} slots/s averaged over \
         the whole demo process ({secs:.2} s wall time including start-up, so a lower bound \
         on the rate achieved).\n",
        if lost == 0 && received == steps as u64 {
            "zero loss: met"
        } else {
            "**loss**"
        },
        received as f64 / secs,
    );
    Ok(())
}

// --------------------------------------------------------------------------------- idle

/// `idle_penalty`: the same small works back to back and paced at the pipeline's rate, the
/// floor under the runner's share of the pipeline's tail on this machine.
fn idle(o: &Opts, md: &mut String) -> Result<()> {
    let bin = o.target.join("release/idle_penalty");
    let samples = if o.quick { "10000" } else { "30000" };
    let rate = PIPELINE_RATE.to_string();
    let v = run_json(&bin, &["--samples", samples, "--rate", &rate])?;
    md.push_str(
        "## What idling costs here

",
    );
    let _ = write!(
        md,
        "`idle_penalty` times the same small works {samples} times back to back and {samples} \
         times paced at {PIPELINE_RATE} Hz, spinning on the clock in between as the runner \
         does (`--wait spin`). The code is the same, so what slows the paced ones is the \
         machine's state after idling: most likely caches and TLB gone cold (this VM exposes no \
         PMU to count the misses). The runner's own work on an instant, its share of the \
         pipeline's end to end, runs in exactly that state.\n\n\
         | work | back to back p50 µs | p99 µs | paced p50 µs | p99 µs | paced / back to back, p99 |\n\
         |---|---:|---:|---:|---:|---:|\n"
    );
    for r in v.as_array().context("idle_penalty rows")? {
        let work = r["work"].as_str().context("work")?;
        let b =
            Pct::from_json(&r["back_to_back"]).with_context(|| format!("{work} back to back"))?;
        let p = Pct::from_json(&r["paced"]).with_context(|| format!("{work} paced"))?;
        let _ = writeln!(
            md,
            "| {work} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2}× |",
            b.p50,
            b.p99,
            p.p50,
            p.p99,
            p.p99 / b.p99
        );
    }
    md.push_str(
        "\n`touch 16 KiB`: one `u64` read and written per cache line of a 16 KiB buffer. \
         `iceoryx2 loan+send`: `loan_uninit` + `write_payload` + `send` of one `Estimate` on \
         a service without subscribers (the runner's publish before 5e02d93); `loaned ahead`: \
         `write_payload` + `send` of a sample loaned after the previous send, off the clock \
         (the runner's publish since).\n\n",
    );
    Ok(())
}

// --------------------------------------------------------------------------------- eval

fn eval(o: &Opts, md: &mut String) -> Result<()> {
    let bin = o.target.join("release/ipc-runner");
    let (runs, horizon) = if o.quick {
        (100u64, 100u32)
    } else {
        (1000, 100)
    };
    md.push_str("## Monte-Carlo evaluation throughput (`ipc-runner eval`)\n\n");
    let _ = writeln!(
        md,
        "Each scenario preset with {runs} runs × horizon {horizon}, seed 1, wall time of the \
         whole process (start-up and report writing included), with one worker thread and \
         with the default (one per core). A step here is one instant of one run, processed \
         by every estimator that applies to the scenario.\n"
    );
    md.push_str("| scenario | estimators | threads | wall s | runs × steps / s |\n|---|---|---:|---:|---:|\n");
    for sc in channel_sim::scenario::preset_names() {
        for threads in [Some(1u32), None] {
            let json = std::env::temp_dir().join(format!(
                "benches-report-eval-{}-{sc}.json",
                std::process::id()
            ));
            // At most 5 minutes per scenario (a slow estimator must not stall the report).
            let mut cmd = Command::new("timeout");
            cmd.arg("300")
                .arg(&bin)
                .args(["eval", "--scenario", sc, "--quiet", "--seed", "1"])
                .args([
                    "--runs",
                    &runs.to_string(),
                    "--horizon",
                    &horizon.to_string(),
                ])
                .arg("--json")
                .arg(&json)
                .stdout(Stdio::null())
                .stderr(Stdio::null());
            if let Some(t) = threads {
                cmd.args(["--threads", &t.to_string()]);
            }
            say(&format!("eval {sc} threads {threads:?}"));
            let t = Instant::now();
            let st = cmd.status().context("ipc-runner eval")?;
            let secs = t.elapsed().as_secs_f64();
            if !st.success() {
                let _ = writeln!(md, "| {sc} | (eval failed: {st}) | | | |");
                continue;
            }
            let names = std::fs::read_to_string(&json)
                .ok()
                .and_then(|s| serde_json::from_str::<Value>(&s).ok())
                .and_then(|v| {
                    v["estimators"]
                        .as_object()
                        .map(|m| m.keys().cloned().collect::<Vec<_>>().join(", "))
                })
                .unwrap_or_default();
            let _ = std::fs::remove_file(&json);
            let _ = writeln!(
                md,
                "| {sc} | {names} | {} | {secs:.2} | {:.0} |",
                threads.map_or_else(
                    || std::thread::available_parallelism()
                        .map_or(0, |n| n.get())
                        .to_string(),
                    |t| t.to_string()
                ),
                (runs * horizon as u64) as f64 / secs
            );
        }
    }
    md.push('\n');
    Ok(())
}

// ---------------------------------------------------------------------------------- main

fn run() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .ok_or_else(|| anyhow!("no workspace root"))?
        .to_path_buf();
    let mut o = Opts {
        quick: false,
        skip: Vec::new(),
        out: root.join("BENCHMARKS.md"),
        target: std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join("target")),
        root,
    };
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => o.quick = true,
            "--skip" => {
                o.skip = args
                    .next()
                    .ok_or_else(|| anyhow!("--skip needs a list"))?
                    .split(',')
                    .map(str::to_string)
                    .collect()
            }
            "--out" => o.out = PathBuf::from(args.next().ok_or_else(|| anyhow!("--out FILE"))?),
            "-h" | "--help" => {
                println!(
                    "report [--quick] [--skip criterion,icount,firmware,ipc,pipeline,idle,eval] [--out FILE]"
                );
                return Ok(());
            }
            x => bail!("unknown argument {x:?}"),
        }
    }
    let t0 = Instant::now();
    let load0 = loadavg();
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "?".into());
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    let rustc = sh("rustc", &["-V"]).unwrap_or_else(|| "?".into());
    let date = sh("date", &["-u", "+%Y-%m-%d %H:%M UTC"]).unwrap_or_else(|| "?".into());
    let commit = sh(
        "git",
        &[
            "-C",
            o.root.to_str().unwrap_or("."),
            "rev-parse",
            "--short",
            "HEAD",
        ],
    )
    .unwrap_or_else(|| "?".into());
    let valgrind = sh("valgrind", &["--version"]).unwrap_or_else(|| "not installed".into());

    let mut body = String::new();
    let mut failures = Vec::new();
    let mut raw = BTreeMap::new();
    type Part<'a> = (
        &'a str,
        Box<dyn FnMut(&Opts, &mut String) -> Result<()> + 'a>,
    );
    let parts: Vec<Part<'_>> = vec![
        ("criterion", Box::new(|o, md| criterion(o, md).map(|_| ()))),
        ("icount", Box::new(|o, md| icount(o, md).map(|_| ()))),
        ("firmware", Box::new(firmware)),
        (
            "ipc",
            Box::new(|o, md| {
                raw = ipc(o, md)?;
                Ok(())
            }),
        ),
    ];
    // Each part writes into its own buffer, kept only if the part completed.
    let mut keep = |name: &str, r: Result<()>, part: String, body: &mut String| match r {
        Ok(()) => body.push_str(&part),
        Err(e) => {
            say(&format!("{name}: {e:#}"));
            failures.push(format!("{name}: {e:#}"));
        }
    };
    for (name, mut f) in parts {
        if o.runs(name) {
            let mut part = String::new();
            let r = f(&o, &mut part);
            keep(name, r, part, &mut body);
        }
    }
    if o.runs("pipeline") {
        let mut part = String::new();
        let r = pipeline(&o, &mut part, &raw);
        keep("pipeline", r, part, &mut body);
    }
    if o.runs("idle") {
        let mut part = String::new();
        let r = idle(&o, &mut part);
        keep("idle", r, part, &mut body);
    }
    if o.runs("eval") {
        let mut part = String::new();
        let r = eval(&o, &mut part);
        keep("eval", r, part, &mut body);
    }
    let load1 = loadavg();

    let mut md = String::new();
    md.push_str("# Benchmarks\n\n");
    md.push_str(
        "Generated by `benches/run.sh` (one command: builds, runs every part below, rewrites \
         this file). Do not edit by hand.\n\n",
    );
    let _ = writeln!(md, "| | |\n|---|---|");
    let _ = writeln!(md, "| date | {date} |");
    let _ = writeln!(md, "| commit | {commit} |");
    let _ = writeln!(md, "| CPU | {cpu} |");
    let _ = writeln!(md, "| nproc | {nproc} |");
    let _ = writeln!(md, "| rustc | {rustc} |");
    let _ = writeln!(md, "| valgrind | {valgrind} |");
    let _ = writeln!(
        md,
        "| load average (1/5/15 min) at start / end | {load0} / {load1} |"
    );
    let _ = writeln!(
        md,
        "| mode | {} |",
        if o.quick {
            "`--quick` (short runs: indicative only)"
        } else {
            "full"
        }
    );
    let _ = writeln!(md, "| duration | {:.0} s |\n", t0.elapsed().as_secs_f64());
    // The 1-minute load average at the start, against the core count: above ~1 per core,
    // other processes competed for the cores while the figures were taken.
    let load_start: f64 = load0
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let busy = load_start.is_nan() || load_start >= cores;
    let _ = write!(
        md,
        "**Noise.** {} Tails (p99.9, max) of the latency tables measure preemption more than \
         the IPC, and spin modes suffer most (a spinning process needs a core of its own; a \
         spinning runner and a publisher share {cores:.0} cores here, with nothing pinned). \
         Read the **ratios measured in the same run** and the **instruction counts** \
         (deterministic) rather than single absolute times.\n\n",
        if busy {
            format!(
                "The machine was busy (1-minute load average {load_start:.1} on {cores:.0} \
                 cores at the start): absolute times are inflated and noisy."
            )
        } else {
            format!(
                "The machine was otherwise idle (1-minute load average {load_start:.1} on \
                 {cores:.0} cores at the start; the run itself keeps one to two cores busy)."
            )
        }
    );
    md.push_str(&body);
    if !failures.is_empty() {
        md.push_str("## Parts that did not run\n\n");
        for f in &failures {
            let _ = writeln!(md, "- {f}");
        }
        md.push('\n');
    }
    std::fs::write(&o.out, md).with_context(|| format!("write {:?}", o.out))?;
    say(&format!("wrote {:?}", o.out));
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("report: {e:#}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_runner::latency::Percentiles;

    fn pct(p99: f64) -> Pct {
        Pct {
            count: 1,
            p99,
            ..Pct::default()
        }
    }

    #[test]
    fn reads_what_the_runner_and_ipc_latency_write() {
        let p = Percentiles {
            count: 30_000,
            p50_us: 0.5,
            p90_us: 0.56,
            p99_us: 0.91,
            p999_us: 9.8,
            max_us: 1500.25,
        };
        let back = Pct::from_json(&serde_json::to_value(p).unwrap()).unwrap();
        assert_eq!(back.percentiles(), p);
        // A renamed or missing field fails loudly instead of printing NaN in BENCHMARKS.md.
        let mut v = serde_json::to_value(p).unwrap();
        v.as_object_mut().unwrap().remove("p99_us");
        let e = Pct::from_json(&v).unwrap_err();
        assert!(format!("{e:#}").contains("p99_us"), "{e:#}");
        assert!(Pct::from_json(&Value::Null).is_err());
    }

    #[test]
    fn the_verdict_is_read_from_the_median_triple_by_the_queue_ratio() {
        // Queue ratios 2.0, 1.2, 3.0, 1.6, 1.4 → sorted 1.2 1.4 1.6 2.0 3.0: median is the 4th.
        let t: Vec<Triple> = [(1.0, 2.0), (1.0, 1.2), (0.5, 1.5), (1.0, 1.6), (1.0, 1.4)]
            .iter()
            .map(|&(raw, queue)| Triple {
                raw: pct(raw),
                queue: pct(queue),
                hop: pct(raw),
                // The blackboard ratio must not decide which triple is the median.
                board: pct(10.0 / queue),
            })
            .collect();
        assert_eq!(median_triple(&t), 3);
        assert_eq!(
            median_triple(&t[..4]),
            0,
            "upper median of 1.2 1.6 2.0 3.0: 2.0"
        );
        assert_eq!(median_triple(&t[..1]), 0);
    }

    #[test]
    fn spread_counts_the_ratios_within_the_target() {
        let s = Spread::of([2.13, 1.6, 1.94, 2.26, 2.89].into_iter(), SPIN_TARGET);
        assert_eq!(
            s,
            Spread {
                lo: 1.6,
                median: 2.13,
                hi: 2.89,
                within: 0,
                n: 5
            }
        );
        assert!(s.unanimous());
        let mixed = Spread::of([1.43, 1.57, 7.03, 1.55, 1.9].into_iter(), SPIN_TARGET);
        assert_eq!((mixed.within, mixed.median), (1, 1.57));
        assert!(!mixed.unanimous());
        // The target itself counts as met.
        assert_eq!(Spread::of([1.5].into_iter(), SPIN_TARGET).within, 1);
    }
}
