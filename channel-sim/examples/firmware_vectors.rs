//! Writes the measurement streams the Cortex-M firmware embeds
//! (`estimator-core/firmware/vectors/occlusion.bin` and `nn.bin`).
//!
//! ```text
//! cargo run -p channel-sim --example firmware_vectors            # (re)write the file
//! cargo run -p channel-sim --example firmware_vectors -- --check # verify it is reproduced
//! ```
//!
//! `occlusion.bin` is one run of seed 001's Section IV example (DESIGN.md's reading): the plant
//! x_{k+1} = A x_k + w_k, z_k = C x_k + v_k with Q = 0.3 I₃, R = 0.2 I₂, x₀ ~ N([5 5 5]ᵀ, 4 I₃);
//! the packet of instant k is dropped iff u_k = x_{1,k} + n_k, n_k ~ N(0, 0.1), lies in one of
//! the regions [20i − 5, 20i + 5], i = 1..4 (the label is that i). k = 1..=T, T = 100,
//! simulation seed [`SEED`] (xoshiro256++, standard normals from rand_distr), computed in f64
//! and stored as f32.
//!
//! `nn.bin` is one run of seed 003's Section IV example (DESIGN.md's reading, the plant of
//! `estimator_core::filter::nn_system::Seed003Example`): x_{k+1} = A_k x_k + f(x_k) + B_k w_k,
//! y_k = C_k x_k + D_k w_k with the same scalar w_k ~ N(0, 0.1), x₀ = [3.1 −2.65 4]ᵀ; the token
//! bucket (a, b, S, z₀) = (2, 3, 10, 6) decides from k = 1 on whether y_k is transmitted
//! (label 0 either way); k = 1..=T, T = 100, seed [`NN_SEED`].
//!
//! After regenerating, update `OCCLUSION_FNV1A64` / `NN_FNV1A64` in
//! `estimator-core/firmware/src/run.rs` to the hashes this prints.
//!
//! File format (little-endian): magic `EFV1`, version u32 = 1, seed u64, steps u32, nx u32 = 3,
//! ny u32 = 2, record size u32 = 32; then per instant: k u32, delivered u8, label u8, 2 zero
//! bytes, channel flags u32 (`FLAG_OCCLUDED` on a drop), z_k f32×2 (the sensor's measurement,
//! also on a drop), x_k f32×3.

use std::path::PathBuf;

use channel_sim::sim::{FLAG_OCCLUDED, FLAG_TOKEN_BLOCKED};
use estimator_core::filter::nn_system::{CoupledNoiseSystem, DifferentiableMap, Seed003Example};
use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
use nalgebra::{SMatrix, Vector3};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Simulation seed of the embedded stream.
const SEED: u64 = 0x5EED_0001_F1A5_0008;
/// Number of instants.
const T: u32 = 100;
/// Simulation seed of the seed-003 stream.
const NN_SEED: u64 = 0x5EED_0003_F1A5_0008;

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

    let mut out = header(SEED);

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
        let flags = if delivered { 0 } else { FLAG_OCCLUDED };
        record(&mut out, k, delivered, label, flags, &z, &x);
    }
    out
}

fn header(seed: u64) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"EFV1");
    out.extend_from_slice(&1u32.to_le_bytes()); // format version
    out.extend_from_slice(&seed.to_le_bytes());
    for w in [T, 3, 2, 32] {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

fn record(
    out: &mut Vec<u8>,
    k: u32,
    delivered: bool,
    label: u8,
    flags: u32,
    z: &[f64; 2],
    x: &[f64; 3],
) {
    out.extend_from_slice(&k.to_le_bytes());
    out.extend_from_slice(&[u8::from(delivered), label, 0, 0]);
    out.extend_from_slice(&flags.to_le_bytes());
    for v in z.iter().chain(x.iter()) {
        out.extend_from_slice(&(*v as f32).to_le_bytes());
    }
}

fn generate_nn() -> Vec<u8> {
    let sys = Seed003Example;
    let w_sd = Seed003Example::W_VAR.sqrt();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(NN_SEED);
    let mut n = move || -> f64 { StandardNormal.sample(&mut rng) };
    let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).expect("valid bucket"));
    let mut out = header(NN_SEED);
    let mut x: Vector3<f64> = Seed003Example::x0();
    let mut w = w_sd * n();
    for k in 1..=T {
        let km1 = (k - 1) as usize;
        let b: SMatrix<f64, 3, 1> = CoupledNoiseSystem::<f64, 3, 1, 2>::b(&sys, km1);
        x = CoupledNoiseSystem::<f64, 3, 1, 2>::a(&sys, km1) * x + sys.eval(&x) + b * w;
        w = w_sd * n();
        let c: SMatrix<f64, 2, 3> = CoupledNoiseSystem::<f64, 3, 1, 2>::c(&sys, k as usize);
        let d: SMatrix<f64, 2, 1> = CoupledNoiseSystem::<f64, 3, 1, 2>::d(&sys, k as usize);
        let y = c * x + d * w;
        let sent = tb.step().transmit;
        let flags = if sent { 0 } else { FLAG_TOKEN_BLOCKED };
        record(
            &mut out,
            k,
            sent,
            0,
            flags,
            &[y[0], y[1]],
            &[x[0], x[1], x[2]],
        );
    }
    out
}

fn main() -> anyhow::Result<()> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../estimator-core/firmware/vectors");
    let check = std::env::args().any(|a| a == "--check");
    for (file, seed, bytes) in [
        ("occlusion.bin", SEED, generate()),
        ("nn.bin", NN_SEED, generate_nn()),
    ] {
        let path = dir.join(file);
        let hash = fnv1a64(&bytes);
        let drops = bytes[32..].chunks(32).filter(|r| r[4] == 0).count();
        if check {
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
        println!("{file}: steps={T} dropouts={drops} seed={seed:#018x} fnv1a64={hash:#018x}");
    }
    Ok(())
}
