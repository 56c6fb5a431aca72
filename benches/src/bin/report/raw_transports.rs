//! Part `ipc`: the raw transports (iceoryx2, Unix socket), back to back and paced at the
//! pipeline's rate.

use crate::ipc_latency::{self, Raw};
use crate::opts::Opts;
use crate::pct::PCT_HEAD;
use crate::prose;
use crate::rate::PIPELINE_RATE;
use anyhow::Result;
use std::fmt::Write as _;

/// Returns what it measured for the pipeline's comparisons. Keys: `MODE` (back to back) and
/// `MODE paced` (one ping every 1/[`PIPELINE_RATE`] s).
pub fn part(o: &Opts, md: &mut String) -> Result<Raw> {
    let samples = if o.quick { 10_000 } else { 30_000 };
    let all = "iox-spin,iox-block,uds-spin,uds-block";
    let mut res = ipc_latency::run(o, samples, 0.0, all)?;
    for (mode, v) in ipc_latency::run(o, samples, PIPELINE_RATE, all)? {
        res.insert(format!("{mode} paced"), v);
    }
    prose::push(md, &intro(samples));
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

fn intro(samples: u32) -> String {
    prose::fill(
        include_str!("prose/raw_transports.md"),
        &[("samples", &samples), ("rate", &PIPELINE_RATE)],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(30_000).contains("30000 rounds each"));
    }
}
