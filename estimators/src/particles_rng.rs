//! The random numbers of the particle filters (`pf`, `pf-mix` and seed 003's coupled
//! filter): xoshiro256++ (`rand_xoshiro`, the generator of the simulation) with Box–Muller
//! normals, one stream per filter seeded from `(seed, run)`, independent of the
//! simulation's streams (the seed mixed by [`splitmix64`], as the simulation mixes its own).
//!
//! The filters drew from a hand-written xoshiro256++ before; the state is seeded and the
//! normals are formed exactly as there, so their estimates are unchanged bit for bit.

use rand_core::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// SplitMix64 finaliser (Steele, Lea & Flood 2014): a bijective mix, so that nearby inputs
/// give unrelated seeds. The simulator seeds its streams with the same function.
pub(crate) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A particle filter's generator of uniforms and standard normals.
#[derive(Clone, Debug)]
pub(crate) struct Rng {
    xoshiro: Xoshiro256PlusPlus,
    /// Box–Muller makes normals in pairs: the second of the last pair, not yet drawn.
    spare: Option<f64>,
}

impl Rng {
    /// The generator whose four state words are SplitMix64 of `seed + i·γ`, i = 1..=4
    /// (γ the golden-ratio increment): not `seed_from_u64`, which starts one increment
    /// earlier, so that the filters keep the streams they always drew.
    pub(crate) fn new(seed: u64) -> Self {
        let mut bytes = [0u8; 32];
        let mut x = seed;
        for word in bytes.chunks_exact_mut(8) {
            x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
            word.copy_from_slice(&splitmix64(x).to_le_bytes());
        }
        Self {
            xoshiro: Xoshiro256PlusPlus::from_seed(bytes),
            spare: None,
        }
    }

    /// Uniform in (0, 1): the top 53 bits, centred in their interval (never 0, so `ln` is
    /// finite).
    #[inline]
    pub(crate) fn uniform(&mut self) -> f64 {
        ((self.xoshiro.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box–Muller).
    #[inline]
    pub(crate) fn normal(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The generator the particle filters carried before, kept here as the reference.
    struct HandWritten([u64; 4]);

    impl HandWritten {
        fn new(seed: u64) -> Self {
            let mut x = seed;
            let mut s = [0u64; 4];
            for v in &mut s {
                x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
                *v = splitmix64(x);
            }
            Self(s)
        }
        fn next_u64(&mut self) -> u64 {
            let s = &mut self.0;
            let r = (s[0].wrapping_add(s[3])).rotate_left(23).wrapping_add(s[0]);
            let t = s[1] << 17;
            s[2] ^= s[0];
            s[3] ^= s[1];
            s[1] ^= s[2];
            s[0] ^= s[3];
            s[2] ^= t;
            s[3] = s[3].rotate_left(45);
            r
        }
    }

    #[test]
    fn the_stream_is_the_hand_written_generators_bit_for_bit() {
        for seed in [0, 1, 42, u64::MAX, 0x7066_5f70_6172_7469] {
            let (mut ours, mut theirs) = (Rng::new(seed), HandWritten::new(seed));
            for _ in 0..1000 {
                assert_eq!(ours.xoshiro.next_u64(), theirs.next_u64(), "seed {seed}");
            }
        }
        // The normals come in pairs, cosine first.
        let (mut ours, mut theirs) = (Rng::new(7), HandWritten::new(7));
        let u = |h: &mut HandWritten| ((h.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        for _ in 0..100 {
            let (u1, u2) = (u(&mut theirs), u(&mut theirs));
            let (r, t) = ((-2.0 * u1.ln()).sqrt(), 2.0 * std::f64::consts::PI * u2);
            assert_eq!(ours.normal().to_bits(), (r * t.cos()).to_bits());
            assert_eq!(ours.normal().to_bits(), (r * t.sin()).to_bits());
        }
    }
}
