//! Seed 004: Tobit Kalman filtering of censored measurements under a dynamic event trigger
//! and a shared token bucket, one local filter per sensor node and their federated fusion.
//!
//! * [`config`]: what configures a local filter (ε and κ of Theorem 1, τ, Ξ, where Υ enters)
//!   and the measurement covariances it accepts;
//! * [`gain`]: the bound (30) as a quadratic in the gain and its minimiser (37);
//! * [`local`]: the local filter (21)-(23), (29)-(30) of one node;
//! * [`fusion`]: the federated fusion (50)-(51) of `L` local filters;
//! * [`mirrored`]: the fusion behind the receiver's bucket mirror, for the silence-reading
//!   local filters (the product's, docs/tobit-fusion.md "Silence that speaks");
//! * [`moment_matched`]: the product's centralised filter at the information bound — a
//!   covariance, exact moment matching of censored components ([`censored`]) and the held
//!   silences (docs/tobit-fusion.md "At the information bound");
//! * [`tobit_kf`]: the Tobit Kalman filter of Allik et al. (2016), the practitioner's baseline.
//!
//! The section 4 example's scalars are [`BoundScalars::paper_example`], defined with the other
//! papers' examples in [`crate::papers`].

pub mod censored;
pub mod config;
pub mod fusion;
pub mod gain;
pub mod local;
pub mod mirrored;
pub mod moment_matched;
pub mod tobit_kf;

pub use config::{
    diagonal_variances, BoundScalars, Kappas, Silence, TobitFilterConfig, UpsilonPlacement,
};
pub use fusion::{federated_fuse, TobitFusion};
pub use gain::GainProblem;
pub use local::{LocalStepPlan, TobitFilter};
pub use mirrored::MirroredFusion;
pub use moment_matched::MomentMatchedTobit;
pub use tobit_kf::TobitKf;
