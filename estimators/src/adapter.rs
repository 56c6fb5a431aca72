//! The application's dynamic [`Estimator`] over a core one: a name, the estimate and its
//! covariance as `f64`s, diagnostics, and the stepping: the slot observations become the core
//! measurement ([`FromSlots`]), the core's [`CatchUp`](estimator_core::CatchUp) fills missed
//! instants ([`Fed`]), with `--gate P` the core's [`Gated`] runs the innovation gate with its
//! lock-out rule (docs/gate.md), and with `--lag L` the core's fixed-lag layer folds in late
//! slots ([`Lagged`], docs/pipeline.md "Late packets"). Nothing here re-implements a step.

use estimator_core::filter::{Gated, GatedStep, InnovationGate};
use estimator_core::{Error, LostMeasurement, Revise};
use estpipe_wire::Observation;

use super::fed::Fed;
use super::lagged::Lagged;
use super::slots::FromSlots;
use crate::{CovarianceKind, Estimator, LateFold};

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
        $crate::adapter::Name {
            plain: $n,
            gated: concat!($n, "+gate"),
        }
    };
}
pub(crate) use name;

/// Reports an estimator's per-step diagnostics (see [`Estimator::diagnostics`]).
pub(crate) type Diagnostics<E> = fn(&E, &mut dyn FnMut(&'static str, f64));

/// The measurement of a core estimator on `NX` states.
type Meas<E, const NX: usize> = <E as estimator_core::Estimator<f64, NX>>::Measurement;

/// A [`Fed`] estimator behind the core's gate, with or without its history.
type GatedFed<E, const NX: usize> = Lagged<Gated<f64, Fed<E>>, Meas<E, NX>>;

/// The gated estimator's step.
type GatedStepFn<E, const NX: usize> =
    fn(&mut GatedFed<E, NX>, usize, &Meas<E, NX>) -> Result<(), Error>;
/// The gated estimator's fold of a late part.
type GatedFoldFn<E, const NX: usize> = fn(&mut GatedFed<E, NX>, usize, &Meas<E, NX>) -> LateFold;

/// The gated estimator's step and fold, taken where `E`'s bounds say it has a gated step (an
/// estimator without an innovation, such as `nn`, runs ungated).
struct GatedOps<E, const NX: usize>
where
    E: estimator_core::Estimator<f64, NX>,
{
    step: GatedStepFn<E, NX>,
    fold: GatedFoldFn<E, NX>,
}

fn gated_step<E, const NX: usize>(
    g: &mut GatedFed<E, NX>,
    k: usize,
    y: &Meas<E, NX>,
) -> Result<(), Error>
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone,
{
    g.step(k, y)
}

fn gated_fold<E, const NX: usize>(g: &mut GatedFed<E, NX>, k: usize, y: &Meas<E, NX>) -> LateFold
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone,
{
    g.fold(k, y)
}

/// How a [`Fed`] estimator steps: on its own, or behind the core's gate; with the history of
/// `--lag` or without.
enum Stepping<E, const NX: usize>
where
    E: estimator_core::Estimator<f64, NX>,
{
    Plain(Lagged<Fed<E>, Meas<E, NX>>),
    Gated(GatedFed<E, NX>, GatedOps<E, NX>),
}

impl<E: estimator_core::Estimator<f64, NX>, const NX: usize> Stepping<E, NX> {
    fn fed(&self) -> &Fed<E> {
        match self {
            Self::Plain(f) => f.inner(),
            Self::Gated(g, _) => &g.inner().estimator,
        }
    }
}

/// A core estimator `E` on `NX` states under a name.
pub(crate) struct Adapted<E, const NX: usize>
where
    E: estimator_core::Estimator<f64, NX>,
{
    name: Name,
    stepping: Stepping<E, NX>,
    diagnostics: Diagnostics<E>,
    full_information: bool,
    cov_kind: CovarianceKind,
    nees: bool,
}

impl<E: estimator_core::Estimator<f64, NX>, const NX: usize> Adapted<E, NX> {
    /// `fed` named `name`, reporting `trace_p`, the trace of the estimate's covariance.
    pub(crate) fn new(name: Name, fed: Fed<E>) -> Self {
        Self {
            name,
            stepping: Stepping::Plain(Lagged::Off(fed)),
            diagnostics: trace_p,
            full_information: false,
            cov_kind: CovarianceKind::Estimate,
            nees: false,
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

    /// Reports `nees` = eᵀP⁻¹e against the truth and `inside_95` (the error inside the 95 %
    /// ellipse of P) in evaluation, as the Tobit views do: opt-in, so that the JSON of the
    /// estimators that never reported them stays as it was.
    pub(crate) fn with_nees(mut self) -> Self {
        self.nees = true;
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
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone,
{
    /// Behind the χ² innovation gate of probability `p` when `gate` is `Some(p)`, under its
    /// gated name (docs/gate.md); unchanged with `None`.
    pub(crate) fn with_gate(mut self, gate: Option<f64>) -> Result<Self, Error> {
        if let Some(p) = gate {
            let gate = InnovationGate::chi2(p)?;
            self.stepping = match self.stepping {
                Stepping::Plain(Lagged::Off(fed)) => Stepping::Gated(
                    Lagged::Off(Gated::new(fed, gate)),
                    GatedOps {
                        step: gated_step::<E, NX>,
                        fold: gated_fold::<E, NX>,
                    },
                ),
                other => other,
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
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone + Send,
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
        let k = k as usize;
        let y = E::Measurement::from_slots(obs);
        let done = match &mut self.stepping {
            Stepping::Plain(f) => f.step(k, &y),
            Stepping::Gated(g, ops) => (ops.step)(g, k, &y),
        };
        if let Err(e) = done {
            if !matches!(e, Error::OutOfOrder { .. }) {
                // Still an error if even the prediction fails: the state is then kept. With a
                // history the prediction is the recorded step (a re-step takes the same path).
                let lost = E::Measurement::lost();
                let _ = match &mut self.stepping {
                    Stepping::Plain(f) => f.step(k, &lost),
                    Stepping::Gated(Lagged::Off(g), _) => {
                        estimator_core::Estimator::step(&mut g.estimator, k, &lost)
                    }
                    Stepping::Gated(g, ops) => (ops.step)(g, k, &lost),
                };
            }
        }
        done
    }

    fn set_lag(&mut self, lag: u32) -> bool {
        match &mut self.stepping {
            Stepping::Plain(f) => f.set_lag(lag),
            Stepping::Gated(g, _) => g.set_lag(lag),
        }
        lag > 0
    }

    fn fold_late(&mut self, k: u32, obs: &[Observation]) -> LateFold {
        let (k, late) = (k as usize, E::Measurement::from_slots(obs));
        match &mut self.stepping {
            Stepping::Plain(f) => f.fold(k, &late),
            Stepping::Gated(g, ops) => (ops.fold)(g, k, &late),
        }
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
            let s = g.inner().state();
            sink("gate_tested", f64::from(s.counts.tested));
            sink("gate_rejected", f64::from(s.counts.rejected));
            sink("gate_forced", f64::from(s.forced));
        }
    }

    fn diagnostics_vs_truth(&self, truth: &[f64], sink: &mut dyn FnMut(&'static str, f64)) {
        if !self.nees || NX > super::tobit::CHI2_95.len() {
            return;
        }
        let (x, p) = self.core().estimate().into_parts();
        let e = nalgebra::SVector::<f64, NX>::from_column_slice(&truth[..NX]) - x;
        if let Ok(pe) = estimator_core::linalg::solve_spd(&p, &e, "covariance") {
            let nees = e.dot(&pe);
            sink("nees", nees);
            let inside = nees <= super::tobit::CHI2_95[NX - 1];
            sink("inside_95", f64::from(u8::from(inside)));
        }
    }

    fn full_information(&self) -> bool {
        self.full_information
    }
}
