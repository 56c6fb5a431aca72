//! `nn-token-bucket`: the illustrative example of seed 003, section IV.
//!
//! Plant [`Seed003Plant`] (time-varying A_k, B_k, C_k, D_k, `f(x) = 8[sin x₁ cos x₃, sin x₂,
//! sin x₂ cos x₃]ᵀ`, one scalar `w_k ~ N(0, 0.1)` in state and measurement), deterministic
//! `x₀ = [3.1, −2.65, 4]ᵀ`, estimators' prior `x̂₀ = 0`, `P₀ = 10 I`, one sensor behind a token
//! bucket with `a = 2`, `b = 3`, `S = 10`, `z₀ = 6`. The paper's horizon is T = 300
//! (`ipc-runner eval --scenario nn-token-bucket --steps 300`).
//!
//! The paper's timing: the sensor measures from k = 0 and the bucket takes its first decision
//! at k = 0 (μ₀ = min{6 + 2, 10} − 3 = 5 ≥ 0: y₀ is sent). The stream's slots start at k = 1, so
//! y₀ and its delivery are the run's
//! [`initial_observations`](crate::Simulation::initial_observations), which the seed 003
//! estimators are initialised with (docs/design.md, "Seed 003").

use std::sync::Arc;

use nalgebra::{dvector, DMatrix};

use crate::channel::token_bucket::TokenBucketStage;
use crate::error::ScenarioError;
use crate::plant::nn::Seed003Plant;
use crate::scenario::composed::ComposedScenario;
use crate::scenario::initial::InitialDistribution;
use crate::sim::Scenario;

/// The bucket of section IV.
pub const BUCKET: TokenBucketStage = TokenBucketStage {
    a: 2,
    b: 3,
    s: 10,
    z0: 6,
};

/// `w̄² = 0.1`.
pub const W_VAR: f64 = 0.1;

/// The `nn-token-bucket` preset.
pub fn preset() -> Result<Box<dyn Scenario>, ScenarioError> {
    BUCKET.config("stages[0]")?;
    let initial = InitialDistribution::new(
        dvector![3.1, -2.65, 4.0],
        DMatrix::zeros(3, 3),
        dvector![0.0, 0.0, 0.0],
        DMatrix::identity(3, 3) * 10.0,
    )?;
    Ok(Box::new(ComposedScenario::new(
        "nn-token-bucket",
        Arc::new(Seed003Plant::new(W_VAR)?),
        initial,
        vec![Arc::new(BUCKET)],
    )?))
}

#[cfg(test)]
mod tests {
    use crate::sim::FLAG_TOKEN_BLOCKED;

    /// The paper's transmission sequence from k = 0, by hand from eq. (2)-(3) with a = 2,
    /// b = 3, S = 10, z₀ = 6 (μ_k = min{z_k + a, S} − b, z_{k+1} = min{z_k + a, S} − 1{μ_k ≥ 0} b,
    /// y_k sent iff μ_k ≥ 0):
    ///
    /// ```text
    ///  k   z_k  min{z_k+2, 10}  μ_k  sent  z_{k+1}
    ///  0    6         8          5    1      5
    ///  1    5         7          4    1      4
    ///  2    4         6          3    1      3
    ///  3    3         5          2    1      2
    ///  4    2         4          1    1      1
    ///  5    1         3          0    1      0
    ///  6    0         2         −1    0      2
    ///  7    2         4          1    1      1
    ///  8    1         3          0    1      0
    ///  9    0         2         −1    0      2
    /// 10    2         4          1    1      1
    /// 11    1         3          0    1      0
    /// 12    0         2         −1    0      2
    /// ```
    ///
    /// From k = 6 the state (z_k = 0, 2, 1) repeats with period 3: withheld exactly at
    /// k = 6, 9, 12, …, i.e. k ≡ 0 (mod 3), k ≥ 6.
    const SENT_FROM_0: [bool; 13] = [
        true, true, true, true, true, true, false, true, true, false, true, true, false,
    ];

    #[test]
    fn bucket_sequence_from_k0_is_the_papers() {
        let s = super::preset().unwrap();
        assert_eq!((s.nx(), s.ny(), s.nodes()), (3, 2, 1));
        let mut sim = s.start(0, 0);
        assert_eq!(&sim.initial_truth()[..3], &[3.1, -2.65, 4.0]);
        // k = 0: y₀ is measured and sent (μ₀ = 5); it is carried by the run's start.
        let o0 = sim
            .initial_observations()
            .expect("seed 003 measures at k = 0")[0];
        assert_eq!((o0.k, o0.delivered, o0.flags), (0, SENT_FROM_0[0], 0));
        assert!(o0.y[..2].iter().all(|v| v.is_finite() && *v != 0.0));
        let mut sent = 0;
        for k in 1..=300u32 {
            let i = sim.next_instant();
            assert_eq!(i.k, k);
            assert!(i.truth[..3].iter().all(|v| v.is_finite()));
            let o = i.obs[0];
            if let Some(&want) = SENT_FROM_0.get(k as usize) {
                assert_eq!(o.delivered, want, "k = {k}");
            }
            // The closed form of the table's periodic tail.
            assert_eq!(o.delivered, k < 6 || k % 3 != 0, "k = {k}");
            assert_eq!(o.flags & FLAG_TOKEN_BLOCKED != 0, !o.delivered);
            sent += usize::from(o.delivered);
        }
        // k = 1..=300: withheld at k = 6, 9, …, 300 (99 instants); with y₀, 202 of the 301
        // instants k = 0..=300 transmit.
        assert_eq!(sent, 300 - 99);
    }
}
