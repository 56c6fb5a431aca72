//! Every estimator the firmware runs, each a core [`Estimator`](estimator_core::Estimator)
//! with what its digest records ([`Digested`](super::Digested)), and the `run_<name>` each
//! firmware binary calls: the seed 001 estimators over the occlusion stream, the seed 003 NN
//! estimator over the token-bucket stream, the seed 004 fusion filters and the centralised
//! moment-matched filter over the Tobit stream; and IKF and ADF under the fixed-lag layer over
//! the occlusion stream with late packets.

mod late;
mod nn;
mod occlusion;
mod tobit;
mod tobit_cmm;
mod tobit_silence;

pub use late::{run_adf_lag8_counts, run_ikf_lag8_counts, AdfOn, IkfOn};
pub use nn::{run_nn, Nn};
pub use occlusion::{run_adf, run_cce, run_ikf, run_kf, run_kf_io, Adf, Cce, Ikf, Kf, KfIo};
pub use tobit::{run_tobit, Fusion, Tobit};
pub use tobit_cmm::{run_tobit_cmm, Cmm, TobitCmm};
pub use tobit_silence::{paper_bucket, run_tobit_silence, TobitSilence};
