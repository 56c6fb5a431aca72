//! How a particle filter's own random stream is seeded from `(seed, run)`: independent of the
//! simulation's streams, reproducible, and the same whatever the thread count.

/// SplitMix64 finaliser (Steele, Lea & Flood 2014): a bijective mix, so that nearby inputs
/// give unrelated seeds. The simulator seeds its streams with the same function.
pub(crate) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
