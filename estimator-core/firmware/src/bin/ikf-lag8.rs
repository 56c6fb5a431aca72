//! The intermittent Kalman filter under the fixed-lag layer (L = 8) over the embedded occlusion
//! stream, with packets made late by a fixed pattern and folded in when they arrive.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with_lag(run::OCCLUSION, run::run_ikf_lag8_counts)
}
