//! KF-IO (linear MMSE filter treating arrival as Bernoulli) over the embedded occlusion stream.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::OCCLUSION, run::run_kf_io)
}
