//! `eval --paired REF`: every estimator's paired difference from a reference estimator over
//! the same runs — the comparison a Monte-Carlo table's separate standard errors cannot make
//! (two filters on the same runs share most of their run-to-run spread, so their difference is
//! known far better than either average).
//!
//! For estimators `a` and `REF` with run averages `ā_r`, `ref_r` (mean squared error over
//! k = 1..=T of run r) on the runs where both are valid:
//!
//! ```text
//! d = mean_r (ā_r − ref_r),   s.e. = sd_r(ā_r − ref_r) / √n,   relative = d / mean_r ref_r
//! ```

use std::fmt::Write;

use super::report::EvalResult;
use crate::estimators::role::figure;

/// One estimator's paired difference from the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paired {
    /// Mean of the per-run differences.
    pub diff: f64,
    /// Its standard error.
    pub se: f64,
    /// `diff` over the reference's mean on the same runs.
    pub relative: f64,
    /// Runs where both were valid.
    pub runs: usize,
}

/// The paired difference of run averages `a` from `reference` (each `(run, average)`, in run
/// order), over the runs both have; `None` with fewer than two such runs.
pub fn paired(a: &[(u64, f64)], reference: &[(u64, f64)]) -> Option<Paired> {
    let (mut d, mut r) = (Vec::new(), Vec::new());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < reference.len() {
        match a[i].0.cmp(&reference[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                d.push(a[i].1 - reference[j].1);
                r.push(reference[j].1);
                i += 1;
                j += 1;
            }
        }
    }
    let n = d.len();
    if n < 2 {
        return None;
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let m = mean(&d);
    let var = d.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64;
    Some(Paired {
        diff: m,
        se: (var / n as f64).sqrt(),
        relative: m / mean(&r),
        runs: n,
    })
}

/// The table printed under the summary: every other estimator against `reference`. An
/// unknown reference is the caller's error (checked before the runs).
pub fn table(result: &EvalResult, reference: &str) -> String {
    let Some((_, base)) = result.estimators.iter().find(|(n, _)| n == reference) else {
        return String::new();
    };
    let w = (result.estimators.iter())
        .map(|(n, _)| n.chars().count())
        .fold(12, usize::max);
    let mut s = format!(
        "paired differences from {reference} (same runs; MSE run averages):\n{:<w$} {:>12} {:>12} {:>9} {:>6}\n",
        "estimator", "difference", "± s.e.", "relative", "runs"
    );
    for (name, r) in &result.estimators {
        if name == reference {
            continue;
        }
        match paired(&r.run_averages, &base.run_averages) {
            Some(p) => {
                let _ = writeln!(
                    s,
                    "{name:<w$} {} {} {:>+8.2} % {:>6}",
                    figure(p.diff, 12),
                    figure(p.se, 12),
                    100.0 * p.relative,
                    p.runs
                );
            }
            None => {
                let _ = writeln!(s, "{name:<w$} {:>12}", "too few runs");
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_by_run_and_matches_a_hand_computation() {
        // Runs 0..4 of a, runs 1..5 of the reference: pairs on 1, 2, 3.
        let a = [(0, 9.0), (1, 2.0), (2, 3.0), (3, 5.0)];
        let r = [(1, 1.0), (2, 1.0), (3, 4.0), (4, 7.0)];
        let p = paired(&a, &r).unwrap();
        // Differences 1, 2, 1: mean 4/3, sample variance 1/3, s.e. √(1/9) = 1/3.
        assert_eq!(p.runs, 3);
        assert!((p.diff - 4.0 / 3.0).abs() < 1e-15);
        assert!((p.se - 1.0 / 3.0).abs() < 1e-15);
        assert!((p.relative - (4.0 / 3.0) / 2.0).abs() < 1e-15);
        assert!(paired(&a[..1], &r).is_none());
    }
}
