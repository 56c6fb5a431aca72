//! `pf` on seed 003's `nn-token-bucket`: a particle filter on the true nonlinear model
//! `x_{k+1} = A_k x_k + f(x_k) + B_k w_k`, `y_k = C_k x_k + D_k w_k` (one scalar `w_k` in both),
//! the reference of what an estimator that knows the model can achieve (evaluation only; std,
//! no core). Built by the `nn` family when `--particles` is not 0.
//!
//! # Conditioning on the shared noise
//! Given `x_k`, the pair `(y_k, x_{k+1})` is driven by the same `w_k`, so the filter must not
//! weight by `p(y_k | x_k)` and then draw `x_{k+1}` from `p(x_{k+1} | x_k)` as if the two were
//! independent: it draws `w_k` from `p(w_k | x_k, y_k)` and moves with *that* `w_k`. And
//! `p(y_k | x_k) = N(y_k; C_k x_k, D_k w̄² D_kᵀ)` is singular (rank 1 in 2-D): one combination
//! `u_kᵀ y_k` (`u_k ⊥ D_k`) is noise-free, `u_kᵀ (y_k − C_k x_k) = 0` exactly, so every particle
//! drawn from a density has likelihood zero. The filter therefore conditions kernels, not
//! points (a regularised, fully adapted particle filter):
//!
//! 1. The prediction `p(x_k | y_{0:k−1})` is the particle cloud smoothed by a Gaussian kernel,
//!    `Σ_i ω_i N(x; m_i, H)`, with `H = h² Σ̂` (`Σ̂` the weighted sample covariance, Silverman's
//!    `h = (4 / (5N))^{1/7}` for 3 dimensions) and the locations shrunk towards the mean,
//!    `m_i = x̄ + √(1 − h²)(x_i − x̄)`, so that the mixture keeps the cloud's mean and
//!    covariance (Liu & West 2001).
//! 2. If `y_k` was sent, `(x_k, w_k, y_k)` is jointly Gaussian within each kernel:
//!    `y = C x + D w + v` with `Cov(y) = S = C H Cᵀ + D w̄² Dᵀ + ε I`, `Cov(x, y) = H Cᵀ`,
//!    `Cov(w, y) = w̄² Dᵀ`. The weights become `ω_i N(y_k; C m_i, S)` — the exact predictive
//!    likelihood of kernel i, nonsingular because `H` is positive definite (the argument of
//!    `kf-indep`: `S` is singular only if some `v` has `Cᵀ v = 0` and `Dᵀ v = 0`) — the cloud is
//!    resampled when the effective sample size falls below N/2, and each particle draws
//!    `(x̃_k, w̃_k)` from its kernel's exact conditional given `y_k` (Matheron's rule: draw
//!    `x* ~ N(m_i, H)`, `w* ~ N(0, w̄²)`, `v* ~ N(0, ε I)`, `y* = C x* + D w* + v*`, then
//!    `x̃ = x* + H Cᵀ S⁻¹ (y_k − y*)`, `w̃ = w* + w̄² Dᵀ S⁻¹ (y_k − y*)`).
//! 3. It moves with the same noise: `x_{k+1} = A_k x̃_k + f(x̃_k) + B_k w̃_k`.
//!
//! If the bucket withheld `y_k`, nothing is learnt: `w_k ~ N(0, w̄²)` and
//! `x_{k+1} = A_k x_k + f(x_k) + B_k w_k` (the bootstrap step; no kernel).
//!
//! # What the exact conditioning implies, and the one numerical floor
//! Step 2 is exact for the smoothed cloud, so the filter inherits what the model implies:
//! sent measurements are exact linear constraints (one per instant), and the conditioned
//! cloud collapses — after three sent instants the exact posterior is a point, or a few (one scalar
//! noise and two measurements per instant make the state recoverable from the data, as the
//! paper's correlated-noise KF's collapsing covariance shows); a withheld instant spreads it
//! along `B_k` by `w_k`, the next sent one collapses it again. The filter's measurement model
//! therefore has an independent sensor noise `v ~ N(0, ε I)`, `ε =` [`EPS_REL`]` · w̄²` (the
//! plant has none), as a numerical floor only: it keeps `S ≥ ε I` factorisable when the cloud
//! has collapsed (without it the Cholesky factor of `S` is at the edge of what f64 resolves),
//! and at √ε ≈ 3·10⁻⁷ it is far below every noise of the model. A floor of modelling size
//! would not be harmless: the expanding dynamics (`|A_k + ∂f/∂x|` up to ≈ 10) amplify the
//! spread it lets into the cloud at every sent instant. docs/nn-token-bucket.md shows the MSE
//! against `ε` and `N`, and that the filter follows the plant when its cloud starts at `x₀`
//! but does not lock on from the prior `N(0, 10 I)`.
//!
//! The estimate is the weighted mean of the predicted particles (its covariance their
//! weighted sample covariance), `x̂_{k+1} ≈ E[x_{k+1} |
//! y_{0:k}]`, the same one-step prediction every seed 003 estimator reports; `y₀` comes with
//! the run's start as for the others. Diagnostics: `ess` (effective sample size / N after the
//! last sent instant's weighting, before resampling). Random numbers: xoshiro256++ seeded from `(seed, run)`, a stream of its own.

use crate::particles_rng::splitmix64;
use estimator_core::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap};
use estimator_core::gauss::log_sum_exp;
use estimator_core::linalg::cholesky;
use estimator_core::linalg::eig::symmetric_eigen;
use estimator_core::papers::Seed003Example;
use estimator_core::Error;
use estpipe_wire::Observation;
use nalgebra::{SMatrix, SVector};

use crate::particles_rng::Rng;
use crate::Estimator;

type V2 = SVector<f64, 2>;
type V3 = SVector<f64, 3>;
type M3 = SMatrix<f64, 3, 3>;

/// The numerical floor `ε / w̄²` of the filter's measurement model (see the module docs).
pub const EPS_REL: f64 = 1e-12;

/// The seed 003 particle filter (see the module docs).
pub struct CoupledPf {
    n: usize,
    /// Particles of `x_k` (the prediction from `y_0 … y_{k−1}`).
    x: Vec<V3>,
    /// Scratch: kernel locations, then the propagated particles.
    loc: Vec<V3>,
    next: Vec<V3>,
    /// Log-weights of `x`, and scratch for the new ones.
    lw: Vec<f64>,
    lw_next: Vec<f64>,
    w_var: f64,
    eps: f64,
    /// Silverman's `h²`.
    h2: f64,
    k: usize,
    /// `y_k` if it was sent (processed by the next step).
    y: Option<V2>,
    mean: V3,
    /// The weighted covariance of the predicted particles about `mean` (P_0 at first).
    cov: M3,
    ess: f64,
    rng: Rng,
}

impl CoupledPf {
    /// `n ≥ 2` particles from the estimators' prior `N(x̂₀, P₀)`, noise variance `w̄² = w_var`,
    /// `y₀` if it was sent; random numbers from `(seed, run)`.
    pub fn new(
        x0: V3,
        p0: M3,
        w_var: f64,
        y0: Option<V2>,
        n: usize,
        seed: u64,
        run: u64,
    ) -> anyhow::Result<Self> {
        Self::with_eps(x0, p0, w_var, y0, n, EPS_REL * w_var, seed, run)
    }

    /// As [`Self::new`] with the floor `eps` (≥ 0; 0 is the model exactly) instead of
    /// [`EPS_REL`]` · w̄²` (for the sensitivity study of docs/nn-token-bucket.md).
    pub fn with_eps(
        x0: V3,
        p0: M3,
        w_var: f64,
        y0: Option<V2>,
        n: usize,
        eps: f64,
        seed: u64,
        run: u64,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(n >= 2, "pf: needs at least 2 particles, got {n}");
        anyhow::ensure!(
            w_var.is_finite() && w_var > 0.0,
            "pf: w̄² must be finite and positive, got {w_var}"
        );
        anyhow::ensure!(eps.is_finite() && eps >= 0.0, "pf: ε must be finite, ≥ 0");
        if let Some(y) = &y0 {
            anyhow::ensure!(y.iter().all(|v| v.is_finite()), "pf: y₀ is not finite");
        }
        let l0 = cholesky(&p0, "P0")
            .map_err(|e| anyhow::anyhow!("pf: {e}"))?
            .l();
        // "pf-coupled" stream: independent of the simulation's and of the occlusion pf's.
        let mut rng = Rng::new(splitmix64(splitmix64(seed ^ 0x7066_2d63_6f75_706c) ^ run));
        let x: Vec<V3> = (0..n)
            .map(|_| {
                let xi = V3::new(rng.normal(), rng.normal(), rng.normal());
                x0 + l0 * xi
            })
            .collect();
        let h = (4.0 / (5.0 * n as f64)).powf(1.0 / 7.0);
        Ok(Self {
            n,
            loc: x.clone(),
            next: x.clone(),
            x,
            lw: vec![-(n as f64).ln(); n],
            lw_next: vec![0.0; n],
            w_var,
            eps,
            h2: h * h,
            k: 0,
            y: y0,
            mean: x0,
            cov: p0,
            ess: 1.0,
            rng,
        })
    }

    /// Instant `k` of the current prediction.
    pub fn instant(&self) -> usize {
        self.k
    }

    /// From `k` to `k + 1`: processes the stored `y_k`, stores `y_next` (= `y_{k+1}`). On
    /// error nothing changes (the new particles and weights are built in scratch space).
    fn advance(&mut self, y_next: Option<V2>) -> Result<(), Error> {
        let sys = Seed003Example;
        let k = self.k;
        let step = Move {
            a: sys.a(k),
            b: sys.b(k),
        };
        let total = log_sum_exp(&self.lw);
        if !total.is_finite() {
            return Err(Error::Numerical {
                what: "pf: every particle has zero weight",
            });
        }
        let mut ess = self.ess;
        match self.y {
            None => {
                // Withheld: nothing learnt; w_k from its prior.
                let sd = self.w_var.sqrt();
                self.lw_next.copy_from_slice(&self.lw);
                for (x, out) in self.x.iter().zip(self.next.iter_mut()) {
                    *out = step.apply(x, sd * self.rng.normal());
                }
            }
            Some(y) => {
                let kernel = self.kernel(total)?;
                ess = self.weigh_kernels(y, &kernel)?;
                self.draw_conditional(y, &kernel, &step);
            }
        }
        self.commit(ess, y_next)
    }

    /// The kernel of the cloud for the update with `y_k`: the weighted mean and covariance of
    /// the particles (weights `lw − total`), the kernel covariance `h²` times it, and the gains
    /// of x and w on the innovation.
    fn kernel(&self, total: f64) -> Result<Kernel, Error> {
        let sys = Seed003Example;
        let k = self.k;
        let c: SMatrix<f64, 2, 3> = sys.c(k);
        let d: V2 = sys.d(k);
        let mut m = V3::zeros();
        for (x, &l) in self.x.iter().zip(&self.lw) {
            m += x * (l - total).exp();
        }
        let mut cov = M3::zeros();
        for (x, &l) in self.x.iter().zip(&self.lw) {
            let e = x - m;
            cov += (e * e.transpose()) * (l - total).exp();
        }
        let hk = (cov + cov.transpose()) * (0.5 * self.h2);
        let (lam, u) = symmetric_eigen(&hk, "pf kernel covariance")?;
        let lk = u * M3::from_diagonal(&lam.map(|l| l.max(0.0).sqrt()));
        let r = d * d.transpose() * self.w_var + SMatrix::<f64, 2, 2>::identity() * self.eps;
        let s = c * hk * c.transpose() + r;
        let s_inv = cholesky(&((s + s.transpose()) * 0.5), "pf innovation covariance")?.inverse();
        let kx = hk * c.transpose() * s_inv;
        let kw = d.transpose() * s_inv * self.w_var;
        Ok(Kernel {
            m,
            lk,
            s_inv,
            kx,
            kw,
            c,
            d,
        })
    }

    /// The kernel locations (shrunk towards the mean) weighted by their predictive
    /// likelihoods N(y; C m_i, S), normalised, resampled when the effective sample size falls
    /// below half the particles; returns the effective sample size as a fraction.
    fn weigh_kernels(&mut self, y: V2, kernel: &Kernel) -> Result<f64, Error> {
        let n = self.n;
        let shrink = (1.0 - self.h2).sqrt();
        for i in 0..n {
            let li = kernel.m + (self.x[i] - kernel.m) * shrink;
            let res = y - kernel.c * li;
            self.loc[i] = li;
            self.lw_next[i] = self.lw[i] - 0.5 * (res.transpose() * kernel.s_inv * res)[0];
        }
        let t = log_sum_exp(&self.lw_next);
        if !t.is_finite() {
            return Err(Error::Numerical {
                what: "pf: every kernel has zero likelihood",
            });
        }
        let mut sum_w2 = 0.0;
        for l in self.lw_next.iter_mut() {
            *l -= t;
            sum_w2 += (2.0 * *l).exp();
        }
        if 1.0 / sum_w2 < 0.5 * n as f64 {
            systematic_resample(&self.lw_next, &self.loc, &mut self.next, &mut self.rng);
            std::mem::swap(&mut self.loc, &mut self.next);
            self.lw_next.fill(-(n as f64).ln());
        }
        Ok(1.0 / (sum_w2 * n as f64))
    }

    /// Each particle: (x̃, w̃) from its kernel's conditional given y (Matheron's rule), then
    /// the move with the same w̃.
    fn draw_conditional(&mut self, y: V2, kernel: &Kernel, step: &Move) {
        let (sd, se) = (self.w_var.sqrt(), self.eps.sqrt());
        let (c, d) = (kernel.c, kernel.d);
        for (li, out) in self.loc.iter().zip(self.next.iter_mut()) {
            let xi = V3::new(self.rng.normal(), self.rng.normal(), self.rng.normal());
            let xs = li + kernel.lk * xi;
            let ws = sd * self.rng.normal();
            let mut ys = c * xs + d * ws;
            if se > 0.0 {
                ys += V2::new(self.rng.normal(), self.rng.normal()) * se;
            }
            let inn = y - ys;
            *out = step.apply(&(xs + kernel.kx * inn), ws + (kernel.kw * inn)[0]);
        }
    }

    /// The prediction x̂_{k+1} (the weighted mean) and its covariance Σ w (x − x̂)(x − x̂)ᵀ
    /// (each term exactly symmetric) from the moved particles, then the commit: the scratch
    /// space becomes the cloud, `y_next` the stored measurement.
    fn commit(&mut self, ess: f64, y_next: Option<V2>) -> Result<(), Error> {
        let t = log_sum_exp(&self.lw_next);
        let mut mean = V3::zeros();
        for (x, &l) in self.next.iter().zip(&self.lw_next) {
            mean += x * (l - t).exp();
        }
        if !(t.is_finite() && mean.iter().all(|v| v.is_finite())) {
            return Err(Error::NonFinite {
                what: "pf: predicted particles",
            });
        }
        let mut cov = M3::zeros();
        for (x, &l) in self.next.iter().zip(&self.lw_next) {
            let d = x - mean;
            cov += d * d.transpose() * (l - t).exp();
        }
        std::mem::swap(&mut self.x, &mut self.next);
        std::mem::swap(&mut self.lw, &mut self.lw_next);
        self.mean = mean;
        self.cov = cov;
        self.ess = ess;
        self.y = y_next;
        self.k += 1;
        Ok(())
    }
}

/// The plant's move at instant k: x' = A x + g(x) + B w.
struct Move {
    a: M3,
    b: V3,
}

impl Move {
    fn apply(&self, x: &V3, w: f64) -> V3 {
        self.a * x + Seed003Example.eval(x) + self.b * w
    }
}

/// The update's kernel ([`CoupledPf::kernel`]).
struct Kernel {
    m: V3,
    lk: M3,
    s_inv: SMatrix<f64, 2, 2>,
    kx: SMatrix<f64, 3, 2>,
    kw: SMatrix<f64, 1, 2>,
    c: SMatrix<f64, 2, 3>,
    d: V2,
}

impl std::fmt::Debug for CoupledPf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CoupledPf")
            .field("particles", &self.n)
            .field("k", &self.k)
            .field("eps", &self.eps)
            .field("mean", &self.mean)
            .finish_non_exhaustive()
    }
}

/// Systematic resampling of `from` by the normalised log-weights `lw` into `to`.
fn systematic_resample(lw: &[f64], from: &[V3], to: &mut [V3], rng: &mut Rng) {
    let n = from.len();
    let u0 = rng.uniform() / n as f64;
    let mut cum = lw[0].exp();
    let mut j = 0usize;
    for (p, out) in to.iter_mut().enumerate() {
        let target = u0 + p as f64 / n as f64;
        while j < n - 1 && cum < target {
            j += 1;
            cum += lw[j].exp();
        }
        *out = from[j];
    }
}

impl Estimator for CoupledPf {
    fn name(&self) -> &'static str {
        "pf"
    }

    /// Instant `k`'s observation (node 0's). Instants between the last one stepped and `k`
    /// (lost inside the IPC) are stepped first as withheld; an instant already stepped is
    /// refused with [`Error::OutOfOrder`].
    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        let k = k as usize;
        let expected = self.k + 1;
        if k < expected {
            return Err(Error::OutOfOrder { expected, got: k });
        }
        let y = obs
            .first()
            .and_then(|o| o.measurement())
            .map(V2::from_column_slice);
        if let Some(y) = &y {
            if y.iter().any(|v| !v.is_finite()) {
                return Err(Error::NonFinite {
                    what: "measurement",
                });
            }
        }
        while self.k + 1 < k {
            self.advance(None)?;
        }
        self.advance(y)
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..3].copy_from_slice(self.mean.as_slice());
    }

    fn covariance(&self, out: &mut [f64]) -> crate::CovarianceKind {
        for i in 0..3 {
            for j in 0..3 {
                out[i * 3 + j] = self.cov[(i, j)];
            }
        }
        crate::CovarianceKind::Estimate
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        sink("ess", self.ess);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Run `run` of the `nn-token-bucket` preset: truth x_k, observations (k = 1..=t) and y₀.
    fn simulate(seed: u64, run: u64, t: u32) -> (V3, Option<V2>, Vec<(V3, Observation)>) {
        let (_, mut sim) = crate::presets::preset_run("nn-token-bucket", seed, run);
        let x0 = V3::from_column_slice(&sim.initial_truth()[..3]);
        let y0 = sim.initial_observations().unwrap()[0]
            .measurement()
            .map(V2::from_column_slice);
        let steps = (1..=t)
            .map(|_| {
                let i = sim.next_instant();
                (V3::from_column_slice(&i.truth[..3]), i.obs[0])
            })
            .collect();
        (x0, y0, steps)
    }

    #[test]
    fn started_at_the_truth_it_follows_the_plant_at_the_information_bound() {
        // Started at x₀ (prior variance 1e-6), the exact conditioning on the shared noise must
        // keep the cloud on the plant: after a sent y_k, w_k is determined and so is x_{k+1};
        // after a withheld one, x_{k+1} is uncertain by B_k w_k. No predictor can do better
        // than an oracle that knows x_k, whose MSE is w̄² |B_{k−1}|² at the instants after a
        // withheld packet and 0 elsewhere: over k = 1..=12 (withheld at 6 and 9) that bound is
        // 0.1 (2 + cos² 6 + 2 + cos² 9) / 12 ≈ 0.048. A filter that drew w_k independently of
        // y_k, or took D w independent of B w, would be off by O(1) at every instant. The
        // tolerance: the MSE must lie in [0.3, 2] × the bound. With 20 runs the sum is
        // dominated by 40 squared B-sized errors (about χ²₁ each, relative s.d. √(2/40) ≈ 0.22),
        // so 2× is +4.5 s.d. and 0.3× is −3.2 s.d.; the errors at the other instants are
        // ~1e-5 (the cloud's spread) and do not matter. Over longer horizons the cloud does
        // not stay locked (docs/nn-token-bucket.md): a collapsed cloud cannot correct the
        // error the expanding dynamics grow from its last rounding.
        let (runs, t, n) = (20u64, 12u32, 500usize);
        let (mut mse, mut bound) = (0.0, 0.0);
        for run in 0..runs {
            let (x0, y0, steps) = simulate(77, run, t);
            let mut pf = CoupledPf::new(x0, M3::identity() * 1e-6, 0.1, y0, n, 77, run).unwrap();
            let mut prev_sent = y0.is_some();
            for (k, (x, o)) in (1..=t).zip(&steps) {
                pf.step(k, std::slice::from_ref(o)).unwrap();
                let mut xhat = [0.0; 3];
                pf.estimate(&mut xhat);
                mse += (x - V3::from_column_slice(&xhat)).norm_squared();
                if !prev_sent {
                    let b: V3 = Seed003Example.b(k as usize - 1);
                    bound += 0.1 * b.norm_squared();
                }
                prev_sent = o.delivered;
            }
        }
        let (mse, bound) = (
            mse / (runs * t as u64) as f64,
            bound / (runs * t as u64) as f64,
        );
        assert!((bound - 0.0479).abs() < 1e-3, "bound {bound}");
        assert!(
            (0.3 * bound..2.0 * bound).contains(&mse),
            "pf {mse} vs bound {bound}"
        );
    }

    /// The reported covariance is the cloud's: after each step, Σ w x xᵀ − x̂ x̂ᵀ over the
    /// particles and normalised weights the filter holds (another formula for the same
    /// quantity), to 1e-9 of its largest entry; P_0 before the first step.
    #[test]
    fn covariance_is_the_weighted_covariance_of_the_cloud() {
        let (x0, y0, steps) = simulate(5, 1, 8);
        let p0 = M3::identity() * 10.0;
        let mut pf = CoupledPf::new(x0, p0, 0.1, y0, 400, 5, 1).unwrap();
        let mut got = [0.0; 9];
        assert_eq!(pf.covariance(&mut got), crate::CovarianceKind::Estimate);
        assert_eq!(M3::from_row_slice(&got), p0);
        for (k, (_, o)) in (1..=8).zip(&steps) {
            pf.step(k, std::slice::from_ref(o)).unwrap();
            pf.covariance(&mut got);
            let t = log_sum_exp(&pf.lw);
            let (mut m, mut second) = (V3::zeros(), M3::zeros());
            for (x, &l) in pf.x.iter().zip(&pf.lw) {
                let w = (l - t).exp();
                m += x * w;
                second += x * x.transpose() * w;
            }
            let want = second - m * m.transpose();
            let got = M3::from_row_slice(&got);
            assert!(
                (got - want).amax() <= 1e-9 * want.amax(),
                "k={k}: {got} vs {want}"
            );
            assert_eq!(got, got.transpose());
            let mut xhat = [0.0; 3];
            pf.estimate(&mut xhat);
            assert!((V3::from_column_slice(&xhat) - m).amax() < 1e-9 * (1.0 + m.amax()));
        }
    }

    #[test]
    fn refuses_bad_input_and_steps_gaps_as_withheld() {
        let (x0, y0, steps) = simulate(1, 0, 5);
        let p0 = M3::identity() * 10.0;
        assert!(CoupledPf::new(x0, p0, 0.1, y0, 1, 1, 0).is_err());
        assert!(CoupledPf::new(x0, p0, -0.1, y0, 10, 1, 0).is_err());
        let mut pf = CoupledPf::new(V3::zeros(), p0, 0.1, y0, 100, 1, 0).unwrap();
        let mut bad = steps[0].1;
        bad.y[0] = f64::NAN;
        assert_eq!(
            pf.step(1, &[bad]),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(pf.instant(), 0);
        // k = 3 before k = 1, 2: the two are stepped as withheld first.
        pf.step(3, std::slice::from_ref(&steps[2].1)).unwrap();
        assert_eq!(pf.instant(), 3);
        assert_eq!(
            pf.step(3, std::slice::from_ref(&steps[2].1)),
            Err(Error::OutOfOrder {
                expected: 4,
                got: 3
            })
        );
    }
}
