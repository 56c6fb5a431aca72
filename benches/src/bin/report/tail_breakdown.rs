//! What the spin tails were made of: per queue run of the triples, the slowest 1 % of
//! instants split into isolated ones and episodes (`ipc_runner::tail`), and the median
//! triple's run drawn over time (`benches/latency-trace-spin.svg`).

use crate::command::say;
use crate::opts::Opts;
use crate::plots::plots_dir;
use crate::prose;
use crate::rate::PIPELINE_RATE;
use ipc_runner::tail::{TailBreakdown, EPISODE_MIN};
use std::fmt::Write as _;

pub fn section(
    o: &Opts,
    md: &mut String,
    traces: &[Vec<ipc_runner::plot_trace::Point>],
    median: usize,
) {
    prose::push(md, &intro());
    md.push_str(
        "| triple | slowest 1 % from µs | instants | runs | in episodes | longest episode |\n\
         |---:|---:|---:|---:|---:|---|\n",
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

fn intro() -> String {
    prose::fill(
        include_str!("prose/tail_breakdown.md"),
        &[
            ("episode_min", &EPISODE_MIN),
            (
                "episode_us",
                &((EPISODE_MIN as f64 * 1e6 / PIPELINE_RATE) as u64),
            ),
        ],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(!super::intro().contains('{'));
    }
}
