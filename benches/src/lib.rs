//! Shared problem definitions and step kernels for the benchmarks.
//!
//! The criterion benches (`benches/*.rs`) and the instruction-count binary (`bin/icount.rs`)
//! run exactly the kernels defined here, so a wall-clock median and an instruction count of
//! the same name measure the same code on the same data.
//!
//! Every kernel computes one step from a fixed, converged prior (the steady state of the
//! problem), so every iteration does identical work: no drift of the state, no change of
//! branch pattern, and our filter and `adskalman` see bit-for-bit the same inputs.

pub mod ads;
pub mod compare;
pub mod estimators;
pub mod late;
pub mod problems;
pub mod view_tap;
