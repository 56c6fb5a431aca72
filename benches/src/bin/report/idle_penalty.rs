//! Part `idle`: `idle_penalty`, the same small works back to back and paced at the pipeline's
//! rate, the floor under the runner's share of the pipeline's tail on this machine.

use crate::command::run_json;
use crate::opts::Opts;
use crate::pct::Pct;
use crate::prose;
use crate::rate::PIPELINE_RATE;
use anyhow::{Context, Result};
use std::fmt::Write as _;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let bin = o.target.join("release/idle_penalty");
    let samples = if o.quick { "10000" } else { "30000" };
    let rate = PIPELINE_RATE.to_string();
    let v = run_json(&bin, &["--samples", samples, "--rate", &rate])?;
    prose::push(md, &intro(samples));
    md.push_str(
        "| work | back to back p50 µs | p99 µs | paced p50 µs | p99 µs | paced / back to back, p99 |\n\
         |---|---:|---:|---:|---:|---:|\n",
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
    md.push('\n');
    prose::push(md, include_str!("prose/idle_penalty_works.md"));
    Ok(())
}

fn intro(samples: &str) -> String {
    prose::fill(
        include_str!("prose/idle_penalty.md"),
        &[("samples", &samples), ("rate", &PIPELINE_RATE)],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro("30000").contains("30000 times paced at 10000 Hz"));
    }
}
