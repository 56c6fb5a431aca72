//! The floor of a Kalman step (`estimator_firmware::peers::Floor`: straight-line, nothing
//! validated) on the 4x2 problem, over the embedded occlusion stream's measurements.
#![no_std]
#![no_main]

use estimator_firmware::{peers, run};

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::OCCLUSION, peers::run_floor4x2)
}
