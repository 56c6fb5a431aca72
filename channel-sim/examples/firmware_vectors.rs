//! Writes the measurement stream the Cortex-M firmware embeds
//! (`estimator-core/firmware/vectors/occlusion.bin`).
//!
//! ```text
//! cargo run -p channel-sim --example firmware_vectors            # (re)write the file
//! cargo run -p channel-sim --example firmware_vectors -- --check # verify it is reproduced
//! ```
//!
//! The stream is one run of seed 001's Section IV example (DESIGN.md's reading): the plant
//! x_{k+1} = A x_k + w_k, z_k = C x_k + v_k with Q = 0.3 I₃, R = 0.2 I₂, x₀ ~ N([5 5 5]ᵀ, 4 I₃);
//! the packet of instant k is dropped iff u_k = x_{1,k} + n_k, n_k ~ N(0, 0.1), lies in one of
//! the regions [20i − 5, 20i + 5], i = 1..4 (the label is that i). k = 1..=T, T = 100,
//! simulation seed [`SEED`] (xoshiro256++, standard normals from rand_distr), computed in f64
//! and stored as f32. After regenerating, update `VECTORS_FNV1A64` in
//! `estimator-core/firmware/src/run.rs` to the hash this prints.
//!
//! File format (little-endian): magic `EFV1`, version u32 = 1, seed u64, steps u32, nx u32 = 3,
//! ny u32 = 2, record size u32 = 32; then per instant: k u32, delivered u8, label u8, 2 zero
//! bytes, channel flags u32 (`FLAG_OCCLUDED` on a drop), z_k f32×2 (the sensor's measurement,
//! also on a drop), x_k f32×3.

use std::path::PathBuf;

use channel_sim::sim::FLAG_OCCLUDED;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Simulation seed of the embedded stream.
const SEED: u64 = 0x5EED_0001_F1A5_0008;
/// Number of instants.
const T: u32 = 100;

fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn generate() -> Vec<u8> {
    let a = [[1.01, 0.1, 0.0], [0.0, 1.01, 0.1], [0.0, 0.0, -1.02]];
    let c = [[2.0, 3.0, 1.0], [1.0, 0.0, 0.98]];
    let (q, r, psi, mu0, sigma0) = (0.3f64, 0.2f64, 0.1f64, 5.0f64, 4.0f64);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(SEED);
    let mut n = move || -> f64 { StandardNormal.sample(&mut rng) };

    let mut out = Vec::new();
    out.extend_from_slice(b"EFV1");
    out.extend_from_slice(&1u32.to_le_bytes()); // format version
    out.extend_from_slice(&SEED.to_le_bytes());
    for w in [T, 3, 2, 32] {
        out.extend_from_slice(&w.to_le_bytes());
    }

    let mut x = [0.0f64; 3];
    for xi in &mut x {
        *xi = mu0 + sigma0.sqrt() * n();
    }
    for k in 1..=T {
        let w = [q.sqrt() * n(), q.sqrt() * n(), q.sqrt() * n()];
        let mut next = [0.0; 3];
        for i in 0..3 {
            next[i] = (0..3).map(|j| a[i][j] * x[j]).sum::<f64>() + w[i];
        }
        x = next;
        let v = [r.sqrt() * n(), r.sqrt() * n()];
        let z: [f64; 2] =
            std::array::from_fn(|i| (0..3).map(|j| c[i][j] * x[j]).sum::<f64>() + v[i]);
        let u = x[0] + psi.sqrt() * n();
        let label = (1..=4u8)
            .find(|&i| (u - 20.0 * f64::from(i)).abs() <= 5.0)
            .unwrap_or(0);
        let delivered = label == 0;
        out.extend_from_slice(&k.to_le_bytes());
        out.extend_from_slice(&[u8::from(delivered), label, 0, 0]);
        let flags = if delivered { 0 } else { FLAG_OCCLUDED };
        out.extend_from_slice(&flags.to_le_bytes());
        for v in z.iter().chain(x.iter()) {
            out.extend_from_slice(&(*v as f32).to_le_bytes());
        }
    }
    out
}

fn main() -> anyhow::Result<()> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../estimator-core/firmware/vectors/occlusion.bin");
    let bytes = generate();
    let hash = fnv1a64(&bytes);
    let drops = bytes[32..].chunks(32).filter(|r| r[4] == 0).count();
    if std::env::args().any(|a| a == "--check") {
        let on_disk = std::fs::read(&path)?;
        anyhow::ensure!(
            on_disk == bytes,
            "{} differs from what the generator produces",
            path.display()
        );
        println!("{} is reproduced exactly", path.display());
    } else {
        std::fs::write(&path, &bytes)?;
        println!("wrote {} ({} bytes)", path.display(), bytes.len());
    }
    println!("steps={T} dropouts={drops} seed={SEED:#018x} fnv1a64={hash:#018x}");
    Ok(())
}
