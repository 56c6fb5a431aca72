//! Silence updates: what an estimator learns from a node whose event trigger held
//! (docs/tobit-fusion.md, "Silence that speaks").
//!
//! A node that did not fire although it had a token has its measurement inside the trigger's
//! silence set, the ball `‖y − ȳ‖ < r̄` of [`crate::protocol::trigger_knowledge`] (with the
//! receiver's largest possible threshold `r̄`). Two ways to use that set, both from the
//! event-based estimation literature:
//!
//! * **Pseudo-measurement** (Sijs & Lazar 2012): the set as a uniform distribution, read as
//!   the measurement ȳ (its centre) with the noise `R + Σ_set`, `Σ_set` the set's covariance
//!   ([`set::uniform_moments`]).
//! * **Moment-matched truncated Gaussian** (Wu, Jia, Johansson & Shi 2013): the prior of the
//!   (uncensored) measurement `z = C x + v`, `N(C x̂⁻, C P⁻ Cᵀ + R)`, restricted to the set's
//!   box of per-axis bounds ([`set::SilenceBox`]), and x̂, P its first two moments
//!   ([`truncated::truncate_box`]).
//!
//! Where the node's measurement is also Tobit-censored (seed 004, eq. 2), the set is
//! intersected with the censoring region: `y = max(z, τ)` lies in the ball, so an axis whose
//! ball reaches τ is open below in `z` (every `z_j ≤ τ_j` reads `y_j = τ_j`, inside the set).
//!
//! [`kalman`] is the linear Kalman filter behind an event-triggered channel with these
//! updates; the Tobit filters use them through [`crate::filter::tobit::Silence`].

pub mod kalman;
pub mod set;
pub mod truncated;

use nalgebra::SVector;

use crate::catch_up::LostMeasurement;
use crate::fixed_lag::Revise;
use crate::packet::Packet;
use crate::protocol::bucket_mirror::Sent;
use crate::Real;

/// What one node's packet of an instant is to a silence-reading estimator: the packet and,
/// for a silence, what the bucket mirror ([`crate::protocol::bucket_mirror`]) says of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Arrival<'a, T: Real, const NY: usize> {
    /// The measurement arrived.
    Received(&'a SVector<T, NY>),
    /// Nothing arrived although the node had a token: its trigger held.
    Held,
    /// Nothing arrived and the node may have been refused a token (or the mirror does not
    /// know): no information, but the reference did not change.
    Blocked,
    /// Lost in transport: no information, and the node's reference may have changed.
    Lost,
}

/// Which silence update.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SilenceForm {
    /// Sijs–Lazar: the set's centre with `R + Σ_set`.
    PseudoMeasurement,
    /// The moment-matched truncated Gaussian on the set's box.
    TruncatedGaussian,
}

/// Every node's packet of an instant and the bucket level a delivered packet reported
/// (wire version 6's `tokens`; `None` when no packet reported one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggeredPackets<T: Real, const NY: usize, const L: usize> {
    /// Node m's packet.
    pub packets: [Packet<T, NY>; L],
    /// ξ_{t−1} as reported by a delivered packet of this instant.
    pub level: Option<u32>,
}

impl<T: Real, const NY: usize, const L: usize> LostMeasurement for TriggeredPackets<T, NY, L> {
    #[inline]
    fn lost() -> Self {
        Self {
            packets: [Packet::Lost; L],
            level: None,
        }
    }
}

/// A late packet revises its node's lost packet (the rule of [`crate::fixed_lag`]) and brings
/// the level it reported when the instant had none: every grant of an instant uses the same
/// ξ_{t−1} (docs/wire.md, "The bucket level on a delivered packet"), so the refolded instant
/// is the one an on-time arrival would have given.
impl<T: Real, const NY: usize, const L: usize> Revise for TriggeredPackets<T, NY, L> {
    #[inline]
    fn revise(&mut self, late: &Self) -> usize {
        let changed = self.packets.revise(&late.packets);
        if changed > 0 && self.level.is_none() {
            self.level = late.level;
        }
        changed
    }
}

impl<T: Real, const NY: usize, const L: usize> TriggeredPackets<T, NY, L> {
    /// What the bucket mirror reads from the packets.
    #[must_use]
    pub fn sent(&self) -> [Sent; L] {
        self.packets.map(|p| match p {
            Packet::Delivered(_) => Sent::Yes,
            Packet::Dropped => Sent::No,
            Packet::Lost => Sent::Unknown,
        })
    }

    /// The arrivals the mirror's verdict `held` makes of the packets.
    #[must_use]
    pub fn arrivals(&self, held: &[bool; L]) -> [Arrival<'_, T, NY>; L] {
        core::array::from_fn(|m| match &self.packets[m] {
            Packet::Delivered(y) => Arrival::Received(y),
            Packet::Dropped if held[m] => Arrival::Held,
            Packet::Dropped => Arrival::Blocked,
            Packet::Lost => Arrival::Lost,
        })
    }
}

/// How many silences were read as held, and how many of those had no usable set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SilenceCounts {
    /// Silences updated with the set.
    pub held: u32,
    /// Silences without a token (or with the mirror unknown): predicted only.
    pub blocked: u32,
    /// Held silences without a usable set (reference unknown after a loss, or r̄ ≤ 0).
    pub unusable: u32,
}
