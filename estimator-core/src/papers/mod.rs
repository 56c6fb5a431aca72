//! The papers' numerical examples as ready-made values, so that tests, benchmarks, firmware
//! and users start from the same numbers. One file per paper (docs/design.md has a section
//! for each):
//!
//! * [`seed001`]: [`Seed001Example`], the occlusion example (model, regions, prior);
//! * [`seed003`]: [`Seed003Example`], the noise-coupled system and its nonlinearity; the NN
//!   estimator on it, [`Seed003Nn`] with [`Seed003Nn::seed003`]; the bounds' configuration
//!   [`NnBoundConfig::seed003_example`](crate::filter::nn::NnBoundConfig::seed003_example);
//! * [`seed004`]: the scalars of Theorem 1,
//!   [`BoundScalars::paper_example`](crate::filter::tobit::BoundScalars::paper_example).
//!
//! The configurations' example values are associated functions of the configuration types,
//! defined here so that every example number lives in this module.

pub mod seed001;
pub mod seed003;
pub mod seed004;

pub use seed001::Seed001Example;
pub use seed003::{Seed003Example, Seed003Nn};
