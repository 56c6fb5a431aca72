//! `pf`: a bootstrap particle filter with the exact occlusion likelihood — the near-optimal
//! reference every occlusion estimator is compared with (evaluation only; std, no core).
//!
//! Particles start from the estimators' prior `N(x̂_0, P_0)`, move with the plant's
//! `x_k = A x_{k−1} + w (+ B_u u_{k−1})`, `w ~ N(0, BQBᵀ)`, and are weighted by the exact likelihood of what
//! the channel delivered (seed 001 eqs. 2-3, `n_e = 1`):
//!
//! ```text
//! dropout:  P(u ∈ ∪R_i | x) = Σ_i [Φ((ζ_i + r_i − E x)/√Ψ) − Φ((ζ_i − r_i − E x)/√Ψ)]
//! arrival:  N(z; C x, DRDᵀ) · P(u ∉ ∪R_i | x)
//! ```
//!
//! (probabilities from `gauss::ln_interval_prob`, so far tails neither underflow nor cancel).
//! A packet lost in transport (`FLAGS_LOST`: in the IPC or on the network, see `slots`)
//! carries no information: the particles move and keep their weights. `pf-mix` (built beside `pf` with `--loss-rate P`)
//! weights a dropout by `P + (1 − P) P(u ∈ ∪R_i | x)`, a loss the receiver cannot tell from an
//! occlusion.
//! Weights are kept as logarithms; the estimate is the weighted mean, its covariance the
//! weighted sample covariance `Σ_p w_p (x_p − x̂)(x_p − x̂)ᵀ` (before resampling; `P_0` at
//! k = 0); systematic resampling
//! when the effective sample size drops below half the particle count. The particle count is
//! `--particles` (default 5000; 0 disables `pf`). Random numbers: xoshiro256++ seeded from
//! `(seed, run)` by SplitMix64, independent of the simulation's streams, so results are
//! reproducible and thread-count independent. One sensor node, `n_x ≤ 8`, `n_y ≤ 4`.

use std::sync::Arc;

use estimator_core::gauss::{ln_interval_prob, log_sum_exp};
use estimator_core::Error;
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::{Observation, FLAGS_LOST, MAX_NX, MAX_NY};
use nalgebra::DMatrix;

use super::particles_rng::{splitmix64, Rng};
use super::{BuildOptions, RunStart};
use crate::{CovarianceKind, Estimator};

/// Default particle count.
pub const DEFAULT_PARTICLES: usize = 5000;

/// Builds `pf` for a spec with occlusion regions (empty list otherwise or with
/// `--particles 0`), and `pf-mix` beside it when `options.loss_rate > 0`.
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    if options.particles == 0 {
        return Ok(Vec::new());
    }
    let Some(occ) = &spec.channel.occlusion else {
        return Ok(Vec::new());
    };
    if spec.linear().is_none() || spec.nodes() != 1 {
        return Ok(Vec::new());
    }
    let intervals: Vec<(f64, f64)> = occ
        .centres()
        .iter()
        .zip(occ.radii())
        .map(|(c, r)| (c - r, c + r))
        .collect();
    let make = |intervals| {
        ParticleFilter::new(
            spec,
            occ.e().to_vec(),
            occ.psi(),
            intervals,
            options.particles,
            start.seed,
            start.run,
        )
    };
    let mut out: Vec<Box<dyn Estimator>> = vec![Box::new(make(intervals.clone())?)];
    let p = options.loss_rate;
    if p > 0.0 {
        anyhow::ensure!(
            p.is_finite() && p < 1.0,
            "pf-mix: invalid loss_rate: must be finite and in [0, 1)"
        );
        // The same seed: pf-mix draws the same random numbers as pf.
        let mut mix = make(intervals)?;
        mix.name = "pf-mix";
        mix.ln_loss = Some((p.ln(), (-p).ln_1p()));
        out.push(Box::new(mix));
    }
    Ok(out)
}

struct ParticleFilter {
    /// `pf`, or `pf-mix` with a loss rate.
    name: &'static str,
    /// `(ln p_loss, ln(1 − p_loss))` of `pf-mix`.
    ln_loss: Option<(f64, f64)>,
    spec: Arc<EstimatorSpec>,
    e: Vec<f64>,
    sd_n: f64,
    /// Regions as intervals, and the gaps between them (half-lines included), both sorted.
    regions: Vec<(f64, f64)>,
    gaps: Vec<(f64, f64)>,
    nx: usize,
    ny: usize,
    n: usize,
    x: Vec<f64>,
    lw: Vec<f64>,
    scratch: Vec<f64>,
    /// Log-weights being computed (committed by swapping with `lw`).
    lw_scratch: Vec<f64>,
    mean: Vec<f64>,
    /// The weighted sample covariance Σ_p w_p (x_p − x̂)(x_p − x̂)ᵀ, row-major (P_0 before the
    /// first step).
    cov: Vec<f64>,
    /// The model's factors, computed once (no allocation per step).
    model: PfModel,
    rng: Rng,
}

/// `A`, `L_Q` (lower Cholesky factor of `BQBᵀ`), `C`, `L_R` (the known input term `B_u u`
/// is evaluated per instant, in place).
#[derive(Clone)]
struct PfModel {
    a: DMatrix<f64>,
    lq: DMatrix<f64>,
    c: DMatrix<f64>,
    lr: DMatrix<f64>,
}

impl PfModel {
    fn of(model: &LinearModel) -> Result<Self, Error> {
        Ok(Self {
            a: model.a().clone(),
            lq: lower_cholesky(model.process_cov(), "process covariance")?,
            c: model.c(0).clone(),
            lr: lower_cholesky(model.measurement_cov(0), "measurement covariance")?,
        })
    }
}

/// `Σ_p w_p (x_p − mean)(x_p − mean)ᵀ` into `out` (row-major, `nx = mean.len()`), with
/// `w_p = exp(lw_p)` normalised log-weights and `x` the particles one after another. The
/// upper triangle is summed and mirrored, so the result is exactly symmetric.
pub(super) fn weighted_covariance(x: &[f64], lw: &[f64], mean: &[f64], out: &mut [f64]) {
    let nx = mean.len();
    out.fill(0.0);
    for (p, &l) in lw.iter().enumerate() {
        let w = l.exp();
        let xp = &x[p * nx..(p + 1) * nx];
        for i in 0..nx {
            let di = w * (xp[i] - mean[i]);
            for j in i..nx {
                out[i * nx + j] += di * (xp[j] - mean[j]);
            }
        }
    }
    for i in 0..nx {
        for j in 0..i {
            out[i * nx + j] = out[j * nx + i];
        }
    }
}

pub(super) fn lower_cholesky(m: &DMatrix<f64>, what: &'static str) -> Result<DMatrix<f64>, Error> {
    m.clone()
        .cholesky()
        .map(|c| c.l())
        .ok_or(Error::NotPositiveDefinite { what })
}

impl ParticleFilter {
    fn new(
        spec: &Arc<EstimatorSpec>,
        e: Vec<f64>,
        psi: f64,
        mut regions: Vec<(f64, f64)>,
        n: usize,
        seed: u64,
        run: u64,
    ) -> anyhow::Result<Self> {
        let (nx, ny) = (spec.nx(), spec.ny());
        let linear = spec
            .linear()
            .ok_or_else(|| anyhow::anyhow!("pf: the spec has no linear model"))?;
        regions.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut gaps = Vec::with_capacity(regions.len() + 1);
        let mut lo = f64::NEG_INFINITY;
        for &(a, b) in &regions {
            gaps.push((lo, a));
            lo = b;
        }
        gaps.push((lo, f64::INFINITY));
        let prior = &spec.prior;
        let l0 = lower_cholesky(&prior.cov, "P0")?;
        // "pf" stream: independent of the simulation's plant and channel streams.
        let mut rng = Rng::new(splitmix64(splitmix64(seed ^ 0x7066_5f70_6172_7469) ^ run));
        let mut x = vec![0.0; n * nx];
        let mut xi = vec![0.0; nx];
        for p in 0..n {
            for v in xi.iter_mut() {
                *v = rng.normal();
            }
            for i in 0..nx {
                let mut acc = prior.mean[i];
                for j in 0..=i {
                    acc += l0[(i, j)] * xi[j];
                }
                x[p * nx + i] = acc;
            }
        }
        Ok(Self {
            name: "pf",
            ln_loss: None,
            spec: Arc::clone(spec),
            e,
            sd_n: psi.sqrt(),
            regions,
            gaps,
            nx,
            ny,
            n,
            x,
            lw: vec![-(n as f64).ln(); n],
            scratch: vec![0.0; n * nx],
            lw_scratch: vec![0.0; n],
            mean: prior.mean.as_slice().to_vec(),
            cov: (0..nx * nx).map(|i| prior.cov[(i / nx, i % nx)]).collect(),
            model: PfModel::of(linear)?,
            rng,
        })
    }

    /// `ln P(u ∈ ∪ intervals | E x = ex)`.
    fn ln_prob(&self, intervals: &[(f64, f64)], ex: f64) -> f64 {
        let mut terms = [f64::NEG_INFINITY; 9];
        for (t, &(a, b)) in terms.iter_mut().zip(intervals) {
            *t = ln_interval_prob((a - ex) / self.sd_n, (b - ex) / self.sd_n);
        }
        log_sum_exp(&terms[..intervals.len().min(9)])
    }

    fn resample(&mut self) {
        let n = self.n;
        let nx = self.nx;
        let total = log_sum_exp(&self.lw);
        let u0 = self.rng.uniform() / n as f64;
        let mut cum = 0.0;
        let mut j = 0usize;
        for p in 0..n {
            let target = u0 + p as f64 / n as f64;
            while j < n - 1 && cum + (self.lw[j] - total).exp() < target {
                cum += (self.lw[j] - total).exp();
                j += 1;
            }
            self.scratch[p * nx..(p + 1) * nx].copy_from_slice(&self.x[j * nx..(j + 1) * nx]);
        }
        std::mem::swap(&mut self.x, &mut self.scratch);
        let w = -(n as f64).ln();
        self.lw.iter_mut().for_each(|v| *v = w);
    }

    /// Particle `p` moved by the model: x' = A x + L_Q ξ (+ B u), into the scratch space.
    fn propagate(&mut self, p: usize, xi: &[f64; MAX_NX], bu: Option<&[f64]>) {
        let (nx, a, lq) = (self.nx, &self.model.a, &self.model.lq);
        let old = &self.x[p * nx..(p + 1) * nx];
        let new = &mut self.scratch[p * nx..(p + 1) * nx];
        for i in 0..nx {
            let mut acc = 0.0;
            for j in 0..nx {
                acc += a[(i, j)] * old[j];
            }
            for j in 0..=i {
                acc += lq[(i, j)] * xi[j];
            }
            if let Some(bu) = bu {
                acc += bu[i];
            }
            new[i] = acc;
        }
    }

    /// The log-likelihood of the instant for the moved particle `p`: none for a slot lost in
    /// transport, the occlusion (or loss) probability for a dropout, the Gaussian density
    /// and the probability of being outside every region for a measurement.
    fn log_likelihood(&self, p: usize, y: Option<&[f64]>, lost: bool) -> f64 {
        let (nx, ny, c, lr) = (self.nx, self.ny, &self.model.c, &self.model.lr);
        let new = &self.scratch[p * nx..(p + 1) * nx];
        let ex: f64 = self.e.iter().zip(new.iter()).map(|(e, x)| e * x).sum();
        match y {
            None if lost => 0.0,
            None => {
                let occluded = self.ln_prob(&self.regions, ex);
                match self.ln_loss {
                    // ln(p + (1 − p) P(occluded | x))
                    Some((lp, l1p)) => log_sum_exp(&[lp, l1p + occluded]),
                    None => occluded,
                }
            }
            Some(y) => {
                // −½‖L⁻¹(y − Cx)‖² by forward substitution.
                let mut resid = [0.0; MAX_NY];
                let mut q = 0.0;
                for i in 0..ny {
                    let mut r = y[i];
                    for j in 0..nx {
                        r -= c[(i, j)] * new[j];
                    }
                    for j in 0..i {
                        r -= lr[(i, j)] * resid[j];
                    }
                    resid[i] = r / lr[(i, i)];
                    q += resid[i] * resid[i];
                }
                -0.5 * q + self.ln_prob(&self.gaps, ex)
            }
        }
    }

    /// Normalises the log-weights `lw` by their `total`, takes the moved particles with their
    /// weighted mean and covariance, and resamples when the effective sample size falls
    /// below half the particles.
    fn commit(&mut self, mut lw: Vec<f64>, total: f64) {
        let nx = self.nx;
        let mut mean = [0.0; MAX_NX];
        let mut sum_w2 = 0.0;
        for p in 0..self.n {
            lw[p] -= total;
            let w = lw[p].exp();
            sum_w2 += w * w;
            for i in 0..nx {
                mean[i] += w * self.scratch[p * nx + i];
            }
        }
        let mut cov = [0.0; MAX_NX * MAX_NX];
        weighted_covariance(&self.scratch, &lw, &mean[..nx], &mut cov[..nx * nx]);
        std::mem::swap(&mut self.x, &mut self.scratch);
        self.lw_scratch = std::mem::replace(&mut self.lw, lw);
        self.mean.copy_from_slice(&mean[..nx]);
        self.cov.copy_from_slice(&cov[..nx * nx]);
        if 1.0 / sum_w2 < 0.5 * self.n as f64 {
            self.resample();
        }
    }
}

impl Estimator for ParticleFilter {
    fn name(&self) -> &'static str {
        self.name
    }

    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        let mut u = [0.0; MAX_NX];
        let bu = super::fed::linear(&self.spec)?
            .input_into(k.saturating_sub(1) as usize, &mut u)
            .then_some(&u[..self.nx]);
        let ny = self.ny;
        let mut y_buf = [0.0; MAX_NY];
        // Lost in transport: no likelihood, the particles only move.
        let lost = obs
            .first()
            .is_none_or(|o| !o.delivered && o.flags & FLAGS_LOST != 0);
        let y = obs.first().and_then(|o| o.measurement()).map(|y| {
            y_buf[..ny].copy_from_slice(&y[..ny]);
            &y_buf[..ny]
        });
        if let Some(y) = y {
            if y.iter().any(|v| !v.is_finite()) {
                return Err(Error::NonFinite {
                    what: "measurement",
                });
            }
        }
        // Propagate and weight into scratch space; commit only if the weights are usable.
        let mut lw = std::mem::take(&mut self.lw_scratch);
        lw.copy_from_slice(&self.lw);
        let mut xi = [0.0; MAX_NX];
        for p in 0..self.n {
            for v in xi[..self.nx].iter_mut() {
                *v = self.rng.normal();
            }
            self.propagate(p, &xi, bu);
            lw[p] += self.log_likelihood(p, y, lost);
        }
        let total = log_sum_exp(&lw);
        if !total.is_finite() {
            self.lw_scratch = lw;
            return Err(Error::Numerical {
                what: "every particle has zero likelihood",
            });
        }
        self.commit(lw, total);
        Ok(())
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..self.nx].copy_from_slice(&self.mean);
    }

    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        out[..self.nx * self.nx].copy_from_slice(&self.cov);
        CovarianceKind::Estimate
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build_all, FACTORIES};
    use nalgebra::DVector;

    /// The weighted covariance against nalgebra's products on the same particles: the
    /// weighted mean m = Σ w x and Σ w x xᵀ − m mᵀ (a different formula, same quantity).
    #[test]
    fn weighted_covariance_matches_an_independent_formula() {
        let (n, nx) = (500, 3);
        let mut rng = Rng::new(42);
        let x: Vec<f64> = (0..n * nx)
            .map(|i| rng.normal() * (1.0 + (i % nx) as f64))
            .collect();
        let raw: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let total = log_sum_exp(&raw);
        let lw: Vec<f64> = raw.iter().map(|v| v - total).collect();
        let xs = DMatrix::from_column_slice(nx, n, &x);
        let w = DVector::from_iterator(n, lw.iter().map(|l| l.exp()));
        let m = &xs * &w;
        let second = &xs * DMatrix::from_diagonal(&w) * xs.transpose();
        let want = second - &m * m.transpose();
        let mut got = vec![0.0; nx * nx];
        weighted_covariance(&x, &lw, m.as_slice(), &mut got);
        for i in 0..nx {
            for j in 0..nx {
                assert!(
                    (got[i * nx + j] - want[(i, j)]).abs() < 1e-12 * want.amax(),
                    "({i},{j}): {} vs {}",
                    got[i * nx + j],
                    want[(i, j)]
                );
                assert_eq!(got[i * nx + j], got[j * nx + i]);
            }
        }
    }

    /// A slot a bridge wrote for what the network lost (`FLAG_NET_LOST`) is a loss, as one
    /// lost in the IPC: no likelihood, the same estimate bit for bit (it was read as an
    /// occlusion dropout, information, before).
    #[test]
    fn a_slot_lost_on_the_network_is_no_information() {
        use estpipe_wire::{FLAG_IPC_LOST, FLAG_NET_LOST};
        let s = crate::presets::preset_spec("occlusion");
        let options = BuildOptions {
            particles: 2000,
            estimators: vec!["pf".into()],
            ..BuildOptions::default()
        };
        let mut out = Vec::new();
        let start = RunStart {
            seed: 3,
            ..RunStart::default()
        };
        for flags in [FLAG_IPC_LOST, FLAG_NET_LOST, 0] {
            let mut ests = build_all(FACTORIES, &s, &options, &start).unwrap();
            let o = Observation::dropped(1, 0, s.ny() as u8, flags);
            ests[0].step(1, &[o]).unwrap();
            let mut x = [0.0; 3];
            ests[0].estimate(&mut x);
            out.push(x);
        }
        assert_eq!(out[0], out[1]);
        assert_ne!(
            out[0], out[2],
            "a dropout is information in the occlusion model"
        );
    }

    /// Far from every occlusion region a dropout is impossible and an arrival's likelihood
    /// is the Gaussian one, so `pf` is a Monte-Carlo version of the Kalman filter (`ikf`):
    /// after one arrival (occlusion preset, k = 1, x₁ ≈ 5 ≪ 15) its covariance matches the
    /// KF's P within the sampling error of 40 000 weighted particles (tolerance 10 % of
    /// tr P; the observed gap is a few percent), and it is reported as an estimate.
    #[test]
    fn pf_covariance_is_the_kf_covariance_where_occlusion_says_nothing() {
        let (s, mut sim) = crate::presets::preset_run("occlusion", 3, 0);
        let start = RunStart {
            seed: 3,
            ..RunStart::default()
        };
        let options = BuildOptions {
            particles: 40_000,
            estimators: vec!["ikf".into(), "pf".into()],
            ..BuildOptions::default()
        };
        let mut ests = build_all(FACTORIES, &s, &options, &start).unwrap();
        let inst = sim.next_instant();
        assert!(inst.obs[0].delivered, "precondition: k = 1 delivered");
        let mut p = [[0.0; 9]; 2];
        for (e, out) in ests.iter_mut().zip(&mut p) {
            e.step(1, &inst.obs).unwrap();
            assert_eq!(e.covariance(out), CovarianceKind::Estimate, "{}", e.name());
        }
        let [ikf, pf] = p;
        let tr: f64 = (0..3).map(|i| ikf[i * 4]).sum();
        for i in 0..9 {
            assert!(
                (ikf[i] - pf[i]).abs() < 0.1 * tr,
                "entry {i}: ikf {ikf:?} pf {pf:?}"
            );
        }
    }
}
