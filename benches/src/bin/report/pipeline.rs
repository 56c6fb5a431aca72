//! Part `pipeline`: `ipc-runner demo` end to end, one run with a spinning runner and one with a
//! sleeping one, in one table.
//!
//! What this part measured before (five spin triples against paced raw iceoryx2, the slowest
//! 1 % split into episodes, the idling penalty, a sustained run) chased the p99 tails of a
//! shared 2-core VM, which moved with the minute they were measured in; it was retired with
//! issue #23's regeneration of `BENCHMARKS.md` (its last figures are in the git history of
//! the file).

use crate::demo::{demo, demo_scenario};
use crate::opts::Opts;
use crate::pct::{Pct, PCT_HEAD};
use crate::prose;
use crate::rate::PIPELINE_RATE;
use anyhow::Result;
use std::fmt::Write as _;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let steps: u32 = if o.quick { 10_000 } else { 30_000 };
    prose::push(md, &intro(steps));
    let hz = PIPELINE_RATE;
    md.push_str(PCT_HEAD);
    for wait in ["spin", "block"] {
        let r = demo(o, wait, hz, steps)?;
        let lat = &r["latency"];
        for (key, what) in [("end_to_end", "end to end"), ("transport", "transport")] {
            let p = Pct::from_json(&lat[key])?;
            let _ = writeln!(
                md,
                "{}",
                p.row(&format!("pipeline {wait}, {hz} Hz: {what}"))
            );
        }
    }
    md.push('\n');
    Ok(())
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

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(30_000).contains("Scenario `linear`, 30000 instants per run"));
    }
}
