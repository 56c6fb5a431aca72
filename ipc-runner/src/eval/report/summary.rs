//! The head of `eval`'s summary: what was run and how it ended, and the table of every
//! estimator's error.

use std::fmt::Write as _;

use super::EvalResult;
use crate::estimators::role::figure;
use crate::eval::EvalEnding;

/// The scenario, runs, horizon and seed; how the evaluation ended when it did not complete,
/// and the instants left out for a non-finite truth.
pub(super) fn heading(r: &EvalResult, s: &mut String) {
    let runs = match r.runs_requested {
        Some(asked) => format!("{} of {asked} runs", r.runs),
        None => format!("{} runs", r.runs),
    };
    let _ = writeln!(
        s,
        "scenario {}: {runs}, horizon {}, seed {}",
        r.scenario, r.horizon, r.seed
    );
    match (r.ending, &r.error) {
        (EvalEnding::Completed, _) => {}
        (EvalEnding::Interrupted, _) => {
            let _ = writeln!(s, "ended: interrupted (the runs done before the signal)");
        }
        (EvalEnding::Failed, e) => {
            let _ = writeln!(
                s,
                "ended: failed ({}); the runs before it",
                e.as_deref().unwrap_or("?")
            );
        }
    }
    if r.truth_nonfinite > 0 {
        let _ = writeln!(
            s,
            "truth not finite at {} (run, k) instant(s): left out of every MSE",
            r.truth_nonfinite
        );
    }
}

/// One row per estimator: role, average MSE and its standard error, median run, diverged
/// runs; then the note on reading them.
pub(super) fn table(r: &EvalResult, s: &mut String) {
    // The name column fits the longest name (`fused-predict+gate`), 12 at least.
    let w = (r.estimators.iter())
        .map(|(n, _)| n.chars().count())
        .fold(12, usize::max);
    let _ = writeln!(
        s,
        "{:<w$} {:<9} {:>12} {:>12} {:>14} {:>9}",
        "estimator", "role", "avg_mse", "± s.e.", "median_run_avg", "diverged"
    );
    for (name, e) in &r.estimators {
        let _ = writeln!(
            s,
            "{:<w$} {:<9} {} {} {} {:>9}",
            name,
            e.role,
            figure(e.avg_mse, 12),
            figure(e.avg_mse_se, 12),
            figure(e.median_run_avg, 14),
            e.diverged_runs
        );
    }
    if !r.estimators.is_empty() {
        s.push_str(crate::estimators::role::MSE_NOTE);
    }
}
