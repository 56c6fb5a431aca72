//! The seed 004 federated Tobit fusion filter (3 local Tobit filters, fusion and reset) over
//! the embedded three-node stream.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::TOBIT, run::run_tobit)
}
