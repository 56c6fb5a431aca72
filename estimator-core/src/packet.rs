//! What reached an estimator at one instant.
//!
//! A missing measurement means different things depending on why it is missing. A channel
//! that *drops* a packet may say something by dropping it: an occlusion dropout says the state
//! is in an occlusion region (seed 001), a silent event trigger says the measurement is close
//! to the last one sent (seed 004), a withheld token-bucket packet says nothing about the
//! state but is known to the receiver (seed 003). A packet *lost* in transport says nothing at
//! all. Each estimator decides what a [`Packet`] means for it; the [`crate::estimator`] docs
//! list the choices.

use nalgebra::SVector;

use crate::{Error, Real, Result};

/// The measurement of one instant as it reached the estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Packet<T: Real, const NY: usize> {
    /// The measurement arrived.
    Delivered(SVector<T, NY>),
    /// The channel or the sender's protocol dropped it (occlusion, event trigger, token
    /// bucket): the dropout itself may carry information.
    Dropped,
    /// Lost in transport: no information about the state.
    Lost,
}

impl<T: Real, const NY: usize> Packet<T, NY> {
    /// The measurement if it was delivered.
    #[inline]
    pub fn delivered(&self) -> Option<&SVector<T, NY>> {
        match self {
            Packet::Delivered(y) => Some(y),
            Packet::Dropped | Packet::Lost => None,
        }
    }

    /// `true` for [`Packet::Lost`].
    #[inline]
    pub fn is_lost(&self) -> bool {
        matches!(self, Packet::Lost)
    }
}

impl<T: Real, const NY: usize> From<Option<SVector<T, NY>>> for Packet<T, NY> {
    /// `Some(y)` is delivered, `None` dropped (the two cases a channel without transport
    /// losses has).
    #[inline]
    fn from(y: Option<SVector<T, NY>>) -> Self {
        match y {
            Some(y) => Packet::Delivered(y),
            None => Packet::Dropped,
        }
    }
}

/// Validates the probability `p_loss` that a packet is lost in transport without the receiver
/// knowing (the occlusion estimators' `with_loss_rate`): finite and `0 ≤ p_loss < 1` (at 1
/// every packet is lost and no measurement ever arrives).
pub(crate) fn check_loss_rate<T: Real>(p: T) -> Result<T> {
    if !p.finite() || p < T::zero() || p >= T::one() {
        return Err(Error::InvalidConfig {
            field: "loss_rate",
            reason: "must be finite and in [0, 1)",
        });
    }
    Ok(p)
}
