//! The reduction of one estimator's runs: sums over runs, fed in run order, and the
//! estimator's results from them.

use super::{EstimatorResult, GateTotals, NodeCounts};
use crate::estimators::role::Role;
use crate::eval::RunEstimator;

/// One estimator's sums over the runs reduced so far.
#[derive(Default)]
pub(super) struct EstimatorAcc {
    sum_sq: Vec<f64>,
    /// Runs in `sum_sq` per k (those whose truth at k was finite).
    n_k: Vec<u64>,
    valid: u64,
    run_avgs: Vec<f64>,
    /// The run index of each of `run_avgs`.
    run_ids: Vec<u64>,
    diverged: u64,
    first_error: Option<String>,
    diag: Vec<(&'static str, Vec<f64>, Vec<u64>)>,
}

impl EstimatorAcc {
    /// Sums of `len` squared errors (`nx` per k) over `horizon + 1` instants.
    pub(super) fn new(len: usize, horizon: usize) -> Self {
        Self {
            sum_sq: vec![0.0; len],
            n_k: vec![0; horizon + 1],
            ..Default::default()
        }
    }

    /// Adds run `run`'s record: its squared errors and diagnostics, or its divergence.
    pub(super) fn absorb(&mut self, rec: RunEstimator, run: u64, nx: usize, t: usize) {
        let Some(sq) = rec.sq_err else {
            self.diverged += 1;
            if self.first_error.is_none() {
                self.first_error = Some(format!("run {}: {}", run, rec.error.unwrap_or_default()));
            }
            return;
        };
        self.valid += 1;
        self.absorb_errors(&sq, run, nx, t);
        self.absorb_diagnostics(rec.diagnostics, t);
    }

    fn absorb_errors(&mut self, sq: &[f64], run: u64, nx: usize, t: usize) {
        // NaN marks an instant without a sample (non-finite truth, `record_estimate`).
        let (mut run_sum, mut run_n) = (0.0, 0u64);
        let per_k = self
            .sum_sq
            .chunks_exact_mut(nx)
            .zip(sq.chunks_exact(nx))
            .zip(&mut self.n_k)
            .take(t + 1);
        for (k, ((sums, sq_k), n)) in per_k.enumerate() {
            if sq_k[0].is_nan() {
                continue;
            }
            for (s, v) in sums.iter_mut().zip(sq_k) {
                *s += v;
            }
            *n += 1;
            if k > 0 {
                // Element by element: the same sum, bit for bit, as over the whole run.
                for v in sq_k {
                    run_sum += v;
                }
                run_n += 1;
            }
        }
        if run_n > 0 {
            self.run_avgs.push(run_sum / run_n as f64);
            self.run_ids.push(run);
        }
    }

    fn absorb_diagnostics(&mut self, diagnostics: Vec<(&'static str, Vec<f64>)>, t: usize) {
        for (j, (name, values)) in diagnostics.into_iter().enumerate() {
            // The same names in the same order run after run: index j first.
            let slot = match self.diag.get(j) {
                Some((n, _, _)) if *n == name => j,
                _ => match self.diag.iter().position(|(n, _, _)| *n == name) {
                    Some(i) => i,
                    None => {
                        self.diag.push((name, vec![0.0; t + 1], vec![0; t + 1]));
                        self.diag.len() - 1
                    }
                },
            };
            let (_, sums, counts) = &mut self.diag[slot];
            for ((s, c), v) in sums.iter_mut().zip(counts.iter_mut()).zip(&values) {
                if v.is_finite() {
                    *s += v;
                    *c += 1;
                }
            }
        }
    }

    /// The estimator's results over the runs reduced (`nx` states, horizon `t`).
    pub(super) fn result(self, role: Role, nx: usize, t: usize) -> EstimatorResult {
        let n = self.run_avgs.len() as f64;
        let mean_k = |k: usize, v: f64| {
            if self.n_k[k] == 0 {
                f64::NAN
            } else {
                v / self.n_k[k] as f64
            }
        };
        let per_state: Vec<Vec<f64>> = (0..nx)
            .map(|i| {
                (0..=t)
                    .map(|k| mean_k(k, self.sum_sq[k * nx + i]))
                    .collect()
            })
            .collect();
        let mse: Vec<f64> = (0..=t)
            .map(|k| mean_k(k, self.sum_sq[k * nx..][..nx].iter().sum::<f64>()))
            .collect();
        let sampled: Vec<f64> = (1..=t)
            .filter(|&k| self.n_k[k] > 0)
            .map(|k| mse[k])
            .collect();
        let avg_mse = sampled.iter().sum::<f64>() / sampled.len() as f64;
        let mean_run = self.run_avgs.iter().sum::<f64>() / n;
        let var = self
            .run_avgs
            .iter()
            .map(|r| (r - mean_run).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        let diagnostics = diagnostic_means(self.diag);
        let gate = GateTotals::of(&diagnostics, n as u64);
        let run_averages = self
            .run_ids
            .iter()
            .copied()
            .zip(self.run_avgs.clone())
            .collect();
        EstimatorResult {
            role,
            run_averages,
            mse,
            avg_mse,
            avg_mse_se: (var / n).sqrt(),
            median_run_avg: median(self.run_avgs),
            diverged_runs: self.diverged,
            valid_runs: self.valid,
            first_error: self.first_error,
            mse_per_state: per_state,
            gate,
            diagnostics,
        }
    }
}

/// Each diagnostic's mean over the runs that reported it, per k (NaN where none did).
fn diagnostic_means(diag: Vec<(&'static str, Vec<f64>, Vec<u64>)>) -> Vec<(String, Vec<f64>)> {
    diag.into_iter()
        .map(|(name, sums, counts)| {
            let mean = sums
                .iter()
                .zip(&counts)
                .map(|(s, &c)| if c == 0 { f64::NAN } else { s / c as f64 })
                .collect();
            (name.to_owned(), mean)
        })
        .collect()
}

impl NodeCounts {
    /// Adds one run's counts of the same node.
    pub(super) fn absorb(&mut self, c: &NodeCounts) {
        self.instants += c.instants;
        self.delivered += c.delivered;
        self.dropped += c.dropped;
        self.sent += c.sent;
        self.triggered += c.triggered;
        self.blocked += c.blocked;
        self.censored += c.censored;
        self.random_loss += c.random_loss;
        self.occluded += c.occluded;
        self.transport_lost += c.transport_lost;
        self.transport_late += c.transport_late;
        self.transport_too_old += c.transport_too_old;
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    }
}
