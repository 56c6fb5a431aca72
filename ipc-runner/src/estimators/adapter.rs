//! The application's dynamic [`Estimator`] over a core one: a name, the estimate and its
//! covariance as `f64`s, diagnostics, and the stepping: the slot observations become the core
//! measurement ([`FromSlots`]), the core's [`CatchUp`](estimator_core::CatchUp) fills missed
//! instants ([`Fed`]) and, with `--gate P`, the core's [`Gated`] runs the innovation gate with
//! its lock-out rule (docs/gate.md). Nothing here re-implements a step.

use estimator_core::filter::{Gated, GatedStep, InnovationGate};
use estimator_core::{Error, LostMeasurement};
use estpipe_wire::Observation;

use super::fed::Fed;
use super::slots::FromSlots;
use crate::{CovarianceKind, Estimator};

/// An estimator's name and its name behind the gate (`<name>+gate`, so that no report can be
/// mistaken for the ungated estimator's), both fixed at compile time by [`name!`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Name {
    /// Without a gate.
    pub(crate) plain: &'static str,
    /// Behind the gate.
    pub(crate) gated: &'static str,
}

/// The [`Name`] of an estimator named by the literal `$n`.
macro_rules! name {
    ($n:literal) => {
        $crate::estimators::adapter::Name {
            plain: $n,
            gated: concat!($n, "+gate"),
        }
    };
}
pub(crate) use name;

/// Reports an estimator's per-step diagnostics (see [`Estimator::diagnostics`]).
pub(crate) type Diagnostics<E> = fn(&E, &mut dyn FnMut(&'static str, f64));

/// The gated step of a [`Fed`] estimator on an instant's observations, taken where `E`'s
/// bounds say it has one (an estimator without an innovation, such as `nn`, runs ungated).
type GatedFedStep<E> = fn(&mut Gated<f64, Fed<E>>, usize, &[Observation]) -> Result<(), Error>;

fn gated_fed_step<E, const NX: usize>(
    g: &mut Gated<f64, Fed<E>>,
    k: usize,
    obs: &[Observation],
) -> Result<(), Error>
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots + LostMeasurement,
{
    use estimator_core::Estimator as _;
    g.step(k, &E::Measurement::from_slots(obs))
}

/// How a [`Fed`] estimator steps: on its own, or behind the core's gate.
enum Stepping<E> {
    Plain(Fed<E>),
    Gated(Gated<f64, Fed<E>>, GatedFedStep<E>),
}

impl<E> Stepping<E> {
    fn fed(&self) -> &Fed<E> {
        match self {
            Self::Plain(f) => f,
            Self::Gated(g, _) => &g.estimator,
        }
    }
    fn fed_mut(&mut self) -> &mut Fed<E> {
        match self {
            Self::Plain(f) => f,
            Self::Gated(g, _) => &mut g.estimator,
        }
    }
}

/// A core estimator `E` on `NX` states under a name.
pub(crate) struct Adapted<E, const NX: usize> {
    name: Name,
    stepping: Stepping<E>,
    diagnostics: Diagnostics<E>,
    full_information: bool,
    cov_kind: CovarianceKind,
}

impl<E: estimator_core::Estimator<f64, NX>, const NX: usize> Adapted<E, NX> {
    /// `fed` named `name`, reporting `trace_p`, the trace of the estimate's covariance.
    pub(crate) fn new(name: Name, fed: Fed<E>) -> Self {
        Self {
            name,
            stepping: Stepping::Plain(fed),
            diagnostics: trace_p,
            full_information: false,
            cov_kind: CovarianceKind::Estimate,
        }
    }

    /// The core estimate's covariance is a bound on the error covariance, the quantity the
    /// estimator's paper propagates (docs/design.md, The estimator API), not the covariance.
    pub(crate) fn with_covariance_bound(mut self) -> Self {
        self.cov_kind = CovarianceKind::Bound;
        self
    }

    /// Reports `diagnostics` instead of `trace_p`.
    pub(crate) fn with_diagnostics(mut self, diagnostics: Diagnostics<E>) -> Self {
        self.diagnostics = diagnostics;
        self
    }

    /// An oracle fed the observations before the channel ([`Estimator::full_information`]).
    pub(crate) fn with_full_information(mut self, full_information: bool) -> Self {
        self.full_information = full_information;
        self
    }

    /// The core estimator.
    fn core(&self) -> &E {
        &self.stepping.fed().estimator
    }
}

impl<E, const NX: usize> Adapted<E, NX>
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots + LostMeasurement,
{
    /// Behind the χ² innovation gate of probability `p` when `gate` is `Some(p)`, under its
    /// gated name (docs/gate.md); unchanged with `None`.
    pub(crate) fn with_gate(mut self, gate: Option<f64>) -> Result<Self, Error> {
        if let Some(p) = gate {
            let gate = InnovationGate::chi2(p)?;
            self.stepping = match self.stepping {
                Stepping::Plain(fed) => {
                    Stepping::Gated(Gated::new(fed, gate), gated_fed_step::<E, NX>)
                }
                gated @ Stepping::Gated(..) => gated,
            };
        }
        Ok(self)
    }
}

/// `p` row by row into `out[..NX·NX]`.
pub(crate) fn write_row_major<const NX: usize>(
    p: &nalgebra::SMatrix<f64, NX, NX>,
    out: &mut [f64],
) {
    for i in 0..NX {
        for j in 0..NX {
            out[i * NX + j] = p[(i, j)];
        }
    }
}

/// `trace_p`: the trace of the estimate's covariance.
fn trace_p<E: estimator_core::Estimator<f64, NX>, const NX: usize>(
    e: &E,
    sink: &mut dyn FnMut(&'static str, f64),
) {
    sink("trace_p", e.estimate().covariance().trace());
}

impl<E, const NX: usize> Estimator for Adapted<E, NX>
where
    E: estimator_core::Estimator<f64, NX> + Clone + Send,
    E::Measurement: FromSlots + LostMeasurement,
{
    fn name(&self) -> &'static str {
        match self.stepping {
            Stepping::Plain(_) => self.name.plain,
            Stepping::Gated(..) => self.name.gated,
        }
    }

    /// The estimator's step (behind its gate, with `--gate`). A refused step (a
    /// measurement whose update overflows, such as 1e300) is then taken as the instant's
    /// slot lost in transport, the prediction only, so that the estimator stays on time; the
    /// error is still returned, and counted by the commands. Nothing changes in a run without
    /// errors.
    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        use estimator_core::Estimator as _;
        let k = k as usize;
        let done = match &mut self.stepping {
            Stepping::Plain(f) => f.step(k, &E::Measurement::from_slots(obs)),
            Stepping::Gated(g, step) => step(g, k, obs),
        };
        if let Err(e) = done {
            if !matches!(e, Error::OutOfOrder { .. }) {
                // Still an error if even the prediction fails: the state is then kept.
                let _ = self.stepping.fed_mut().step(k, &E::Measurement::lost());
            }
        }
        done
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..NX].copy_from_slice(self.core().estimate().state().as_slice());
    }

    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        write_row_major(self.core().estimate().covariance(), out);
        self.cov_kind
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        (self.diagnostics)(self.core(), sink);
        // Counts so far: eval's mean over runs at k = T times the valid runs is the total.
        if let Stepping::Gated(g, _) = &self.stepping {
            let s = g.state();
            sink("gate_tested", f64::from(s.counts.tested));
            sink("gate_rejected", f64::from(s.counts.rejected));
            sink("gate_forced", f64::from(s.forced));
        }
    }

    fn full_information(&self) -> bool {
        self.full_information
    }
}
