//! The summary's lines on how far an estimator's own account of itself holds: its
//! covariance against its errors, its innovation gate against the gate's probability.

use std::fmt::Write as _;

use super::EvalResult;

/// Consistency of an estimator's own covariance (diagnostics `inside_95`, `trace_p`, and
/// `nees` when it reports it), one line per estimator that reports them.
pub(super) fn covariance_lines(r: &EvalResult, s: &mut String) {
    for (name, e) in &r.estimators {
        let get = |n: &str| e.diagnostics.iter().find(|(d, _)| d == n).map(|(_, v)| v);
        if let (Some(inside), Some(tr)) = (get("inside_95"), get("trace_p")) {
            let t = r.horizon as usize;
            let avg = |v: &[f64]| v[1..].iter().sum::<f64>() / t as f64;
            let worst = inside[1..].iter().copied().fold(f64::INFINITY, f64::min);
            let above = (1..=t).filter(|&k| e.mse[k] > tr[k]).count();
            let anees = get("nees").map_or(String::new(), |v| {
                format!("; ANEES {:.3} (n_x = {})", avg(v), e.mse_per_state.len())
            });
            let _ = writeln!(
                s,
                "{name}: error inside its 95 % ellipse in {:.2} % of run-instants (worst k: \
                 {:.1} %); avg MSE {:.4} vs avg tr P {:.4}; MSE(k) > tr P(k) at {above} of \
                 {t} instants{anees}",
                100.0 * avg(inside),
                100.0 * worst,
                e.avg_mse,
                avg(tr)
            );
        }
    }
}

/// What each gated estimator's gate rejected, against the 1 − P it should.
pub(super) fn gate_lines(r: &EvalResult, s: &mut String) {
    for (name, e) in &r.estimators {
        if let (Some(g), Some(p)) = (e.gate, r.gate) {
            let _ = writeln!(
                s,
                "{name}: innovation gate P = {p} rejected {} of {} measurements ({:.3} %; \
                 1 − P = {:.3} %)",
                g.rejected,
                g.tested,
                100.0 * g.rejection_rate,
                100.0 * (1.0 - p)
            );
        }
    }
}
