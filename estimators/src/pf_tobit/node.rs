//! One sensor node as a particle sees it: its censored measurement (seed 004, eq. 2), its
//! dynamic event trigger (eqs. 11-15) and what one instant's packet does to a particle's
//! weight, η and reference.

use estimator_core::gauss::{ln_cdf, ln_pdf};
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estpipe_spec::LinearModel;
use estpipe_wire::MAX_NY;

use super::super::particles_rng::Rng;

/// What the receiver made of one node's packet of an instant (the bucket mirror's verdict,
/// `estimator_core::filter::silence::Arrival`, with the grant a lost packet would have had).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Seen<'a> {
    /// The measurement arrived (padded to `MAX_NY`; only the node's own components are read).
    Received(&'a [f64]),
    /// Nothing arrived although the node had a token: its trigger held.
    Held,
    /// Nothing arrived and the mirror cannot say the node had a token.
    Blocked,
    /// Lost in transport; `granted`: the node had a token (or the level is unknown).
    Lost {
        /// β of eq. (18) as far as the receiver knows.
        granted: bool,
    },
}

/// Node m's measurement model and trigger parameters.
#[derive(Clone, Debug)]
pub(super) struct NodeModel {
    ny: usize,
    nx: usize,
    /// C_m, row-major `ny × nx`.
    c: Vec<f64>,
    /// √R_jj (R diagonal: the censored likelihood factorises per component).
    sd: Vec<f64>,
    /// Σ_j ln √R_jj, the density's constant.
    ln_sd: f64,
    /// τ_m (eq. 2).
    tau: Vec<f64>,
    trigger: EventTriggerConfig<f64>,
    /// ȳ_{m,0}, the reference before the first send.
    reference: Vec<f64>,
}

impl NodeModel {
    /// Node `m` of `model`, its thresholds `tau`, trigger and initial reference; `None` when
    /// `D R Dᵀ` is not diagonal.
    pub(super) fn new(
        model: &LinearModel,
        m: usize,
        tau: &[f64],
        trigger: EventTriggerConfig<f64>,
        reference: &[f64],
    ) -> Option<Self> {
        let (ny, nx) = (model.node_ny(m), model.nx());
        let r = model.measurement_cov(m);
        let diagonal = (0..ny).all(|i| (0..ny).all(|j| i == j || r[(i, j)] == 0.0));
        if !diagonal || tau.len() != ny || reference.len() != ny {
            return None;
        }
        let c = model.c(m);
        let sd: Vec<f64> = (0..ny).map(|j| r[(j, j)].sqrt()).collect();
        Some(Self {
            ny,
            nx,
            c: (0..ny * nx).map(|i| c[(i / nx, i % nx)]).collect(),
            ln_sd: sd.iter().map(|s| s.ln()).sum(),
            sd,
            tau: tau.to_vec(),
            trigger,
            reference: reference.to_vec(),
        })
    }

    /// n_y of the node.
    pub(super) fn ny(&self) -> usize {
        self.ny
    }

    /// η₀.
    pub(super) fn eta0(&self) -> f64 {
        self.trigger.eta0()
    }

    /// ȳ_{m,0}.
    pub(super) fn initial_reference(&self) -> &[f64] {
        &self.reference
    }

    /// `C_m x` into `out[..ny]`.
    fn mean(&self, x: &[f64], out: &mut [f64; MAX_NY]) {
        for (j, o) in out[..self.ny].iter_mut().enumerate() {
            let row = &self.c[j * self.nx..(j + 1) * self.nx];
            *o = row.iter().zip(x).map(|(c, x)| c * x).sum();
        }
    }

    /// `ln p(y | x)` of the censored measurement: a component at its threshold has the
    /// probability Φ((τ_j − c_j x)/√R_j) that the uncensored one fell below it, any other the
    /// Gaussian density N(y_j; c_j x, R_j) (eq. 2).
    pub(super) fn ln_density(&self, mu: &[f64; MAX_NY], y: &[f64]) -> f64 {
        let mut ll = -self.ln_sd;
        for j in 0..self.ny {
            ll += if y[j] <= self.tau[j] {
                ln_cdf((self.tau[j] - mu[j]) / self.sd[j]) + self.sd[j].ln()
            } else {
                ln_pdf((y[j] - mu[j]) / self.sd[j])
            };
        }
        ll
    }

    /// A draw of `y = max(C x + v, τ)` given `mu = C x`.
    fn sample(&self, mu: &[f64; MAX_NY], rng: &mut Rng, y: &mut [f64; MAX_NY]) {
        for j in 0..self.ny {
            y[j] = (mu[j] + self.sd[j] * rng.normal()).max(self.tau[j]);
        }
    }

    /// ‖ȳ − y‖ over the node's components (eq. 12).
    fn error_norm(&self, reference: &[f64], y: &[f64]) -> f64 {
        let s: f64 = (0..self.ny).map(|j| (reference[j] - y[j]).powi(2)).sum();
        s.sqrt()
    }

    /// The trigger fires: `η/χ + σ − ‖ε‖ ≤ 0` (14).
    fn fires(&self, eta: f64, error_norm: f64) -> bool {
        eta / self.trigger.chi() + self.trigger.sigma() - error_norm <= 0.0
    }

    /// η of the next instant, `λη + σ − ‖ε‖` (13), with ε after the decision (0 when sent).
    fn eta_next(&self, eta: f64, post_error_norm: f64) -> f64 {
        self.trigger.lambda() * eta + self.trigger.sigma() - post_error_norm
    }

    /// The held silence of a particle at `mu = C x` with trigger variable `eta` and reference
    /// `reference`, by `samples` draws of its censored measurement: how many kept the trigger
    /// silent, and ‖ε‖ of the first that did (of the first draw when none did). The count
    /// over `samples` is an unbiased estimate of P(silent | x, η), and the first silent draw
    /// is a draw of y given x and the silence, which η's recursion needs.
    pub(super) fn held(
        &self,
        mu: &[f64; MAX_NY],
        eta: f64,
        reference: &[f64],
        rng: &mut Rng,
        samples: usize,
    ) -> (usize, f64) {
        let mut y = [0.0; MAX_NY];
        let (mut silent, mut first, mut used) = (0, None, None);
        for _ in 0..samples {
            self.sample(mu, rng, &mut y);
            let e = self.error_norm(reference, &y);
            first.get_or_insert(e);
            if !self.fires(eta, e) {
                silent += 1;
                used.get_or_insert(e);
            }
        }
        // With no silent draw the particle's weight is 0, unless the instant collapses and
        // the indicators are dropped: its η then follows an unconditioned draw.
        (silent, used.or(first).unwrap_or(0.0))
    }

    /// One instant of node m for one particle at state `x`: the log-likelihood factors of
    /// what was seen `(with the trigger's indicators, without them)`, and the particle's η and
    /// reference moved as the node moved its own (13), (19).
    pub(super) fn update(
        &self,
        seen: Seen<'_>,
        x: &[f64],
        eta: &mut f64,
        reference: &mut [f64],
        rng: &mut Rng,
        samples: usize,
    ) -> (f64, f64) {
        let mut mu = [0.0; MAX_NY];
        self.mean(x, &mut mu);
        match seen {
            Seen::Received(y) => {
                let ll = self.ln_density(&mu, y);
                let fired = self.fires(*eta, self.error_norm(reference, y));
                *eta = self.eta_next(*eta, 0.0);
                reference.copy_from_slice(&y[..self.ny]);
                (if fired { ll } else { f64::NEG_INFINITY }, ll)
            }
            Seen::Held if samples > 0 => {
                let (silent, e) = self.held(&mu, *eta, reference, rng, samples);
                *eta = self.eta_next(*eta, e);
                ((silent as f64 / samples as f64).ln(), 0.0)
            }
            Seen::Held | Seen::Blocked => {
                let mut y = [0.0; MAX_NY];
                self.sample(&mu, rng, &mut y);
                *eta = self.eta_next(*eta, self.error_norm(reference, &y));
                (0.0, 0.0)
            }
            Seen::Lost { granted } => {
                let mut y = [0.0; MAX_NY];
                self.sample(&mu, rng, &mut y);
                let e = self.error_norm(reference, &y);
                if granted && self.fires(*eta, e) {
                    *eta = self.eta_next(*eta, 0.0);
                    reference.copy_from_slice(&y[..self.ny]);
                } else {
                    *eta = self.eta_next(*eta, e);
                }
                (0.0, 0.0)
            }
        }
    }
}
