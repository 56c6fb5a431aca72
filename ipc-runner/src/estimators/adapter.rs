//! The application's dynamic [`Estimator`] over a core one: a name, the estimate and its
//! covariance as `f64`s, diagnostics, the stepping of [`Fed`] and, with `--gate P`, the
//! innovation gate (docs/gate.md).

use std::sync::Mutex;

use estimator_core::filter::gate::GateState;
use estimator_core::filter::{GateCounts, GatedStep, InnovationGate};
use estimator_core::Error;
use estpipe_wire::Observation;

use super::fed::Fed;
use super::slots::FromSlots;
use crate::{CovarianceKind, Estimator};

/// The gated step of a [`Fed`] estimator, with the estimator's measurement type erased.
type GatedFedStep<E> =
    fn(&mut Fed<E>, u32, &[Observation], &InnovationGate<f64>) -> Result<GateCounts, Error>;

/// An estimator's gate: the configuration, its step, and the counts of the run so far.
struct Gate<E> {
    gate: InnovationGate<f64>,
    step: GatedFedStep<E>,
    state: GateState,
}

fn gated_fed_step<E, const NX: usize>(
    fed: &mut Fed<E>,
    k: u32,
    obs: &[Observation],
    gate: &InnovationGate<f64>,
) -> Result<GateCounts, Error>
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots,
{
    fed.step_by::<NX>(k, obs, |e, k, y| e.step_gated(k, y, gate))
}

/// `name` with the suffix `+gate`, so that no report can be mistaken for the ungated
/// estimator's. Interned: the names are a small fixed set, each leaked once.
pub(crate) fn gated_name(name: &'static str) -> &'static str {
    static NAMES: Mutex<Vec<(&'static str, &'static str)>> = Mutex::new(Vec::new());
    let mut names = NAMES.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, g)) = names.iter().find(|(n, _)| *n == name) {
        return g;
    }
    let g: &'static str = Box::leak(format!("{name}+gate").into_boxed_str());
    names.push((name, g));
    g
}

/// Reports an estimator's per-step diagnostics (see [`Estimator::diagnostics`]).
pub(crate) type Diagnostics<E> = fn(&E, &mut dyn FnMut(&'static str, f64));

/// A core estimator `E` on `NX` states under a name.
pub(crate) struct Adapted<E, const NX: usize> {
    name: &'static str,
    fed: Fed<E>,
    diagnostics: Diagnostics<E>,
    full_information: bool,
    cov_kind: CovarianceKind,
    gate: Option<Gate<E>>,
}

impl<E: estimator_core::Estimator<f64, NX>, const NX: usize> Adapted<E, NX> {
    /// `fed` named `name`, reporting `trace_p`, the trace of the estimate's covariance.
    pub(crate) fn new(name: &'static str, fed: Fed<E>) -> Self {
        Self {
            name,
            fed,
            diagnostics: trace_p,
            full_information: false,
            cov_kind: CovarianceKind::Estimate,
            gate: None,
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
}

impl<E, const NX: usize> Adapted<E, NX>
where
    E: GatedStep<f64, NX> + Clone,
    E::Measurement: FromSlots,
{
    /// Behind the χ² innovation gate of probability `p` when `gate` is `Some(p)`, renamed
    /// `<name>+gate` (docs/gate.md); unchanged with `None`.
    pub(crate) fn with_gate(mut self, gate: Option<f64>) -> Result<Self, Error> {
        if let Some(p) = gate {
            self.gate = Some(Gate {
                gate: InnovationGate::chi2(p)?,
                step: gated_fed_step::<E, NX>,
                state: GateState::default(),
            });
            self.name = gated_name(self.name);
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
    E::Measurement: FromSlots,
{
    fn name(&self) -> &'static str {
        self.name
    }

    /// The estimator's step (behind its gate, with `--gate`). A refused step (a
    /// measurement whose update overflows, such as 1e300) is then taken as the instant's
    /// slot lost in transport, the prediction only, so that the estimator stays on time (it
    /// used to keep x̂_{k−1} and predict one instant short from there); the error is still
    /// returned, and counted by the commands. Nothing changes in a run without errors.
    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        let done = match &mut self.gate {
            None => self.fed.step::<NX>(k, obs),
            Some(g) => {
                let gate = g.state.gate_for_next(&g.gate);
                (g.step)(&mut self.fed, k, obs, &gate).map(|c| g.state.record(c, &gate))
            }
        };
        if let Err(e) = done {
            if !matches!(e, Error::OutOfOrder { .. }) {
                // Still an error if even the prediction fails: the state is then kept.
                let _ = self.fed.step::<NX>(k, &[]);
            }
        }
        done
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..NX].copy_from_slice(self.fed.get().estimate().state().as_slice());
    }

    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        write_row_major(self.fed.get().estimate().covariance(), out);
        self.cov_kind
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        (self.diagnostics)(self.fed.get(), sink);
        // Counts so far: eval's mean over runs at k = T times the valid runs is the total.
        if let Some(g) = &self.gate {
            sink("gate_tested", f64::from(g.state.counts.tested));
            sink("gate_rejected", f64::from(g.state.counts.rejected));
            sink("gate_forced", f64::from(g.state.forced));
        }
    }

    fn full_information(&self) -> bool {
        self.full_information
    }
}
