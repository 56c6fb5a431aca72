//! What the slot observations of one instant ([`Observation`], one per node) become
//! for a core estimator: its [`Estimator::Measurement`](estimator_core::Estimator::Measurement),
//! a [`Packet`] or one per node.
//!
//! A packet is in one of three states (docs/design.md, "The estimator API": a loss is not a
//! dropout):
//!
//! * delivered: [`Packet::Delivered`];
//! * dropped by the channel (occlusion, event trigger, token bucket, a random-loss stage of the
//!   channel): [`Packet::Dropped`], which may carry information;
//! * never received — a slot lost inside the IPC, missed before the runner joined the stream,
//!   a row flagged lost in a slot log, a slot lost by `eval --transport-loss`, all marked
//!   [`FLAG_IPC_LOST`](estpipe_wire::FLAG_IPC_LOST), a slot a bridge wrote for what the
//!   network lost ([`FLAG_NET_LOST`](estpipe_wire::FLAG_NET_LOST), docs/bridge.md), and a node
//!   or instant the runner has no observation of at all:
//!   [`Packet::Lost`], which carries none.

use estimator_core::filter::silence::TriggeredPackets;
use estimator_core::Packet;
use estpipe_wire::Observation;
use estpipe_wire::FLAGS_LOST;
use nalgebra::SVector;

/// A core measurement read from the observations of one instant.
pub(crate) trait FromSlots {
    /// The measurement of the instant whose observations are `obs` (in node order); with no
    /// observation at all (an instant that never reached the runner), every node's packet is
    /// lost.
    fn from_slots(obs: &[Observation]) -> Self;
}

/// One node's observation as a packet. A node that measures fewer than `NY` components
/// (sensors of different ny, the estimator sized for the largest) is padded with zeros,
/// which its padded model (`snapshot`) never reads as information; a longer one cannot
/// reach here (the assembler and the simulation give each node its own ny) and is cut.
pub(crate) fn packet<const NY: usize>(o: &Observation) -> Packet<f64, NY> {
    match o.measurement() {
        Some(y) => {
            let mut v = SVector::<f64, NY>::zeros();
            let n = y.len().min(NY);
            v.as_mut_slice()[..n].copy_from_slice(&y[..n]);
            Packet::Delivered(v)
        }
        None if o.flags & FLAGS_LOST != 0 => Packet::Lost,
        None => Packet::Dropped,
    }
}

/// A single-node estimator's packet: node 0's; an instant without any observation is lost.
impl<const NY: usize> FromSlots for Packet<f64, NY> {
    fn from_slots(obs: &[Observation]) -> Self {
        obs.first().map_or(Packet::Lost, packet)
    }
}

/// Every node's packet at its node index; a node without an observation is lost, an
/// observation from a node past `L` is not read.
impl<const NY: usize, const L: usize> FromSlots for [Packet<f64, NY>; L] {
    fn from_slots(obs: &[Observation]) -> Self {
        let mut y = [Packet::Lost; L];
        for o in obs {
            if let Some(slot) = y.get_mut(usize::from(o.node)) {
                *slot = packet(o);
            }
        }
        y
    }
}

/// Every node's packet and the bucket level the instant's first delivered packet reported
/// (docs/wire.md, "The bucket level on a delivered packet").
impl<const NY: usize, const L: usize> FromSlots for TriggeredPackets<f64, NY, L> {
    fn from_slots(obs: &[Observation]) -> Self {
        let level = obs
            .iter()
            .filter(|o| usize::from(o.node) < L && o.measurement().is_some())
            .find_map(|o| o.tokens);
        Self {
            packets: FromSlots::from_slots(obs),
            level,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use estpipe_wire::{FLAG_IPC_LOST, FLAG_NET_LOST};
    use estpipe_wire::{FLAG_OCCLUDED, FLAG_RANDOM_LOSS};

    #[test]
    fn delivered_dropped_and_lost() {
        let mut y = Observation::dropped(3, 0, 2, 0);
        y.delivered = true;
        y.y[..2].copy_from_slice(&[1.5, -2.0]);
        assert_eq!(
            packet::<2>(&y),
            Packet::Delivered(SVector::from([1.5, -2.0]))
        );
        for flags in [0, FLAG_OCCLUDED, FLAG_RANDOM_LOSS] {
            assert_eq!(
                packet::<2>(&Observation::dropped(3, 0, 2, flags)),
                Packet::Dropped
            );
        }
        let lost = Observation::dropped(3, 1, 2, FLAG_IPC_LOST);
        assert_eq!(packet::<2>(&lost), Packet::Lost);
        let net = Observation::dropped(3, 1, 2, FLAG_NET_LOST);
        assert_eq!(packet::<2>(&net), Packet::Lost);
        assert_eq!(<Packet<f64, 2>>::from_slots(&[]), Packet::Lost);
        assert_eq!(<Packet<f64, 2>>::from_slots(&[lost, y]), Packet::Lost);
        // Node 2 sent nothing; node 1's slot was lost; node 0's arrived.
        assert_eq!(
            <[Packet<f64, 2>; 3]>::from_slots(&[y, lost]),
            [packet(&y), Packet::Lost, Packet::Lost]
        );
    }
}
