//! `pf` for seed 004: a bootstrap particle filter on the state *and* every node's trigger
//! variable — the reference the Tobit fusion estimators are compared with (evaluation only;
//! std, no core; docs/tobit-fusion.md).
//!
//! **State.** A particle carries x (n_x), and per node m the trigger variable η_m (eq. 13)
//! and the reference ȳ_m (eq. 19). The receiver knows ȳ_m (the last delivered packet) until
//! a packet is lost in transport; η_m it never knows, because the recursion (13) runs on the
//! errors of measurements that were never sent: that is why η is in the particle. Particles
//! start from `N(x̂_0, P_0)` with η_m = η_{m,0} and ȳ_m the configured initial reference,
//! and move with `x_k = A x_{k−1} + B w (+ B_u u_{k−1})`, `w ~ N(0, Q)`.
//!
//! **Weights.** Per node, after the receiver's mirror of the shared bucket
//! (`estimator_core::protocol::bucket_mirror`, eqs. 16-18) has classified the node's packet
//! (never the simulator's flags):
//!
//! ```text
//! received y:  p(y | x) · 1[η/χ + σ − ‖ȳ − y‖ ≤ 0]          (2), (14)
//!              p(y | x) = Π_j N(y_j; c_j x, R_j) uncensored,  Φ((τ_j − c_j x)/√R_j) at τ_j
//!              then η ← λη + σ (ε = 0 after a send), ȳ ← y          (13), (19)
//! held:        P(η/χ + σ − ‖ȳ − y‖ > 0 | x, η),  y = max(C x + v, τ)
//!              estimated by K draws of y (the fraction that keep the trigger silent);
//!              then η ← λη + σ − ‖ȳ − y‖ with the first silent draw
//! blocked:     1 (no information); η ← λη + σ − ‖ȳ − y‖ with y drawn from p(y | x)
//! lost:        1; y drawn from p(y | x), and the particle's own trigger decides: if it
//!              fires and the node had a token (or the level is unknown), the particle
//!              treats it as sent (η ← λη + σ, ȳ ← y), otherwise η ← λη + σ − ‖ȳ − y‖
//! ```
//!
//! R must be diagonal (the censored likelihood then factorises per component; otherwise
//! `build` refuses the spec). The fraction of K draws is an unbiased estimate of the held
//! silence's likelihood, so the filter targets the exact posterior with a noisier weight;
//! [`HELD_SAMPLES`] is K, and K = 0 reads a held silence as no information (a blocked one).
//! A lost packet's grant is the mirror's when it knows the level (or the level another
//! packet of the instant reports), and assumed when it does not: the particle cannot tell
//! a refused send from a granted one there.
//!
//! **Collapse.** The trigger indicators can exclude every particle at once (a delivered
//! packet no particle's η lets fire, or a held silence no particle's draws reproduce). The
//! instant is then weighted without its indicator factors (delivered densities only), the
//! count `pf_collapses` grows by one, and the filter goes on: never NaN, never an error.
//!
//! **Output.** Weights are kept as logarithms; the estimate is the weighted mean, its
//! covariance the weighted sample covariance (before resampling; P_0 at k = 0), reported as
//! an estimate; systematic resampling when the effective sample size drops below half the
//! particle count. Diagnostics: `trace_p`, `ess` (of the instant's weights), `pf_collapses`
//! (cumulative), and against the truth `nees` = eᵀP⁻¹e and `inside_95` (`nees ≤ χ²_{n_x}(0.95)`).
//! Random numbers: the particle filters' xoshiro256++ (`particles_rng`), seeded from
//! `(seed, run)` by SplitMix64 on a stream of its own. The particles are allocated once
//! ([`bytes_per_particle`]); a step allocates nothing. Instants that never reached the
//! runner are stepped as lost before the next one.
//!
//! Not built with `--particles 0`, or when the spec declares a loss rate (a loss the
//! receiver cannot tell from a silence would make every held silence ambiguous, as for the
//! silence-reading Tobit views).

mod node;
#[cfg(test)]
mod tests;

use std::sync::Arc;

use estimator_core::catch_up::LostMeasurement;
use estimator_core::filter::gate::chi2_quantile;
use estimator_core::filter::silence::{Arrival, TriggeredPackets};
use estimator_core::gauss::log_sum_exp;
use estimator_core::protocol::bucket_mirror::BucketMirror;
use estimator_core::protocol::shared_token_bucket::{share_covers, SharedTokenBucket};
use estimator_core::Error;
use estpipe_spec::channel::{TobitCensoring, TriggeredTokenBucket};
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::{Observation, MAX_NX, MAX_NY};
use nalgebra::SMatrix;

use super::particles_rng::{splitmix64, Rng};
use super::pf::{lower_cholesky, weighted_covariance};
use super::slots::FromSlots;
use super::{BuildOptions, RunStart};
use crate::{CovarianceKind, Estimator};
use node::{NodeModel, Seen};

/// K: draws of a particle's censored measurement per held silence.
pub const HELD_SAMPLES: usize = 8;

/// Bytes one particle of this filter holds on `spec` (x, η and ȳ of every node, each with
/// its copy while resampling, and two log-weights), 0 for a spec it does not apply to.
pub fn bytes_per_particle(spec: &EstimatorSpec) -> u64 {
    if spec.linear().is_none()
        || spec.channel.tobit.is_none()
        || spec.channel.event_trigger.is_none()
    {
        return 0;
    }
    let (nx, l, ny) = (spec.nx() as u64, spec.nodes() as u64, spec.ny() as u64);
    8 * (2 * (nx + l + l * ny) + 2)
}

/// Builds `pf` for a spec with a linear model, Tobit censoring and event triggers sharing a
/// token bucket (empty otherwise, with `--particles 0`, or with a declared loss rate).
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    if options.particles == 0 || options.loss_rate > 0.0 || bytes_per_particle(spec) == 0 {
        return Ok(Vec::new());
    }
    let setup = Setup {
        particles: options.particles,
        held_samples: HELD_SAMPLES,
        seed: start.seed,
        run: start.run,
    };
    Ok(vec![boxed(spec, &setup)?])
}

/// What a filter is built with beside the spec.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Setup {
    /// N.
    pub particles: usize,
    /// K ([`HELD_SAMPLES`]; 0 reads a held silence as no information).
    pub held_samples: usize,
    /// Experiment seed.
    pub seed: u64,
    /// Run index.
    pub run: u64,
}

/// The filter for `spec`'s node count (the bucket mirror is sized at compile time).
pub(crate) fn boxed(
    spec: &Arc<EstimatorSpec>,
    setup: &Setup,
) -> anyhow::Result<Box<dyn Estimator>> {
    macro_rules! by_l {
        ($($l:literal)*) => {
            match spec.nodes() {
                $($l => Box::new(TobitPf::<$l>::new(spec, setup)?) as Box<dyn Estimator>,)*
                l => anyhow::bail!("pf: {l} nodes not supported (1..=8)"),
            }
        };
    }
    Ok(by_l!(1 2 3 4 5 6 7 8))
}

/// `A` row-major and `G = B L_Q` (`L_Q` the lower Cholesky factor of Q), so that `G ξ`,
/// `ξ ~ N(0, I)`, is the process noise even where `B Q Bᵀ` is singular (the example's B is
/// a column).
struct Plant {
    nx: usize,
    nw: usize,
    a: Vec<f64>,
    g: Vec<f64>,
}

impl Plant {
    fn of(model: &LinearModel) -> Result<Self, Error> {
        let (nx, nw) = (model.nx(), model.q().nrows());
        let g = model.b() * lower_cholesky(model.q(), "process noise Q")?;
        Ok(Self {
            nx,
            nw,
            a: (0..nx * nx).map(|i| model.a()[(i / nx, i % nx)]).collect(),
            g: (0..nx * nw).map(|i| g[(i / nw, i % nw)]).collect(),
        })
    }

    /// `x ← A x + G ξ (+ bu)` in place.
    fn propagate(&self, x: &mut [f64], bu: Option<&[f64]>, rng: &mut Rng) {
        let (nx, nw) = (self.nx, self.nw);
        let mut xi = [0.0; MAX_NX];
        for v in xi[..nw].iter_mut() {
            *v = rng.normal();
        }
        let mut next = [0.0; MAX_NX];
        for (i, out) in next[..nx].iter_mut().enumerate() {
            let a = &self.a[i * nx..(i + 1) * nx];
            let g = &self.g[i * nw..(i + 1) * nw];
            *out = a.iter().zip(&*x).map(|(a, x)| a * x).sum::<f64>()
                + g.iter().zip(&xi).map(|(g, w)| g * w).sum::<f64>()
                + bu.map_or(0.0, |b| b[i]);
        }
        x.copy_from_slice(&next[..nx]);
    }
}

/// The particles: x, η and ȳ of every node, row by row, and their log-weights.
struct Particles {
    x: Vec<f64>,
    eta: Vec<f64>,
    reference: Vec<f64>,
    lw: Vec<f64>,
    /// The instant's log-weights without the trigger's indicator factors (the fallback of
    /// a collapse).
    lw_soft: Vec<f64>,
}

/// The seed-004 particle filter over `L` nodes.
struct TobitPf<const L: usize> {
    spec: Arc<EstimatorSpec>,
    n: usize,
    /// The row length of ȳ: the largest node's n_y.
    nyw: usize,
    held_samples: usize,
    plant: Plant,
    nodes: Vec<NodeModel>,
    costs: [u32; L],
    mirror: BucketMirror<L>,
    p: Particles,
    /// The copy resampling writes into.
    spare: Particles,
    mean: Vec<f64>,
    cov: Vec<f64>,
    ess: f64,
    collapses: u32,
    chi2_95: f64,
    /// The last instant stepped.
    k: u32,
    rng: Rng,
}

/// Node m's τ, trigger and reference, checked against `L`.
fn node_models(
    linear: &LinearModel,
    tobit: &TobitCensoring,
    trig: &TriggeredTokenBucket,
    l: usize,
) -> anyhow::Result<Vec<NodeModel>> {
    anyhow::ensure!(
        tobit.nodes() == l && trig.nodes() == l,
        "pf: the censoring and trigger stages must have one entry per node ({l})"
    );
    (0..l)
        .map(|m| {
            NodeModel::new(linear, m, tobit.tau(m), *trig.trigger(m), trig.reference(m)).ok_or_else(
                || {
                    anyhow::anyhow!(
                        "pf: node {m}: the censored likelihood needs a diagonal D R Dᵀ and \
                         one threshold and reference entry per measurement component"
                    )
                },
            )
        })
        .collect()
}

impl<const L: usize> TobitPf<L> {
    fn new(spec: &Arc<EstimatorSpec>, setup: &Setup) -> anyhow::Result<Self> {
        let linear = super::fed::linear(spec)?;
        let (Some(tobit), Some(trig)) = (&spec.channel.tobit, &spec.channel.event_trigger) else {
            anyhow::bail!("pf: the spec has no Tobit censoring and event trigger");
        };
        let nodes = node_models(linear, tobit, trig, L)?;
        let (initial, rate, capacity) = trig.bucket();
        let costs: [u32; L] = core::array::from_fn(|m| trig.costs()[m]);
        let bucket = SharedTokenBucket::<L>::new(initial, rate, capacity, costs)
            .map_err(|e| anyhow::anyhow!("pf: bucket: {e}"))?;
        let (nx, n, nyw) = (spec.nx(), setup.particles, spec.ny());
        // "pf_tobit": a stream of its own, independent of the simulation's and of seed 001's.
        let mut rng = Rng::new(splitmix64(
            splitmix64(setup.seed ^ 0x7066_5f74_6f62_6974) ^ setup.run,
        ));
        let p = Particles::prior(spec, &nodes, n, nyw, &mut rng)?;
        let spare = Particles {
            x: vec![0.0; n * nx],
            eta: vec![0.0; n * L],
            reference: vec![0.0; n * L * nyw],
            lw: Vec::new(),
            lw_soft: Vec::new(),
        };
        let prior = &spec.prior;
        Ok(Self {
            spec: Arc::clone(spec),
            n,
            nyw,
            held_samples: setup.held_samples,
            plant: Plant::of(linear)?,
            nodes,
            costs,
            mirror: BucketMirror::new(bucket),
            p,
            spare,
            mean: prior.mean.as_slice().to_vec(),
            cov: (0..nx * nx).map(|i| prior.cov[(i / nx, i % nx)]).collect(),
            ess: n as f64,
            collapses: 0,
            chi2_95: chi2_quantile(0.95, nx)?,
            k: 0,
            rng,
        })
    }
}

impl Particles {
    /// `n` particles from the prior, every node's η at η₀ and ȳ at its initial reference.
    fn prior(
        spec: &EstimatorSpec,
        nodes: &[NodeModel],
        n: usize,
        nyw: usize,
        rng: &mut Rng,
    ) -> anyhow::Result<Self> {
        let (nx, l) = (spec.nx(), nodes.len());
        let l0 = lower_cholesky(&spec.prior.cov, "P0")?;
        let mut x = vec![0.0; n * nx];
        let mut xi = [0.0; MAX_NX];
        for row in x.chunks_exact_mut(nx) {
            for v in xi[..nx].iter_mut() {
                *v = rng.normal();
            }
            for (i, out) in row.iter_mut().enumerate() {
                *out = spec.prior.mean[i] + (0..=i).map(|j| l0[(i, j)] * xi[j]).sum::<f64>();
            }
        }
        let mut reference = vec![0.0; n * l * nyw];
        for (r, node) in reference.chunks_exact_mut(nyw).zip(nodes.iter().cycle()) {
            r[..node.ny()].copy_from_slice(node.initial_reference());
        }
        Ok(Self {
            x,
            eta: (0..n * l).map(|i| nodes[i % l].eta0()).collect(),
            reference,
            lw: vec![-(n as f64).ln(); n],
            lw_soft: vec![0.0; n],
        })
    }
}

impl<const L: usize> TobitPf<L> {
    /// One instant: the mirror's verdict on every node, then the particles.
    fn advance(&mut self, k: u32, packets: &TriggeredPackets<f64, MAX_NY, L>) -> Result<(), Error> {
        // ξ_{t−1}, what this instant's grants use: reported by a delivered packet, or the
        // mirror's while it knows it.
        let level = packets.level.or(self.mirror.level());
        let held = self.mirror.step(&packets.sent(), packets.level);
        let arrivals = packets.arrivals(&held);
        let seen: [Seen<'_>; L] = core::array::from_fn(|m| match arrivals[m] {
            Arrival::Received(y) => Seen::Received(y.as_slice()),
            Arrival::Held => Seen::Held,
            Arrival::Blocked => Seen::Blocked,
            Arrival::Lost => Seen::Lost {
                granted: level.is_none_or(|xi| share_covers(xi, L, self.costs[m])),
            },
        });
        let mut u = [0.0; MAX_NX];
        let bu = super::fed::linear(&self.spec)?
            .input_into(k.saturating_sub(1) as usize, &mut u)
            .then_some(&u[..self.plant.nx]);
        self.weigh(&seen, bu);
        self.settle();
        if self.ess < 0.5 * self.n as f64 {
            self.resample();
        }
        Ok(())
    }

    /// Moves every particle and multiplies in the instant's likelihood factors: `lw` with
    /// the trigger's indicators, `lw_soft` without them.
    fn weigh(&mut self, seen: &[Seen<'_>; L], bu: Option<&[f64]>) {
        let (nx, nyw) = (self.plant.nx, self.nyw);
        let p = &mut self.p;
        let rows =
            p.x.chunks_exact_mut(nx)
                .zip(p.eta.chunks_exact_mut(L))
                .zip(p.reference.chunks_exact_mut(L * nyw))
                .zip(p.lw.iter_mut().zip(p.lw_soft.iter_mut()));
        for (((x, eta), reference), (lw, lw_soft)) in rows {
            self.plant.propagate(x, bu, &mut self.rng);
            let (mut full, mut soft) = (0.0, 0.0);
            for (m, node) in self.nodes.iter().enumerate() {
                let r = &mut reference[m * nyw..m * nyw + node.ny()];
                let (f, s) =
                    node.update(seen[m], x, &mut eta[m], r, &mut self.rng, self.held_samples);
                full += f;
                soft += s;
            }
            *lw_soft = *lw + soft;
            *lw += full;
        }
    }

    /// Normalises the weights (the indicator-free ones when the indicators excluded every
    /// particle), then the weighted mean, covariance and effective sample size.
    fn settle(&mut self) {
        let mut total = log_sum_exp(&self.p.lw);
        if !total.is_finite() {
            self.collapses += 1;
            std::mem::swap(&mut self.p.lw, &mut self.p.lw_soft);
            total = log_sum_exp(&self.p.lw);
            if !total.is_finite() {
                // Not reachable with finite measurements; uniform rather than NaN.
                self.p.lw.fill(0.0);
                total = (self.n as f64).ln();
            }
        }
        let nx = self.plant.nx;
        let mut mean = [0.0; MAX_NX];
        let mut sum_w2 = 0.0;
        for (lw, x) in self.p.lw.iter_mut().zip(self.p.x.chunks_exact(nx)) {
            *lw -= total;
            let w = lw.exp();
            sum_w2 += w * w;
            for (m, v) in mean[..nx].iter_mut().zip(x) {
                *m += w * v;
            }
        }
        self.mean.copy_from_slice(&mean[..nx]);
        weighted_covariance(&self.p.x, &self.p.lw, &self.mean, &mut self.cov);
        self.ess = 1.0 / sum_w2;
    }

    /// Systematic resampling of every particle's x, η and ȳ.
    fn resample(&mut self) {
        let (n, nx, nyw) = (self.n, self.plant.nx, self.nyw);
        let u0 = self.rng.uniform() / n as f64;
        let (mut cum, mut j) = (0.0, 0usize);
        let (p, s) = (&self.p, &mut self.spare);
        for i in 0..n {
            let target = u0 + i as f64 / n as f64;
            while j < n - 1 && cum + p.lw[j].exp() < target {
                cum += p.lw[j].exp();
                j += 1;
            }
            s.x[i * nx..(i + 1) * nx].copy_from_slice(&p.x[j * nx..(j + 1) * nx]);
            s.eta[i * L..(i + 1) * L].copy_from_slice(&p.eta[j * L..(j + 1) * L]);
            let w = L * nyw;
            s.reference[i * w..(i + 1) * w].copy_from_slice(&p.reference[j * w..(j + 1) * w]);
        }
        std::mem::swap(&mut self.p.x, &mut self.spare.x);
        std::mem::swap(&mut self.p.eta, &mut self.spare.eta);
        std::mem::swap(&mut self.p.reference, &mut self.spare.reference);
        self.p.lw.fill(-(n as f64).ln());
    }
}

impl<const L: usize> Estimator for TobitPf<L> {
    fn name(&self) -> &'static str {
        "pf"
    }

    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        if obs
            .iter()
            .filter_map(|o| o.measurement())
            .any(|y| y.iter().any(|v| !v.is_finite()))
        {
            return Err(Error::NonFinite {
                what: "measurement",
            });
        }
        // Instants that never reached the runner: every packet lost.
        for missed in self.k.saturating_add(1)..k {
            self.advance(missed, &TriggeredPackets::lost())?;
        }
        self.advance(k, &FromSlots::from_slots(obs))?;
        self.k = k;
        Ok(())
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..self.plant.nx].copy_from_slice(&self.mean);
    }

    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        out[..self.cov.len()].copy_from_slice(&self.cov);
        CovarianceKind::Estimate
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        let nx = self.plant.nx;
        sink("trace_p", (0..nx).map(|i| self.cov[i * nx + i]).sum());
        sink("ess", self.ess);
        sink("pf_collapses", f64::from(self.collapses));
    }

    fn diagnostics_vs_truth(&self, truth: &[f64], sink: &mut dyn FnMut(&'static str, f64)) {
        if let Some(nees) = nees(&self.mean, &self.cov, truth) {
            sink("nees", nees);
            sink("inside_95", f64::from(u8::from(nees <= self.chi2_95)));
        }
    }
}

/// `eᵀP⁻¹e` with `e = truth − mean` (`None` when P is not positive definite): P padded with
/// the identity to the largest n_x, so the factorisation needs no allocation.
fn nees(mean: &[f64], cov: &[f64], truth: &[f64]) -> Option<f64> {
    let nx = mean.len();
    let mut p = SMatrix::<f64, MAX_NX, MAX_NX>::identity();
    let mut e = SMatrix::<f64, MAX_NX, 1>::zeros();
    for i in 0..nx {
        e[i] = truth[i] - mean[i];
        for j in 0..nx {
            p[(i, j)] = cov[i * nx + j];
        }
    }
    let v = e.dot(&p.cholesky()?.solve(&e));
    v.is_finite().then_some(v)
}
