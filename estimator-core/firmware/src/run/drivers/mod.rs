//! One [`Driven`](super::Driven) per estimator, with the `run_<name>` each firmware binary
//! calls: the seed 001 estimators over the occlusion stream, the seed 003 NN estimator over the
//! token-bucket stream, the seed 004 fusion filter over the Tobit stream.

mod nn;
mod occlusion;
mod tobit;

pub use nn::{run_nn, Nn};
pub use occlusion::{
    run_adf, run_cce, run_ikf, run_kf, run_kf_io, Adf, Cce, KfIoF32, OcclusionEstimator, OnModel,
};
pub use tobit::{run_tobit, Fusion, Tobit};
