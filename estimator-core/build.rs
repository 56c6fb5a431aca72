//! Emits one short cfg, `simd_lanes`, for "the `simd` feature is on and the target has the
//! SIMD lanes of `linalg::lanes`" (x86-64, AArch64), so that the code says `cfg(simd_lanes)`
//! instead of repeating the feature-and-architecture condition. The Cortex-M4 (thumbv7em) has
//! no SIMD floating point: the alias is off there whatever the features.

use std::env;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(simd_lanes)");
    println!("cargo:rerun-if-changed=build.rs");
    // Cargo sets CARGO_FEATURE_<NAME> for every enabled feature and CARGO_CFG_TARGET_ARCH to
    // the architecture being compiled for (not the host's).
    let simd = env::var_os("CARGO_FEATURE_SIMD").is_some();
    let arch = env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    if simd && matches!(arch.as_str(), "x86_64" | "aarch64") {
        println!("cargo:rustc-cfg=simd_lanes");
    }
}
