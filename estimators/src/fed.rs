//! A core estimator as the application feeds it: the core's [`CatchUp`] (instants that never
//! reached the runner are stepped as lost, on a copy committed only when every step succeeds)
//! with the hook that brings a controlled model's input term to each instant.

use std::sync::Arc;

use estimator_core::catch_up::Remodel as CoreRemodel;
use estimator_core::{CatchUp, Error};
use estpipe_spec::{EstimatorSpec, LinearModel};

/// Brings an estimator's model to instant `k` (writes the input term in place).
pub(crate) type Remodel<E> = fn(&mut E, &LinearModel, usize);

/// The hook of a [`Fed`] estimator: for a controlled model, the spec and how to write its input
/// term of instant `k` into the estimator's model; nothing for a constant model.
pub(crate) struct ModelHook<E> {
    varying: Option<(Arc<EstimatorSpec>, Remodel<E>)>,
}

// Not derived: that would ask `E: Clone`, and the hook holds only a spec and a function.
impl<E> Clone for ModelHook<E> {
    fn clone(&self) -> Self {
        Self {
            varying: self.varying.clone(),
        }
    }
}

impl<E> CoreRemodel<E> for ModelHook<E> {
    fn remodel(&mut self, e: &mut E, k: usize) -> Result<(), Error> {
        if let Some((spec, remodel)) = &self.varying {
            remodel(e, linear(spec)?, k);
        }
        Ok(())
    }
}

/// A core estimator `E` that catches up on missed instants, with its model's hook.
pub(crate) type Fed<E> = CatchUp<E, ModelHook<E>>;

/// An estimator whose model does not change (or is not the spec's linear model).
pub(crate) fn fixed<E>(est: E) -> Fed<E> {
    CatchUp::new(est).with_remodel(ModelHook { varying: None })
}

/// An estimator on the linear model of `spec`, its model built for instant 1: `remodel` runs
/// before every step only when the model has a control input.
pub(crate) fn on_model<E>(est: E, spec: &Arc<EstimatorSpec>, remodel: Remodel<E>) -> Fed<E> {
    let varying = spec
        .linear()
        .is_some_and(|m| !m.time_invariant())
        .then(|| (Arc::clone(spec), remodel));
    CatchUp::new(est).with_remodel(ModelHook { varying })
}

/// The spec's linear model, or the error every linear adapter reports without one.
pub(crate) fn linear(spec: &EstimatorSpec) -> Result<&LinearModel, Error> {
    spec.linear().ok_or(Error::InvalidConfig {
        field: "model",
        reason: "has no linear description",
    })
}
