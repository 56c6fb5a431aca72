//! Emits two short cfgs:
//!
//! * `simd_lanes` for "the `simd` feature is on and the target has the SIMD lanes of
//!   `linalg::lanes`" (x86-64, AArch64), so that the code says `cfg(simd_lanes)` instead of
//!   repeating the feature-and-architecture condition. The Cortex-M4 (thumbv7em) has no SIMD
//!   floating point: the alias is off there whatever the features.
//! * `small_code` for "this build is optimised for size" (the profile's `opt-level` is `"s"`
//!   or `"z"`, as the firmware's is): a kernel of `linalg::small` that a Kalman step calls
//!   twice with the same shapes is then one copy out of line instead of inlined twice, an
//!   error's finiteness test is inlined where nobody may read it, and `linalg::all_finite`
//!   reads the matrix as a slice. The results are the same either way.
//! * `in_order_core` for "the target is a microcontroller core that executes in order" (Arm
//!   without an operating system: the Cortex-M family, the firmware's target). The
//!   continued fractions that `gauss::side_by_side` runs side by side to hide the divider's
//!   latency on an out-of-order core only add instructions there, so they run one at a time,
//!   as in a size-optimised build. The results are the same bits either way.

use std::env;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(simd_lanes)");
    println!("cargo:rustc-check-cfg=cfg(small_code)");
    println!("cargo:rustc-check-cfg=cfg(in_order_core)");
    println!("cargo:rerun-if-changed=build.rs");
    // Cargo gives build scripts the opt-level this package is compiled with.
    let opt = env::var("OPT_LEVEL").unwrap_or_default();
    if matches!(opt.as_str(), "s" | "z") {
        println!("cargo:rustc-cfg=small_code");
    }
    // Cargo sets CARGO_FEATURE_<NAME> for every enabled feature and CARGO_CFG_TARGET_ARCH to
    // the architecture being compiled for (not the host's).
    let simd = env::var_os("CARGO_FEATURE_SIMD").is_some();
    let arch = env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let os = env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if arch == "arm" && os == "none" {
        println!("cargo:rustc-cfg=in_order_core");
    }
    if simd && matches!(arch.as_str(), "x86_64" | "aarch64") {
        println!("cargo:rustc-cfg=simd_lanes");
    }
}
