//! `nn-token-bucket`: the illustrative example of seed 003, section IV.
//!
//! Plant [`Seed003Plant`] (time-varying A_k, B_k, C_k, D_k, `f(x) = 8[sin x₁ cos x₃, sin x₂,
//! sin x₂ cos x₃]ᵀ`, one scalar `w_k ~ N(0, 0.1)` in state and measurement), deterministic
//! `x₀ = [3.1, −2.65, 4]ᵀ`, estimators' prior `x̂₀ = 0`, `P₀ = 10 I`, one sensor behind a token
//! bucket with `a = 2`, `b = 3`, `S = 10`, `z₀ = 6`. The paper's horizon is T = 300
//! (`ipc-runner eval --scenario nn-token-bucket --horizon 300`).

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

    #[test]
    fn preset_runs_and_transmits_two_thirds() {
        let s = super::preset().unwrap();
        assert_eq!((s.nx(), s.ny(), s.nodes()), (3, 2, 1));
        let mut sim = s.start(0, 0);
        assert_eq!(&sim.initial_truth()[..3], &[3.1, -2.65, 4.0]);
        let mut sent = 0;
        for _ in 0..300 {
            let i = sim.next_instant();
            assert!(i.truth[..3].iter().all(|v| v.is_finite()));
            let o = i.obs[0];
            sent += usize::from(o.delivered);
            assert_eq!(o.flags & FLAG_TOKEN_BLOCKED != 0, !o.delivered);
        }
        // 6 initial sends, then 2 of every 3 of the remaining 294 instants.
        assert_eq!(sent, 6 + 196);
    }
}
