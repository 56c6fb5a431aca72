//! Part `view`: what the live view costs the loop (docs/view.md, "Cost to the loop"; issue
//! #36: the end-to-end p50 with a connected page within 5 % of without). Short `demo` runs
//! in pairs, one without a view and one with `--view` and a page reading every frame, the
//! order alternating from pair to pair, all in this process; per pair the ratio of the two
//! p50s, then the median ratio and its spread over the pairs — a pair's two runs are seconds
//! apart, so a VM whose load drifts over minutes moves both. Beside it, the instructions the
//! loop's tap executes per instant with and without a view (callgrind, deterministic), which
//! do not depend on the load at all.

use crate::command::say;
use crate::demo::demo_scenario;
use crate::icount::callgrind_ir;
use crate::opts::Opts;
use crate::prose;
use anyhow::{anyhow, bail, Context, Result};
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// The loop's rate in these runs.
const RATE: f64 = 1000.0;

/// One run: the end-to-end p50 and p99 (µs) and the bytes the page read (`None` without a
/// view).
struct Run {
    p50: f64,
    p99: f64,
    page_bytes: Option<u64>,
}

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let (pairs, steps) = if o.quick { (4, 1000) } else { (30, 3000) };
    prose::push(md, &intro(pairs, steps));
    let rows = run_pairs(o, pairs, steps)?;
    write_pairs(md, pairs, &rows);
    let (n, per) = tap_per_instant(o)?;
    let (ln, reps, per_instant) = loop_per_instant(o)?;
    prose::push(
        md,
        &prose::fill(
            include_str!("prose/view_loop.md"),
            &[
                ("n", &ln),
                ("reps", &reps),
                ("rate", &LOOP_RATE),
                ("scenario", &demo_scenario()),
                ("table", &loop_table(&per_instant)),
            ],
        ),
    );
    prose::push(
        md,
        &prose::fill(
            include_str!("prose/view_icount.md"),
            &[
                ("n", &n),
                ("off", &format!("{:.1}", per[0].1)),
                ("on", &format!("{:.1}", per[1].1)),
                ("diff", &format!("{:.1}", per[1].1 - per[0].1)),
            ],
        ),
    );
    Ok(())
}

/// `pairs` pairs of runs of `steps` instants, one without a view and one with a page, the
/// order alternating; each pair as (without, with).
fn run_pairs(o: &Opts, pairs: usize, steps: u32) -> Result<Vec<(Run, Run)>> {
    let mut rows = Vec::new();
    for i in 0..pairs {
        // Alternating order: a trend over the part cancels instead of favouring one side.
        let view_first = i % 2 == 1;
        let a = run(o, view_first, steps, i)?;
        let b = run(o, !view_first, steps, i)?;
        let (off, on) = if view_first { (b, a) } else { (a, b) };
        say(&format!(
            "view pair {i}: p50 {:.1} µs without, {:.1} µs with a page ({} bytes read)",
            off.p50,
            on.p50,
            on.page_bytes.unwrap_or(0)
        ));
        rows.push((off, on));
    }
    Ok(rows)
}

/// The pairs' table: the median p50s, the ratios' median and spread, the p99s and the bytes.
fn write_pairs(md: &mut String, pairs: usize, rows: &[(Run, Run)]) {
    let mut ratios: Vec<f64> = rows.iter().map(|(off, on)| on.p50 / off.p50).collect();
    ratios.sort_by(f64::total_cmp);
    let q = |p: f64| quantile(&ratios, p);
    let median = |f: &dyn Fn(&(Run, Run)) -> f64| {
        let mut v: Vec<f64> = rows.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        quantile(&v, 0.5)
    };
    let slower = rows.iter().filter(|(off, on)| on.p50 > off.p50).count();
    let bytes = median(&|r| r.1.page_bytes.unwrap_or(0) as f64);
    let _ = writeln!(
        md,
        "| pairs | p50 without (median) | p50 with a page (median) | ratio of the pair's p50s: median | 25–75 % | min–max | pairs slower with a page |\n|---:|---:|---:|---:|---:|---:|---:|\n| {pairs} | {:.1} µs | {:.1} µs | **{:.3}** | {:.3}–{:.3} | {:.3}–{:.3} | {slower} of {pairs} |\n",
        median(&|r| r.0.p50),
        median(&|r| r.1.p50),
        q(0.5),
        q(0.25),
        q(0.75),
        q(0.0),
        q(1.0),
    );
    let _ = writeln!(
        md,
        "p99 (medians over the pairs): {:.0} µs without, {:.0} µs with a page. The page read {:.0} kB per run (median).\n",
        median(&|r| r.0.p99),
        median(&|r| r.1.p99),
        bytes / 1e3
    );
}

/// The tap's instructions per instant, (I(2N) − I(N)) / N as part `icount` counts, without
/// and with a view; and N.
fn tap_per_instant(o: &Opts) -> Result<(u64, Vec<(&'static str, f64)>)> {
    let bin = o.target.join("release/icount");
    let n: u64 = if o.quick { 2000 } else { 20_000 };
    let mut per = Vec::new();
    for k in ["view/tap-off", "view/tap-on"] {
        say(&format!("callgrind {k}"));
        let a = callgrind_ir(&bin, k, n)?;
        let b = callgrind_ir(&bin, k, 2 * n)?;
        per.push((k, b.saturating_sub(a) as f64 / n as f64));
    }
    Ok((n, per))
}

/// `[view off/on][function]` → the per-instant figures of the runs.
type PerInstant = Vec<Vec<Vec<f64>>>;

/// The loop, instant by instant, with and without a page: the demo's main thread under
/// callgrind, three functions' inclusive counts, (I(2N) − I(N)) / N, `reps` runs each.
/// Returns N, `reps` and the figures.
fn loop_per_instant(o: &Opts) -> Result<(u32, usize, PerInstant)> {
    let (ln, reps) = if o.quick { (500, 1) } else { (2000, 2) };
    let mut per_instant = vec![vec![Vec::new(); LOOP_FUNCTIONS.len()]; 2];
    for r in 0..reps {
        for (i, view) in [false, true].into_iter().enumerate() {
            say(&format!("callgrind: the demo's loop, view {view}, run {r}"));
            let a = loop_ir(o, view, ln, r)?;
            let b = loop_ir(o, view, 2 * ln, r)?;
            for f in 0..LOOP_FUNCTIONS.len() {
                if let (Some(a), Some(b)) = (a[f], b[f]) {
                    per_instant[i][f].push(b.saturating_sub(a) as f64 / f64::from(ln));
                }
            }
        }
    }
    Ok((ln, reps, per_instant))
}

/// The loop's table: each function's instructions per instant without and with a page (the
/// runs' span) and the ratio of their means.
fn loop_table(per_instant: &PerInstant) -> String {
    let span = |v: &[f64]| {
        if v.is_empty() {
            return "–".to_string();
        }
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if hi - lo < 0.5 {
            format!("{lo:.0}")
        } else {
            format!("{lo:.0}–{hi:.0}")
        }
    };
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mut table = String::from(
        "| function (inclusive) | what it is | instructions / instant, no view | with a page | with ÷ without |\n|---|---|---:|---:|---:|\n",
    );
    for (f, (name, what)) in LOOP_FUNCTIONS.iter().enumerate() {
        let (off, on) = (&per_instant[0][f], &per_instant[1][f]);
        let ratio = if off.is_empty() || on.is_empty() {
            "–".to_string()
        } else {
            format!("{:.3}", mean(on) / mean(off))
        };
        let _ = writeln!(
            table,
            "| `{name}` | {what} | {} | {} | {ratio} |",
            span(off),
            span(on)
        );
    }
    table
}

fn intro(pairs: usize, steps: u32) -> String {
    prose::fill(
        include_str!("prose/view.md"),
        &[
            ("pairs", &pairs),
            ("steps", &steps),
            ("rate", &RATE),
            ("scenario", &demo_scenario()),
        ],
    )
}

/// The value at fraction `p` of `sorted` (linear between neighbours).
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let at = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (at - lo as f64)
}

/// The rate of the runs under callgrind: slow enough for the loop under valgrind to keep up,
/// so that every instant is one wake-up.
const LOOP_RATE: f64 = 200.0;

/// The loop's functions counted, each with what it is: the symbol's tail in callgrind's
/// function names.
const LOOP_FUNCTIONS: [(&str, &str); 3] = [
    (
        "Runner::step_and_publish",
        "the latency path: every estimator stepped, every estimate published",
    ),
    (
        "Runner::on_instant",
        "the instant: the latency path, then the histograms, the evaluation and the view's tap",
    ),
    (
        "Loop::drain",
        "the loop's work per wake-up: the slots received and assembled, the instants",
    ),
];

/// The inclusive instructions of [`LOOP_FUNCTIONS`] on the main thread (the loop) of a
/// `demo --wait block` of `steps` instants under callgrind, with a view and a page reading it
/// when `view`; `None` where callgrind saw no such function (inlined).
fn loop_ir(o: &Opts, view: bool, steps: u32, rep: usize) -> Result<[Option<u64>; 3]> {
    let tag = format!(
        "{}-{rep}-{steps}-{}",
        std::process::id(),
        if view { "on" } else { "off" }
    );
    let dir = std::env::temp_dir().join(format!("benches-report-viewloop-{tag}"));
    std::fs::create_dir_all(&dir)?;
    let mut child = loop_command(o, view, steps, &tag, &dir)
        .spawn()
        .context("valgrind ipc-runner demo")?;
    let err = child.stderr.take().expect("piped");
    let page = std::thread::spawn(move || page_reading_all(err));
    let status = child.wait().context("valgrind ipc-runner demo")?;
    page.join()
        .map_err(|_| anyhow!("the page's thread panicked"))??;
    if !status.success() {
        bail!("valgrind ipc-runner demo (view: {view}, {steps} instants) failed ({status})");
    }
    // --separate-threads: one file per thread, `-01` the main thread, which runs the loop.
    let out = Command::new("callgrind_annotate")
        .args(["--inclusive=yes", "--threshold=100"])
        .arg(dir.join("cg.out-01"))
        .output()
        .context("callgrind_annotate (valgrind)")?;
    let _ = std::fs::remove_dir_all(&dir);
    if !out.status.success() {
        bail!("callgrind_annotate failed");
    }
    let text = String::from_utf8_lossy(&out.stdout);
    Ok(LOOP_FUNCTIONS.map(|(name, _)| inclusive(&text, name)))
}

/// The `demo --wait block` of [`loop_ir`] under callgrind (collecting in the loop's drain,
/// one file per thread in `dir`), with a view when `view`; stderr piped for the view's address.
fn loop_command(o: &Opts, view: bool, steps: u32, tag: &str, dir: &Path) -> Command {
    let bin = o.target.join("release/ipc-runner");
    let mut cmd = Command::new("timeout");
    cmd.arg("600")
        .arg("valgrind")
        .args([
            "--tool=callgrind",
            "--separate-threads=yes",
            "--toggle-collect=ipc_runner::run::slot_loop::Loop::drain",
        ])
        .arg(format!(
            "--callgrind-out-file={}",
            dir.join("cg.out").display()
        ))
        .arg(&bin)
        .args(["demo", "--quiet", "--wait", "block", "--scenario"])
        .arg(demo_scenario())
        .args([
            "--rate",
            &LOOP_RATE.to_string(),
            "--steps",
            &steps.to_string(),
        ])
        .args(["--prefix", &format!("benches-report-viewloop-{tag}")])
        .arg("--out")
        .arg(dir.join("out"))
        .env("IOX2_LOG_LEVEL", "Error")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if view {
        cmd.args(["--view", "--view-addr", "127.0.0.1:0"]);
    }
    cmd
}

/// The page of [`loop_ir`]: reads the demo's stderr until the view says where it is (none
/// without a view), then reads the view until it closes, draining the rest of stderr.
fn page_reading_all(err: std::process::ChildStderr) -> Result<()> {
    let mut lines = BufReader::new(err).lines();
    let mut s = None;
    for l in lines.by_ref() {
        let l = l?;
        if let Some(a) = l.strip_prefix("view: http://") {
            s = Some(page_connect(a.trim_end_matches('/'))?);
            break;
        }
    }
    let Some(mut s) = s else { return Ok(()) };
    let drain = std::thread::spawn(move || lines.for_each(drop));
    let mut buf = vec![0u8; 1 << 16];
    while let Ok(k) = s.read(&mut buf) {
        if k == 0 {
            break;
        }
    }
    let _ = drain.join();
    Ok(())
}

/// The count of the first line of `callgrind_annotate` output whose function ends in `name`
/// (`9,445,308 (100.0%)  ???:path::to::name [binary]`).
fn inclusive(annotate: &str, name: &str) -> Option<u64> {
    annotate.lines().find_map(|l| {
        let (count, rest) = l.trim_start().split_once(' ')?;
        let func = rest.split_whitespace().nth(1)?;
        if !func.ends_with(&format!("::{name}")) {
            return None;
        }
        count.replace(',', "").parse().ok()
    })
}

/// A page's websocket to the view at `addr` (host:port), upgraded.
fn page_connect(addr: &str) -> Result<std::net::TcpStream> {
    let mut s = std::net::TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(600)))?;
    write!(
        s,
        "GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )?;
    Ok(s)
}

/// One `demo` of `steps` instants at [`RATE`], with a view and a reading page when `view`.
fn run(o: &Opts, view: bool, steps: u32, pair: usize) -> Result<Run> {
    let tag = format!(
        "{}-{pair}-{}",
        std::process::id(),
        if view { "on" } else { "off" }
    );
    let out = std::env::temp_dir().join(format!("benches-report-view-{tag}"));
    let mut child = run_command(o, view, steps, &tag, &out)
        .spawn()
        .context("ipc-runner demo")?;
    // The page: it connects as soon as the view says where it is, and reads every byte until
    // the process ends.
    let page = child
        .stderr
        .take()
        .map(|err| std::thread::spawn(move || page_counting_bytes(err)));
    let status = child.wait().context("ipc-runner demo")?;
    let page_bytes = match page {
        Some(t) => Some(
            t.join()
                .map_err(|_| anyhow!("the page's thread panicked"))??,
        ),
        None => None,
    };
    let res = if status.success() {
        end_to_end_latency(&out)
    } else {
        Err(anyhow!("ipc-runner demo (view: {view}) failed ({status})"))
    };
    let _ = std::fs::remove_dir_all(&out);
    let (p50, p99) = res?;
    Ok(Run {
        p50,
        p99,
        page_bytes,
    })
}

/// The `demo --wait spin` of [`run`], writing to `out`; with a view (stderr piped for its
/// address) when `view`.
fn run_command(o: &Opts, view: bool, steps: u32, tag: &str, out: &Path) -> Command {
    let bin = o.target.join("release/ipc-runner");
    let mut cmd = Command::new("timeout");
    cmd.arg("300")
        .arg(&bin)
        .args(["demo", "--quiet", "--wait", "spin", "--scenario"])
        .arg(demo_scenario())
        .args(["--rate", &RATE.to_string(), "--steps", &steps.to_string()])
        .args(["--prefix", &format!("benches-report-view-{tag}")])
        .arg("--out")
        .arg(out)
        .env("IOX2_LOG_LEVEL", "Error")
        .stdout(Stdio::null());
    if view {
        cmd.args(["--view", "--view-addr", "127.0.0.1:0"])
            .stderr(Stdio::piped());
    } else {
        cmd.stderr(Stdio::null());
    }
    cmd
}

/// The page of [`run`]: waits for the view's address on the demo's stderr, then reads every
/// byte of the view until the process ends (the rest of stderr drained so that the demo never
/// blocks on it); the bytes read.
fn page_counting_bytes(err: std::process::ChildStderr) -> Result<u64> {
    let mut lines = BufReader::new(err).lines();
    let addr = loop {
        let l = lines
            .next()
            .ok_or_else(|| anyhow!("the demo ended before its view"))??;
        if let Some(a) = l.strip_prefix("view: http://") {
            break a.trim_end_matches('/').to_string();
        }
    };
    // The rest of stderr is drained so that the demo never blocks on it.
    let drain = std::thread::spawn(move || lines.for_each(drop));
    let mut s = page_connect(&addr)?;
    let mut buf = vec![0u8; 1 << 16];
    let mut n = 0u64;
    loop {
        match s.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(k) => n += k as u64,
        }
    }
    let _ = drain.join();
    Ok(n)
}

/// The end-to-end p50 and p99 (µs) of the run's `report.json` in `out`.
fn end_to_end_latency(out: &Path) -> Result<(f64, f64)> {
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json"))?)?;
    let e = &r["latency"]["end_to_end"];
    let f = |k: &str| {
        e[k].as_f64()
            .ok_or_else(|| anyhow!("report.json: no latency.end_to_end.{k}"))
    };
    Ok((f("p50_us")?, f("p99_us")?))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(30, 3000).contains("30 pairs of runs of 3000 instants"));
    }

    #[test]
    fn callgrind_annotate_lines_parse() {
        let t = "Profiled target: x\n9,445,308 (100.0%)  ???:ipc_runner::run::slot_loop::Loop::drain [/b]\n5,388,888 (57.05%)  ???:ipc_runner::run::instant::Runner::on_instant [/b]\n";
        assert_eq!(super::inclusive(t, "Loop::drain"), Some(9_445_308));
        assert_eq!(super::inclusive(t, "Runner::on_instant"), Some(5_388_888));
        assert_eq!(super::inclusive(t, "Runner::step_and_publish"), None);
    }

    #[test]
    fn quantiles_interpolate() {
        let v = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(super::quantile(&v, 0.5), 2.5);
        assert_eq!(super::quantile(&v, 0.0), 1.0);
        assert_eq!(super::quantile(&v, 1.0), 4.0);
        assert_eq!(super::quantile(&[7.0], 0.25), 7.0);
    }
}
