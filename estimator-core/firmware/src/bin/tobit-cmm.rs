//! The product's seed 004 estimator at the information bound, `tobit-cmm-held`: the
//! centralised moment-matched Tobit filter behind the bucket mirror, reading held silences,
//! over the embedded three-node stream.
#![no_std]
#![no_main]

use estimator_firmware::run;

#[cortex_m_rt::entry]
fn main() -> ! {
    estimator_firmware::main_with(run::TOBIT, run::run_tobit_cmm)
}
