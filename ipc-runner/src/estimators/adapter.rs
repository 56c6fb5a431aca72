//! The application's dynamic [`Estimator`] over a core one: a name, the estimate and its
//! covariance as `f64`s, diagnostics, and the stepping of [`Fed`].

use estimator_core::Error;

use super::fed::Fed;
use super::slots::FromSlots;
use crate::{CovarianceKind, Estimator};

/// Reports an estimator's per-step diagnostics (see [`Estimator::diagnostics`]).
pub(crate) type Diagnostics<E> = fn(&E, &mut dyn FnMut(&'static str, f64));

/// A core estimator `E` on `NX` states under a name.
pub(crate) struct Adapted<E, const NX: usize> {
    name: &'static str,
    fed: Fed<E>,
    diagnostics: Diagnostics<E>,
    full_information: bool,
    cov_kind: CovarianceKind,
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

    fn step(&mut self, k: u32, obs: &[channel_sim::Observation]) -> Result<(), Error> {
        self.fed.step::<NX>(k, obs)
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
    }

    fn full_information(&self) -> bool {
        self.full_information
    }
}
