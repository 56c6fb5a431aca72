//! The eight timed steps of the KF comparison with `adskalman` (two problems × two covariance
//! forms × two libraries), each one monomorphic, non-inlined function.
//!
//! The criterion bench `kf_vs_adskalman`, the `icount` kernels and `kf_interleaved` all call
//! these, so the three measure the same machine code. Inlined into each harness's own loop,
//! the same source compiled differently per call site: `adskalman`'s 4x2 f32 step took
//! 661 instructions in `icount` and 799 in an interleaving harness, which would have biased
//! the interleaved ratio in our favour.

use crate::ads::{AdsProblem, AdsState};
use crate::problems::KfProblem;
use estimator_core::filter::KalmanFilter;
use estimator_core::Result;

/// Ours, Joseph form (the default), 3x2 f64.
#[inline(never)]
pub fn ours_joseph_3x2_f64(p: &KfProblem<f64, 3, 2>) -> Result<KalmanFilter<f64, 3>> {
    p.kf_step()
}
/// `adskalman`, Joseph form, 3x2 f64.
#[inline(never)]
pub fn ads_joseph_3x2_f64(p: &AdsProblem<f64, 3, 2>) -> AdsState<f64, 3> {
    p.step()
}
/// Ours, optimal-gain form, 3x2 f64.
#[inline(never)]
pub fn ours_standard_3x2_f64(p: &KfProblem<f64, 3, 2>) -> Result<KalmanFilter<f64, 3>> {
    p.kf_standard_step()
}
/// `adskalman`, optimal-gain form made symmetric, 3x2 f64.
#[inline(never)]
pub fn ads_symmetric_3x2_f64(p: &AdsProblem<f64, 3, 2>) -> AdsState<f64, 3> {
    p.step_symmetric()
}
/// Ours, Joseph form, 4x2 f32.
#[inline(never)]
pub fn ours_joseph_4x2_f32(p: &KfProblem<f32, 4, 2>) -> Result<KalmanFilter<f32, 4>> {
    p.kf_step()
}
/// `adskalman`, Joseph form, 4x2 f32.
#[inline(never)]
pub fn ads_joseph_4x2_f32(p: &AdsProblem<f32, 4, 2>) -> AdsState<f32, 4> {
    p.step()
}
/// Ours, optimal-gain form, 4x2 f32.
#[inline(never)]
pub fn ours_standard_4x2_f32(p: &KfProblem<f32, 4, 2>) -> Result<KalmanFilter<f32, 4>> {
    p.kf_standard_step()
}
/// `adskalman`, optimal-gain form made symmetric, 4x2 f32.
#[inline(never)]
pub fn ads_symmetric_4x2_f32(p: &AdsProblem<f32, 4, 2>) -> AdsState<f32, 4> {
    p.step_symmetric()
}
