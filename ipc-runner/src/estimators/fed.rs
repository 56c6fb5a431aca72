//! A core estimator ([`estimator_core::Estimator`]) as the application feeds it: instant `k`
//! with the slot observations of `k`, converted by [`FromSlots`], and the model of `k` when
//! the plant is time varying. Instants that never reached the runner are stepped as lost.

use std::sync::Arc;

use channel_sim::plant::{LinearDescription, Plant};
use channel_sim::Observation;
use estimator_core::filter::GateCounts;
use estimator_core::{Error, Estimator};

use super::slots::FromSlots;

/// Re-reads an estimator's model for instant `k` from the plant's linear description.
pub(crate) type Remodel<E> = fn(&mut E, &dyn LinearDescription, usize);

/// A core estimator `E`, and for a time-varying plant how to bring its model to instant `k`.
pub(crate) struct Fed<E> {
    est: E,
    varying: Option<(Arc<dyn Plant>, Remodel<E>)>,
}

impl<E> Fed<E> {
    /// An estimator whose model does not change (or is not the plant's).
    pub(crate) fn fixed(est: E) -> Self {
        Self { est, varying: None }
    }

    /// An estimator on `plant`, its model built for a time-invariant plant: `remodel` runs
    /// before every step only when the plant is time varying.
    pub(crate) fn on_plant(est: E, plant: Arc<dyn Plant>, remodel: Remodel<E>) -> Self {
        let varying = plant
            .linear()
            .is_some_and(|m| !m.time_invariant())
            .then_some((plant, remodel));
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
        if let Some((plant, remodel)) = &self.varying {
            remodel(&mut self.est, super::linear_of(&**plant)?, k as usize);
        }
        let y = E::Measurement::from_slots(obs);
        match step(&mut self.est, k as usize, &y) {
            Err(Error::OutOfOrder { expected, got }) if got > expected => {
                let (mut est, gap) = (self.est.clone(), E::Measurement::from_slots(&[]));
                for j in expected..got {
                    // Each gap instant on its own model (a time-varying plant, a control
                    // input's u_{j−1}).
                    if let Some((plant, remodel)) = &self.varying {
                        remodel(&mut est, super::linear_of(&**plant)?, j);
                    }
                    est.step(j, &gap)?;
                }
                if let Some((plant, remodel)) = &self.varying {
                    remodel(&mut est, super::linear_of(&**plant)?, got);
                }
                let counts = step(&mut est, got, &y)?;
                self.est = est;
                Ok(counts)
            }
            done => done,
        }
    }
}
