//! The target-independent half of the firmware: the embedded measurement streams, the models
//! they were simulated from, and one generic driver ([`drive`]) that runs any core estimator
//! ([`estimator_core::Estimator`]) in `f32` over a stream and digests every estimate.
//!
//! The same source is compiled into the firmware (Cortex-M4F) and into the host check
//! (`tests/firmware_qemu.rs`, through `#[path]` on this file), so the two sides run the same
//! source over the same bytes; the check is that their results agree bit for bit.
//!
//! No `unsafe`, no allocation, no panics on the stream's content: a malformed stream is a
//! [`StreamError`], an estimator error is counted in [`Summary::errors`]. No floating-point
//! function of `std` is called (on the host it would be the platform's libm, on the target
//! there is none): transcendental functions go through nalgebra's `ComplexField`, which
//! `estimator-core`'s `libm-force` routes to the `libm` crate on both sides.
//!
//! Modules, each importing only from those above it:
//! - `digest`: FNV-1a 64 over bytes and estimates;
//! - `summary`: what a run reports (the `RESULT` line);
//! - `mark`: the step marker, through which the instruction-count plugin counts single steps;
//! - `drive`: the stream's [`Instant`], what its node slots become for an estimator
//!   ([`FromNodes`]), what the digest records of one ([`Digested`]) and the one driver
//!   [`drive`];
//! - `lag`: the driver under the core's fixed-lag layer ([`drive_lag`]), with packets made
//!   late by a fixed pattern ([`lateness`]) and folded in when they arrive;
//! - `vectors`: the embedded vector files, their format and parsers;
//! - `models`: the `f32` models of seeds 001 and 004;
//! - `drivers`: every estimator (mostly a core filter paired with its model in an
//!   [`estimator_core::OnModel`]) and its `run_<name>`.
//!
//! Everything public is re-exported here, so users name it `run::…`.
#![forbid(unsafe_code)]

mod digest;
mod drive;
mod drivers;
mod lag;
pub mod mark;
mod models;
mod summary;
mod vectors;

pub use digest::{fnv1a64, Fnv1a64};
pub use drive::{drive, Digested, FromNodes, Instant};
pub use drivers::{
    paper_bucket, run_adf, run_cce, run_ikf, run_kf, run_kf_io, run_nn, run_tobit, run_tobit_cmm,
    run_tobit_silence, Adf, Cce, Cmm, Fusion, Ikf, Kf, KfIo, Nn, Tobit, TobitCmm, TobitSilence,
};
pub use drivers::{run_adf_lag8_counts, run_ikf_lag8_counts, AdfOn, IkfOn};
pub use lag::{drive_lag, lateness, LateLine, LAG};
pub use models::{
    model, occlusion, prior, Model, TobitModel, TOBIT_CHI, TOBIT_ETA0, TOBIT_LAMBDA, TOBIT_SIGMA,
};
pub use summary::{Summary, MAX_NX};
pub use vectors::{
    Link, NodeRecord, NodeStream, Record, Slot, Source, Stream, StreamError, Vectors,
    FORMAT_VERSION, HEADER_LEN, MAGIC, NN, NODES, NODE_FORMAT_VERSION, NODE_HEADER_LEN,
    NODE_RECORD_LEN, NX, NY, OCCLUSION, RECORD_LEN, SLOT_LEN, TOBIT, TOBIT_NX,
};
