//! Writes the measurement streams the Cortex-M firmware embeds
//! (`estimator-core/firmware/vectors/occlusion.bin`, `nn.bin` and `tobit.bin`).
//!
//! ```text
//! cargo run --release -p channel-sim --example firmware_vectors            # (re)write the file
//! cargo run --release -p channel-sim --example firmware_vectors -- --check # verify it is reproduced
//! ```
//!
//! `occlusion.bin` is run 0 of channel-sim's `occlusion` preset (seed 001's Section IV example,
//! as docs/design.md, Seed 001, reads it: x_{k+1} = A x_k + w_k, z_k = C x_k + v_k with
//! Q = 0.3 I₃, R = 0.2 I₂, x₀ ~ N([5 5 5]ᵀ, 4 I₃); the packet of instant k is dropped iff
//! u_k = x_{1,k} + n_k, n_k ~ N(0, 0.1), lies in one of the regions [20i − 5, 20i + 5],
//! i = 1..4) with seed [`SEED`], k = 1..=T, T = 100, computed in f64 and stored as f32. The
//! measurement stored on a dropped instant comes from the same run without its channel stage.
//!
//! `nn.bin` is run 0 of channel-sim's `nn-token-bucket` preset (seed 003's Section IV example:
//! x_{k+1} = A_k x_k + f(x_k) + B_k w_k, y_k = C_k x_k + D_k w_k with one scalar
//! w_k ~ N(0, 0.1), x₀ = [3.1 −2.65 4]ᵀ, token bucket (a, b, S, z₀) = (2, 3, 10, 6)) with seed
//! [`NN_SEED`], k = 1..=T, T = 100 (label 0 throughout). It is a fixed recorded stream with
//! the timing the product had before issue 22: the bucket's first decision at k = 1 and no
//! y₀. The preset now follows the paper (y₀ measured and sent at k = 0, so the bucket's
//! pattern on k ≥ 1 is one instant earlier); the plant's x_k, y_k for k ≥ 1 are unchanged by
//! that, so the generator replays the preset without its channel and runs the bucket from
//! k = 1 itself, which reproduces the recorded file.
//!
//! `tobit.bin` is run 0 of channel-sim's `tobit-fusion` preset (seed 004's section 4 example:
//! the oscillator x_{t+1} = [cos w  sin w; −sin w  cos w] x_t + [0.16; 0.18] ω_t, w = 0.052π,
//! ω_t ~ N(0, 0.05), three nodes z_{m,t} = x_t + v_{m,t}, v ~ N(0, 0.5 I₂), censored at τ = 0,
//! dynamic event triggers sharing one token bucket) with seed [`TOBIT_SEED`], t = 1..=200
//! (the paper's T): per instant and node what the channel delivered.
//!
//! After regenerating, update the hashes of `OCCLUSION` / `NN` / `TOBIT` in
//! `estimator-core/firmware/src/run/vectors.rs` to the hashes this prints.
//!
//! File format, version 1 (`occlusion.bin`, `nn.bin`; little-endian): magic `EFV1`, version
//! u32 = 1, seed u64, steps u32, nx u32 = 3, ny u32 = 2, record size u32 = 32; then per
//! instant: k u32, delivered u8, label u8, 2 zero bytes, channel flags u32 (channel-sim's
//! `FLAG_*` bits), z_k f32×2 (the sensor's measurement, also on a drop), x_k f32×3.
//!
//! File format, version 2 (`tobit.bin`, one slot per instant and node; little-endian): magic
//! `EFV1`, version u32 = 2, seed u64, steps u32, nx u32 = 2, ny u32 = 2, record size u32 = 60
//! (bytes per instant), nodes u32 = 3, 4 zero bytes; then per instant: k u32, x_k f32×2, and
//! per node m = 1..3 in order: delivered u8 (1: the node transmitted, α β = 1), 3 zero bytes,
//! channel flags u32 (`FLAG_TRIGGERED` α = 1, `FLAG_TOKEN_BLOCKED` triggered but no token,
//! `FLAG_CENSORED` some component was censored at τ), y f32×2 (the measurement as delivered,
//! censored components equal to τ; 0 when nothing was sent, as on the wire).

use std::path::PathBuf;

use channel_sim::scenario::ComposedScenario;
use channel_sim::Simulation;

/// Simulation seed of the embedded stream.
const SEED: u64 = 0x5EED_0001_F1A5_0008;
/// Number of instants.
const T: u32 = 100;
/// Simulation seed of the seed-003 stream.
const NN_SEED: u64 = 0x5EED_0003_F1A5_0008;
/// Simulation seed of the seed-004 stream.
const TOBIT_SEED: u64 = 0x5EED_0004_F1A5_0008;
/// Instants of the seed-004 stream (the paper's T).
const TOBIT_T: u32 = 200;
/// Nodes of the seed-004 stream.
const TOBIT_NODES: u32 = 3;
/// Bytes per instant of the seed-004 stream: k, x_k f32×2, per node (status, flags, y f32×2).
const TOBIT_RECORD: u32 = 4 + 4 * 2 + TOBIT_NODES * (8 + 4 * 2);

fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn generate() -> anyhow::Result<Vec<u8>> {
    let preset = channel_sim::scenario::preset("occlusion")?;
    let composed = preset
        .as_any()
        .downcast_ref::<ComposedScenario>()
        .ok_or_else(|| anyhow::anyhow!("the occlusion preset is not a composed scenario"))?;
    // The same run twice: with the channel (what the estimators see) and without it (the
    // sensor's measurement on every instant, for the lossless KF); the plant's random streams
    // do not depend on the channel, so truth and delivered measurements coincide.
    let mut sim = composed.simulate(SEED, 0);
    let mut lossless = composed.without_channel().simulate(SEED, 0);
    let mut out = header(SEED);
    for k in 1..=T {
        let (inst, full) = (sim.next_instant(), lossless.next_instant());
        anyhow::ensure!(
            inst.k == k && full.k == k,
            "instants out of step at k = {k}"
        );
        anyhow::ensure!(inst.truth == full.truth, "truth differs at k = {k}");
        let (o, f) = (&inst.obs[0], &full.obs[0]);
        anyhow::ensure!(
            f.delivered && (!o.delivered || o.y == f.y),
            "z differs at k = {k}"
        );
        let x: [f64; 3] = std::array::from_fn(|i| inst.truth[i]);
        // u_k = x₁ + n_k is not exposed; on a dropout it lies in region i, and the regions are
        // 20 apart, so the nearest centre is that region unless |n_k| > 5 (15.8 σ).
        let label = if o.delivered {
            0
        } else {
            (1..=4u8)
                .min_by(|&a, &b| {
                    let d = |i: u8| (x[0] - 20.0 * f64::from(i)).abs();
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(0)
        };
        record(
            &mut out,
            k,
            o.delivered,
            label,
            o.flags,
            &[f.y[0], f.y[1]],
            &x,
        );
    }
    Ok(out)
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

fn generate_nn() -> anyhow::Result<Vec<u8>> {
    use channel_sim::channel::token_bucket::TokenBucketStage;
    use channel_sim::sim::FLAG_TOKEN_BLOCKED;
    use estimator_core::protocol::token_bucket::TokenBucket;

    let preset = channel_sim::scenario::preset("nn-token-bucket")?;
    let composed = preset
        .as_any()
        .downcast_ref::<ComposedScenario>()
        .ok_or_else(|| anyhow::anyhow!("the nn-token-bucket preset is not composed"))?;
    let spec = composed
        .stage::<TokenBucketStage>()
        .ok_or_else(|| anyhow::anyhow!("the nn-token-bucket preset has no token bucket"))?;
    // The recorded timing (see the module docs): the bucket decides from k = 1, y₀ unused.
    let mut bucket = TokenBucket::new(spec.config("stages[0]")?);
    let mut sim = composed.without_channel().simulate(NN_SEED, 0);
    let mut out = header(NN_SEED);
    for k in 1..=T {
        let inst = sim.next_instant();
        anyhow::ensure!(inst.k == k, "instants out of step at k = {k}");
        let o = &inst.obs[0];
        let x: [f64; 3] = std::array::from_fn(|i| inst.truth[i]);
        if bucket.step().transmit {
            record(&mut out, k, true, 0, 0, &[o.y[0], o.y[1]], &x);
        } else {
            record(&mut out, k, false, 0, FLAG_TOKEN_BLOCKED, &[0.0, 0.0], &x);
        }
    }
    Ok(out)
}

fn generate_tobit() -> anyhow::Result<Vec<u8>> {
    let preset = channel_sim::scenario::preset("tobit-fusion")?;
    anyhow::ensure!(
        (preset.nx(), preset.ny(), preset.nodes()) == (2, 2, TOBIT_NODES as usize),
        "the tobit-fusion preset changed shape"
    );
    let mut sim = preset.start(TOBIT_SEED, 0);
    let mut out = Vec::new();
    out.extend_from_slice(b"EFV1");
    out.extend_from_slice(&2u32.to_le_bytes()); // format version 2: one slot per node
    out.extend_from_slice(&TOBIT_SEED.to_le_bytes());
    for w in [TOBIT_T, 2, 2, TOBIT_RECORD, TOBIT_NODES, 0] {
        out.extend_from_slice(&w.to_le_bytes());
    }
    for k in 1..=TOBIT_T {
        let inst = sim.next_instant();
        anyhow::ensure!(inst.k == k, "instants out of step at k = {k}");
        anyhow::ensure!(
            inst.obs.len() == TOBIT_NODES as usize,
            "node count at k = {k}"
        );
        out.extend_from_slice(&k.to_le_bytes());
        for v in &inst.truth[..2] {
            out.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        for (m, o) in inst.obs.iter().enumerate() {
            anyhow::ensure!(o.node as usize == m && o.ny == 2, "node {m} at k = {k}");
            out.extend_from_slice(&[u8::from(o.delivered), 0, 0, 0]);
            out.extend_from_slice(&o.flags.to_le_bytes());
            for v in &o.y[..2] {
                out.extend_from_slice(&(*v as f32).to_le_bytes());
            }
        }
    }
    Ok(out)
}

/// Slots without a transmission: instants of a version-1 file, node slots of a version-2 one.
fn not_delivered(bytes: &[u8]) -> usize {
    if bytes[4] == 1 {
        bytes[32..].chunks(32).filter(|r| r[4] == 0).count()
    } else {
        let nodes = TOBIT_NODES as usize;
        bytes[40..]
            .chunks(TOBIT_RECORD as usize)
            .flat_map(|r| (0..nodes).map(move |m| r[12 + 16 * m]))
            .filter(|&d| d == 0)
            .count()
    }
}

fn main() -> anyhow::Result<()> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../estimator-core/firmware/vectors");
    let check = std::env::args().any(|a| a == "--check");
    for (file, seed, steps, bytes) in [
        ("occlusion.bin", SEED, T, generate()?),
        ("nn.bin", NN_SEED, T, generate_nn()?),
        ("tobit.bin", TOBIT_SEED, TOBIT_T, generate_tobit()?),
    ] {
        let path = dir.join(file);
        let hash = fnv1a64(&bytes);
        let drops = not_delivered(&bytes);
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
        println!(
            "{file}: steps={steps} not delivered={drops} seed={seed:#018x} fnv1a64={hash:#018x}"
        );
    }
    Ok(())
}
