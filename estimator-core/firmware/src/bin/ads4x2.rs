//! `adskalman` 0.18 (Joseph form) on the 4x2 problem (constant-velocity tracker),
//! over the embedded occlusion stream's measurements (see `estimator_firmware::peers`).
#![no_std]
#![no_main]

use estimator_firmware::{peers, run};

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::OCCLUSION, peers::run_ads4x2)
}
