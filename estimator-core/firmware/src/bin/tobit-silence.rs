//! The seed 004 fusion filter with the silence update (the product's option: the receiver's
//! bucket mirror and the truncated-Gaussian silence update) over the embedded three-node
//! stream.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::TOBIT, run::run_tobit_silence)
}
