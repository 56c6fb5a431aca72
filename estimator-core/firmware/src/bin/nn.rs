//! The seed 003 NN estimator (paper configuration) over the embedded token-bucket stream.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::NN, run::run_nn)
}
