//! The intermittent Kalman filter over the embedded occlusion stream.
#![no_std]
#![no_main]

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(estimator_firmware::run::run_ikf)
}
