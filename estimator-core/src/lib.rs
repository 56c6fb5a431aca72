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
//! Features (off by default): `simd` runs the Kalman kernels of [`linalg::small`] on SIMD
//! lanes on x86-64 and AArch64 (`linalg::lanes`), bit-identical to the scalar ones.
//!
//! # Module map
//!
//! One concept per file, families in folders:
//!
//! * [`estimator`]: the [`Estimator`] trait every estimator implements, and [`OnModel`], which
//!   pairs a filter with its model; [`estimate`]: the [`Estimate`] `(x̂, P)` they hold;
//!   [`packet`]: the [`Packet`] an instant delivers (delivered, dropped, lost);
//!   [`catch_up`](mod@catch_up): instants that never arrived, stepped as lost; [`fixed_lag`]: packets that
//!   arrived late, folded into their instant by stepping again from it.
//! * [`filter`]: the estimators, by family — the Kalman filter and its intermittent variant,
//!   [`filter::occlusion`] (seed 001), [`filter::nn`] and [`filter::coupled_kf`] (seed 003),
//!   [`filter::tobit`] (seed 004).
//! * [`model`]: linear and time-varying models; [`protocol`]: the sensor-side communication
//!   protocols (token bucket, event trigger, censoring, occlusion regions).
//! * [`linalg`]: validated Cholesky solves, symmetrisation and the small kernels
//!   ([`linalg::small`], [`linalg::eig`], [`linalg::kron`]); [`gauss`]: normal pdf/cdf,
//!   tail-accurate inverse Mills ratio, log-sum-exp; [`gsum`]: Gaussian-sum tables;
//!   [`CovarianceUpdate`]: the Joseph or standard covariance form (chosen at run time, or at
//!   compile time through [`CovarianceForm`]).
//! * [`papers`]: the papers' numerical examples as ready-made values; [`floor`]: the
//!   operations one step of each estimator needs, counted from its equations (the floor the
//!   firmware's measured instructions are compared with).
//! * [`error`], [`real`]: the error type and the scalar trait.
//!
//! # One estimator interface
//!
//! Generic code is written once against [`Estimator`] and runs every estimator; here a
//! Kalman filter (every measurement delivered) and the cross-coupled estimator of seed 001
//! (whose dropouts say where the state is) on the paper's example:
//!
//! ```
//! use estimator_core::filter::{CrossCoupledEstimator, KalmanFilter};
//! use estimator_core::gsum::GaussSum;
//! use estimator_core::papers::Seed001Example;
//! use estimator_core::{Estimate, Estimator, OnModel, Packet, Result};
//! use nalgebra::vector;
//!
//! /// Runs an estimator over measurements of the instants 1, 2, ...
//! fn run<E: Estimator<f64, 3>>(e: &mut E, ys: &[E::Measurement]) -> Result<Estimate<f64, 3>> {
//!     for (k, y) in ys.iter().enumerate() {
//!         e.step(k + 1, y)?;
//!     }
//!     Ok(*e.estimate())
//! }
//!
//! let model = Seed001Example::model::<f64>()?;
//! let (x0, p0) = (Seed001Example::x0(), Seed001Example::p0());
//! let kf = KalmanFilter::new(x0, p0)?;
//! let gsum = GaussSum::<f64, 1, 15>::uniform()?;
//! let cce = CrossCoupledEstimator::new(x0, p0, Seed001Example::occlusion()?, &gsum)?;
//!
//! let ys = [vector![30.0, 10.0], vector![31.0, 11.0], vector![33.0, 9.0]];
//! let packets = [Packet::Delivered(ys[0]), Packet::Dropped, Packet::Delivered(ys[2])];
//! // On an arrival the cross-coupled estimator is the Kalman filter, bit for bit.
//! let a = run(&mut OnModel::new(&model, kf), &ys[..1])?;
//! let b = run(&mut OnModel::new(&model, cce), &packets[..1])?;
//! assert_eq!(a, b);
//! // The whole records: every measurement, and a dropout at k = 2.
//! let all = run(&mut OnModel::new(&model, kf), &ys)?;
//! let dropout = run(&mut OnModel::new(&model, cce), &packets)?;
//! assert_ne!(all.state(), dropout.state());
//! # Ok::<(), estimator_core::Error>(())
//! ```
//!
//! The filters also keep the "split" form, model passed at each call:
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
//! assert!((kf.estimate().state()[0] - 1.0).abs() < 0.2);
//! # Ok::<(), estimator_core::Error>(())
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod catch_up;
pub mod covariance_update;
pub mod error;
pub mod estimate;
pub mod estimator;
pub mod filter;
pub mod fixed_lag;
pub mod floor;
pub mod gauss;
pub mod gsum;
pub mod linalg;
pub mod model;
pub mod packet;
pub mod papers;
pub mod protocol;
pub mod real;

pub use catch_up::{catch_up, CatchUp, LostMeasurement};
pub use covariance_update::{CovarianceForm, CovarianceUpdate, JosephForm, StandardForm};
pub use error::{Error, Result};
pub use estimate::Estimate;
pub use estimator::{Estimator, OnModel};
pub use fixed_lag::{FixedLag, LagCounts, Revise, Revision};
pub use packet::Packet;
pub use real::Real;
