//! `minikalman` 0.8 on the 3x2 problem (seed 001's model),
//! over the embedded occlusion stream's measurements (see `estimator_firmware::peers`).
#![no_std]
#![no_main]

use estimator_firmware::{peers, run};

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::OCCLUSION, peers::run_mk3x2)
}
