//! Part `pipeline`: `ipc-runner demo` end to end, spin (the verdict against raw iceoryx2) and
//! blocking, then a sustained run.

use crate::demo::{demo, demo_scenario};
use crate::format::verdict;
use crate::ipc_latency::{self, Raw};
use crate::opts::Opts;
use crate::pct::{Pct, PCT_HEAD};
use crate::plots::ladders;
use crate::prose;
use crate::rate::PIPELINE_RATE;
use crate::spin_verdict::{median_triple, Spread, Triple, SPIN_TARGET, TRIPLES};
use crate::{sustained, tail_breakdown};
use anyhow::{Context, Result};
use std::fmt::Write as _;

/// `raw`: what part `ipc` measured (empty if it did not run), for the comparisons with the
/// back-to-back ping-pong and the socket.
pub fn part(o: &Opts, md: &mut String, raw: &Raw) -> Result<()> {
    let steps: u32 = if o.quick { 10_000 } else { 30_000 };
    prose::push(md, &intro(steps));
    // The spin target is a ratio of two tails measured minutes apart on a shared VM, so it
    // is measured as triples run back to back (paced raw iceoryx2, the pipeline publishing
    // on the queue, the pipeline publishing on the blackboard), three times; the verdict is
    // on the median triple (by the queue's ratio).
    let mut pairs = Vec::new();
    let mut traces = Vec::new();
    for _ in 0..TRIPLES {
        let raw_now = ipc_latency::run(o, steps, PIPELINE_RATE, "iox-spin")?;
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
    for (p, label) in [
        (e2e, format!("pipeline spin, {hz} Hz: end to end")),
        (tr, format!("pipeline spin, {hz} Hz: transport")),
        (
            board,
            format!("pipeline spin, {hz} Hz, `--latest-estimates`: end to end"),
        ),
        (iox, format!("raw iceoryx2 spin paced, {hz} Hz: one-way")),
        (block_e2e, format!("pipeline block, {hz} Hz: end to end")),
        (block_tr, format!("pipeline block, {hz} Hz: transport")),
    ] {
        let _ = writeln!(md, "{}", p.row(&label));
    }
    md.push('\n');
    prose::push(md, &triples_prose());
    md.push_str(
        "| triple | raw iceoryx2 paced p99 µs | pipeline p99 µs (queue) | ratio | pipeline p99 µs (blackboard) | ratio | its own hop p99 µs | pipeline / own hop |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|\n",
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
    verdicts(md, &pairs, median, raw);
    md.push('\n');
    tail_breakdown::section(o, md, &traces, median);
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
    sustained::section(o, md)
}

/// The spin targets' sentences: against the pipeline's own hop, against paced raw iceoryx2
/// (the verdict), on the blackboard, and against the raw runs of part `ipc`.
fn verdicts(md: &mut String, pairs: &[Triple], median: usize, raw: &Raw) {
    let e2e = pairs[median].queue;
    let own = Spread::of(pairs.iter().map(Triple::own_hop), SPIN_TARGET);
    let _ = writeln!(
        md,
        "Against its own hop, the pipeline's p99 was {:.2}–{:.2}× (median {:.2}×): the share of \
         the tail that the runner's work (steps, publishing) adds to the IPC it rides on.\n",
        own.lo, own.hi, own.median
    );
    let r_paced = pairs[median].ratio();
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
}

fn intro(steps: u32) -> String {
    prose::fill(
        include_str!("prose/pipeline.md"),
        &[
            ("scenario", &demo_scenario()),
            ("steps", &steps),
            ("rate", &PIPELINE_RATE),
        ],
    )
}

fn triples_prose() -> String {
    prose::fill(
        include_str!("prose/spin_triples.md"),
        &[("triples", &TRIPLES)],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(30_000).contains("Scenario `linear`, 30000 instants per run"));
        assert!(super::triples_prose().contains("the median of 5 triples"));
    }
}
