//! Instants that never reached the estimator: stepped as lost before the instant that did.
//!
//! An estimator that counts its own instants (the seed 003 filters) refuses a step for any
//! `k` but its next one with [`Error::OutOfOrder`] `{ expected, got }`. When `got > expected`
//! the instants `expected..got` were never received (a sequence gap, a dead link): nothing
//! is known of them, so each is stepped with a [`LostMeasurement`] (docs/design.md, "A loss is
//! not a dropout"), then `got` itself — on a copy of the estimator, committed only if every
//! step succeeds, so that on error the estimator keeps its state.
//!
//! [`catch_up`] does this around any step (plain or gated); [`CatchUp`] is an estimator with
//! it built in, and a [`GatedStep`] one when the estimator is (the gaps carry no measurement
//! and take the plain step). A time-varying model is brought to each instant by a
//! [`Remodel`] hook, called before the instant's step: on the estimator itself before the
//! first attempt at `k`, then on the copy before every gap instant and before `got`.

use crate::estimate::Estimate;
use crate::estimator::Estimator;
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// A measurement that can say "nothing arrived at this instant".
pub trait LostMeasurement {
    /// The measurement of an instant whose packets were all lost in transport.
    fn lost() -> Self;
}

impl<T: Real, const NY: usize> LostMeasurement for Packet<T, NY> {
    #[inline]
    fn lost() -> Self {
        Packet::Lost
    }
}

/// Every node's packet lost.
impl<M: LostMeasurement, const L: usize> LostMeasurement for [M; L] {
    #[inline]
    fn lost() -> Self {
        core::array::from_fn(|_| M::lost())
    }
}

/// Brings an estimator `E`'s model to instant `k` before it steps `k` (a time-varying plant,
/// a known control input of `k − 1`). Closures `FnMut(&mut E, usize) -> Result<()>` are
/// hooks; [`Fixed`] is the hook of a model that does not change.
pub trait Remodel<E> {
    /// `e`'s model at instant `k`. An error stops the step (the estimator keeps its state).
    fn remodel(&mut self, e: &mut E, k: usize) -> Result<()>;
}

impl<E, F: FnMut(&mut E, usize) -> Result<()>> Remodel<E> for F {
    #[inline]
    fn remodel(&mut self, e: &mut E, k: usize) -> Result<()> {
        self(e, k)
    }
}

/// The [`Remodel`] hook of a model that does not change: does nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fixed;

impl<E> Remodel<E> for Fixed {
    #[inline]
    fn remodel(&mut self, _e: &mut E, _k: usize) -> Result<()> {
        Ok(())
    }
}

/// Instant `k` with `y` by `step` (the plain or the gated step), the instants the estimator
/// never received stepped first as lost (module docs). `remodel` brings the model to each
/// instant before its step. Returns what `step` returned at `k`. On error `est` keeps its
/// state (its model is `k`'s if `remodel` ran).
pub fn catch_up<T, const NX: usize, E, H, O>(
    est: &mut E,
    k: usize,
    y: &E::Measurement,
    remodel: &mut H,
    mut step: impl FnMut(&mut E, usize, &E::Measurement) -> Result<O>,
) -> Result<O>
where
    T: Real,
    E: Estimator<T, NX> + Clone,
    E::Measurement: LostMeasurement,
    H: Remodel<E>,
{
    remodel.remodel(est, k)?;
    match step(est, k, y) {
        Err(Error::OutOfOrder { expected, got }) if got > expected => {
            let (mut copy, gap) = (est.clone(), E::Measurement::lost());
            for j in expected..got {
                remodel.remodel(&mut copy, j)?;
                copy.step(j, &gap)?;
            }
            remodel.remodel(&mut copy, got)?;
            let out = step(&mut copy, got, y)?;
            *est = copy;
            Ok(out)
        }
        done => done,
    }
}

/// An estimator `E` whose steps catch up on the instants it never received ([`catch_up`]),
/// with the hook `H` that brings its model to each instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CatchUp<E, H = Fixed> {
    /// The estimator.
    pub estimator: E,
    /// Its model's hook.
    pub remodel: H,
}

impl<E> CatchUp<E> {
    /// `estimator` on a model that does not change.
    #[inline]
    pub fn new(estimator: E) -> Self {
        Self {
            estimator,
            remodel: Fixed,
        }
    }
}

impl<E, H> CatchUp<E, H> {
    /// The same estimator with the hook `remodel`.
    #[inline]
    pub fn with_remodel<G: Remodel<E>>(self, remodel: G) -> CatchUp<E, G> {
        CatchUp {
            estimator: self.estimator,
            remodel,
        }
    }
}

impl<T: Real, const NX: usize, E, H> Estimator<T, NX> for CatchUp<E, H>
where
    E: Estimator<T, NX> + Clone,
    E::Measurement: LostMeasurement,
    H: Remodel<E>,
{
    type Measurement = E::Measurement;

    fn step(&mut self, k: usize, y: &E::Measurement) -> Result<()> {
        catch_up(&mut self.estimator, k, y, &mut self.remodel, |e, k, y| {
            e.step(k, y)
        })
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.estimator.estimate()
    }
}

/// The gated step at `k`, the plain step at the gap instants (they carry no measurement);
/// the counts are `k`'s.
impl<T: Real, const NX: usize, E, H> GatedStep<T, NX> for CatchUp<E, H>
where
    E: GatedStep<T, NX> + Clone,
    E::Measurement: LostMeasurement,
    H: Remodel<E>,
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &E::Measurement,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        catch_up(&mut self.estimator, k, y, &mut self.remodel, |e, k, y| {
            e.step_gated(k, y, gate)
        })
    }
}

#[cfg(test)]
mod tests;
