//! Seed 001: estimation when a packet drops exactly while the state lies in an occlusion
//! region, so that a dropout itself says where the state is.
//!
//! * [`cce`]: the paper's cross-coupled region-label / state estimator (Algorithms 1-2);
//! * [`adf`]: an assumed-density filter with the exact interval likelihood;
//! * [`kf_io`]: the linear MMSE baseline that treats arrival as a Bernoulli variable.
//!
//! All three are one [`OcclusionFilter`] ([`skeleton`]: predict, then the member's arrival or
//! dropout update, or prediction only for a packet lost in transport) with the member's
//! configuration ([`CceConfig`], [`AdfConfig`], [`KfIoConfig`]).
//!
//! The occlusion model is [`crate::protocol::occlusion`], the example
//! [`crate::papers::Seed001Example`].

pub mod adf;
pub mod cce;
pub mod kf_io;
pub mod skeleton;
pub(crate) mod truncnorm;

pub use adf::{AdfConfig, AdfState, AssumedDensityFilter};
pub use cce::{CceConfig, CceState, CrossCoupledEstimator};
pub use kf_io::{KfIo, KfIoConfig};
pub use skeleton::{OcclusionFilter, OcclusionUpdate};
