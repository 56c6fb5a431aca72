//! A core estimator ([`estimator_core::Estimator`]) as the application feeds it: instant `k`
//! with the slot observations of `k`, converted by [`FromSlots`], and the model's input term
//! of `k` when the model has a control input. Instants that never reached the runner are
//! stepped as lost.

use std::sync::Arc;

use estimator_core::filter::GateCounts;
use estimator_core::{Error, Estimator};
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::Observation;

use super::slots::FromSlots;

/// Brings an estimator's model to instant `k` (writes the input term in place).
pub(crate) type Remodel<E> = fn(&mut E, &LinearModel, usize);

/// A core estimator `E`, and for a controlled model how to bring its model to instant `k`.
pub(crate) struct Fed<E> {
    est: E,
    varying: Option<(Arc<EstimatorSpec>, Remodel<E>)>,
}

impl<E> Fed<E> {
    /// An estimator whose model does not change (or is not the plant's).
    pub(crate) fn fixed(est: E) -> Self {
        Self { est, varying: None }
    }

    /// An estimator on the linear model of `spec`, its model built for instant 1: `remodel`
    /// runs before every step only when the model has a control input.
    pub(crate) fn on_model(est: E, spec: &Arc<EstimatorSpec>, remodel: Remodel<E>) -> Self {
        let varying = spec
            .linear()
            .is_some_and(|m| !m.time_invariant())
            .then(|| (Arc::clone(spec), remodel));
        Self { est, varying }
    }

    /// The estimator.
    pub(crate) fn get(&self) -> &E {
        &self.est
    }

    /// Instant `k` with the observations `obs`. An estimator that counts its own instants
    /// refuses a `k` past its next one ([`Error::OutOfOrder`]): the instants between never
    /// reached the runner, and are stepped first as instants without any observation (every
    /// packet [`Packet::Lost`](estimator_core::Packet::Lost), see `slots`). On error the
    /// estimator keeps its previous state, gap instants included.
    pub(crate) fn step<const NX: usize>(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error>
    where
        E: Estimator<f64, NX> + Clone,
        E::Measurement: FromSlots,
    {
        self.step_by::<NX>(k, obs, |e, k, y| e.step(k, y).map(|()| GateCounts::NONE))
            .map(|_| ())
    }

    /// [`Fed::step`] with `step` stepping instant `k` itself (the gated step,
    /// [`GatedStep::step_gated`](estimator_core::filter::GatedStep::step_gated)): the gap
    /// instants carry no measurement and take the plain step. Returns what the gate counted
    /// at `k`.
    pub(crate) fn step_by<const NX: usize>(
        &mut self,
        k: u32,
        obs: &[Observation],
        step: impl Fn(&mut E, usize, &E::Measurement) -> Result<GateCounts, Error>,
    ) -> Result<GateCounts, Error>
    where
        E: Estimator<f64, NX> + Clone,
        E::Measurement: FromSlots,
    {
        if let Some((spec, remodel)) = &self.varying {
            remodel(&mut self.est, linear(spec)?, k as usize);
        }
        let y = E::Measurement::from_slots(obs);
        match step(&mut self.est, k as usize, &y) {
            Err(Error::OutOfOrder { expected, got }) if got > expected => {
                let (mut est, gap) = (self.est.clone(), E::Measurement::from_slots(&[]));
                for j in expected..got {
                    // Each gap instant on its own model (a time-varying plant, a control
                    // input's u_{j−1}).
                    if let Some((spec, remodel)) = &self.varying {
                        remodel(&mut est, linear(spec)?, j);
                    }
                    est.step(j, &gap)?;
                }
                if let Some((spec, remodel)) = &self.varying {
                    remodel(&mut est, linear(spec)?, got);
                }
                let counts = step(&mut est, got, &y)?;
                self.est = est;
                Ok(counts)
            }
            done => done,
        }
    }
}

/// The spec's linear model, or the error every linear adapter reports without one.
pub(crate) fn linear(spec: &EstimatorSpec) -> Result<&LinearModel, Error> {
    spec.linear().ok_or(Error::InvalidConfig {
        field: "model",
        reason: "has no linear description",
    })
}
