//! Part `criterion`: our Kalman step against `adskalman`'s, by criterion and interleaved in one
//! process, then every criterion median of the run.

use crate::command::say;
use crate::criterion::{self, fmt_ci};
use crate::format::verdict;
use crate::kf_forms::{KF_FORMS, KF_PROBLEMS, KF_TARGET};
use crate::kf_interleaved;
use crate::opts::Opts;
use crate::prose;
use anyhow::Result;
use std::fmt::Write as _;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let res = criterion::medians(o)?;
    let get = |id: &str| res.get(id).cloned();
    prose::push(md, include_str!("prose/kf_comparison.md"));
    md.push_str("| problem | covariance form | ours median (95 % CI) | adskalman median (95 % CI) | ratio ours/adskalman | target ≤ 0.8 |\n|---|---|---:|---:|---:|---|\n");
    for (form, ours, ads, _) in KF_FORMS {
        for prob in KF_PROBLEMS {
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
                    verdict(r <= KF_TARGET)
                );
            }
        }
    }
    // What the interleaved comparison wrote before failing stays: the criterion tables are
    // worth keeping without it.
    if let Err(e) = kf_interleaved::section(o, md) {
        say(&format!("kf_interleaved: {e:#}"));
        let _ = writeln!(md, "\nThe interleaved comparison did not run: {e:#}.");
    }
    criterion::tables(md, &res);
    Ok(())
}
