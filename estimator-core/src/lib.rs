//! # estimator-core
//!
//! Allocation-free state estimators for systems observed over lossy or rationed networks,
//! written for microcontrollers and real-time hosts alike.
//!
//! * `#![no_std]`, no `alloc`, `#![forbid(unsafe_code)]`.
//! * Dimensions are const generics; every estimator is generic over the scalar ([`Real`]:
//!   `f32` or `f64`).
//! * Nothing panics on bad data: every step returns [`Result`], and on error the estimator's
//!   state is exactly what it was before the call.
//!
//! Features (off by default): `simd` runs the Kalman kernels of `linalg_small` on SIMD lanes
//! on x86-64 and AArch64 (`linalg_lanes`), bit-identical to the scalar ones.
//!
//! Module map (one concept per file): [`linalg`] (Cholesky solves, symmetrisation),
//! [`gauss`] (normal pdf/cdf, tail-accurate inverse Mills ratio, log-sum-exp), [`model`]
//! (linear and time-varying models), [`protocol`] (sensor-side communication protocols) and
//! [`filter`] (the estimators).
//!
//! ```
//! use estimator_core::{filter::KalmanFilter, model::LinearModel};
//! use nalgebra::{matrix, vector};
//!
//! // Scalar random walk observed in noise.
//! let model = LinearModel::<f64, 1, 1, 1, 1>::new(
//!     matrix![1.0], matrix![1.0], matrix![1.0], matrix![1.0], matrix![0.1], matrix![1.0],
//! )?;
//! let mut kf = KalmanFilter::new(vector![0.0], matrix![1.0])?;
//! for (k, y) in [0.9, 1.1, 1.0].into_iter().enumerate() {
//!     kf.predict(&model, k)?;
//!     kf.update(&model, k, &vector![y])?;
//! }
//! assert!((kf.state()[0] - 1.0).abs() < 0.2);
//! # Ok::<(), estimator_core::Error>(())
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod covariance_update;
pub mod error;
pub mod filter;
pub mod gauss;
pub mod gsum;
pub mod linalg;
pub mod model;
pub mod papers;
pub mod protocol;
pub mod real;

pub use covariance_update::CovarianceUpdate;
pub use error::{Error, Result};
pub use real::Real;
