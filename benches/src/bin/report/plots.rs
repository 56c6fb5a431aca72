//! The latency plots drawn next to the report and linked from it.

use crate::command::say;
use crate::opts::Opts;
use crate::pct::Pct;
use std::fmt::Write as _;
use std::path::PathBuf;

/// `benches/` next to the report, where its plots go (created if missing).
pub fn plots_dir(o: &Opts) -> PathBuf {
    let dir = o
        .out
        .parent()
        .map_or_else(|| PathBuf::from("benches"), |d| d.join("benches"));
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Draws the latency ladders next to the report (`<out dir>/benches/latency-{spin,block}.svg`)
/// and links them from `md`. A plot that cannot be drawn is reported, not fatal.
pub fn ladders(o: &Opts, md: &mut String, spin: &[(String, Pct)], block: &[(String, Pct)]) {
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
