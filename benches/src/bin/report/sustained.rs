//! The pipeline at 100 000 slots/s for a few seconds, where zero loss is the target.

use crate::demo::{demo, DemoRun};
use crate::opts::Opts;
use anyhow::Result;
use std::fmt::Write as _;

pub fn section(o: &Opts, md: &mut String) -> Result<()> {
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
