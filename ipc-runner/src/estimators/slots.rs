//! What the slot observations of one instant (`channel_sim::Observation`, one per node) become
//! for a core estimator: its [`Estimator::Measurement`](estimator_core::Estimator::Measurement),
//! a [`Packet`] or one per node.
//!
//! A packet the channel dropped is [`Packet::Dropped`]. So, for now, is a slot lost inside the
//! IPC (`FLAG_IPC_LOST`): the estimators have always been fed it as a dropout, and a lost slot
//! says less than a dropout does, which [`Packet::Lost`] will carry once the estimators'
//! results may change with it.

use channel_sim::Observation;
use estimator_core::Packet;
use nalgebra::SVector;

/// A core measurement read from the observations of one instant.
pub(crate) trait FromSlots {
    /// The measurement of the instant whose observations are `obs` (in node order); with no
    /// observation at all, every node's packet is a dropout.
    fn from_slots(obs: &[Observation]) -> Self;
}

/// One node's observation as a packet.
pub(crate) fn packet<const NY: usize>(o: &Observation) -> Packet<f64, NY> {
    match o.measurement() {
        Some(y) => Packet::Delivered(SVector::from_column_slice(y)),
        None => Packet::Dropped,
    }
}

/// A single-node estimator's packet: node 0's; an instant without any observation is a dropout.
impl<const NY: usize> FromSlots for Packet<f64, NY> {
    fn from_slots(obs: &[Observation]) -> Self {
        obs.first().map_or(Packet::Dropped, packet)
    }
}

/// Every node's packet at its node index; a node without an observation is a dropout, an
/// observation from a node past `L` is not read.
impl<const NY: usize, const L: usize> FromSlots for [Packet<f64, NY>; L] {
    fn from_slots(obs: &[Observation]) -> Self {
        let mut y = [Packet::Dropped; L];
        for o in obs {
            if let Some(slot) = y.get_mut(usize::from(o.node)) {
                *slot = packet(o);
            }
        }
        y
    }
}
