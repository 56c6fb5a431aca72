//! Random packet loss: Bernoulli i.i.d. and Gilbert–Elliott (two-state Markov) loss, each node
//! with its own independent loss process.

use std::any::Any;

use rand_distr::{Distribution, StandardUniform};
use serde::Deserialize;

use super::{drop_packet, Stage, StageSpec};
use crate::error::ScenarioError;
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_RANDOM_LOSS};
use crate::validate::check_probability;

fn uniform(rng: &mut SimRng) -> f64 {
    StandardUniform.sample(rng)
}

/// Each packet is lost independently with probability `p_loss`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BernoulliLoss {
    /// Loss probability per packet.
    pub p_loss: f64,
}

impl BernoulliLoss {
    /// Validates the parameters; `field` prefixes the names in errors.
    pub fn validate(&self, field: &str) -> Result<(), ScenarioError> {
        Ok(check_probability(self.p_loss, &format!("{field}.p_loss"))?)
    }
}

impl StageSpec for BernoulliLoss {
    fn name(&self) -> &'static str {
        "bernoulli"
    }
    fn build(&self, _nodes: usize) -> Box<dyn Stage> {
        Box::new(*self)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl Stage for BernoulliLoss {
    fn apply(&mut self, _k: u32, _truth: &[f64], obs: &mut [Observation], rng: &mut SimRng) {
        for o in obs {
            // Draw even for packets already dropped upstream: keeps streams aligned.
            let lost = uniform(rng) < self.p_loss;
            if lost && o.delivered {
                drop_packet(o, FLAG_RANDOM_LOSS);
            }
        }
    }
}

/// Gilbert–Elliott loss: a hidden good/bad channel state per node, a Markov chain with
/// `P(good→bad) = p_good_to_bad`, `P(bad→good) = p_bad_to_good`, and a loss probability per
/// state. The chain starts in its stationary distribution and moves once per instant (before
/// the loss draw), so the loss rate is stationary from k = 1:
/// `π_bad·loss_bad + (1 − π_bad)·loss_good`, `π_bad = p_gb/(p_gb + p_bg)`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GilbertElliottLoss {
    /// Probability of moving from the good to the bad state at an instant.
    pub p_good_to_bad: f64,
    /// Probability of moving from the bad to the good state at an instant.
    pub p_bad_to_good: f64,
    /// Loss probability in the good state.
    #[serde(default)]
    pub loss_good: f64,
    /// Loss probability in the bad state.
    #[serde(default = "one")]
    pub loss_bad: f64,
}

fn one() -> f64 {
    1.0
}

impl GilbertElliottLoss {
    /// Validates the parameters; `field` prefixes the names in errors.
    pub fn validate(&self, field: &str) -> Result<(), ScenarioError> {
        check_probability(self.p_good_to_bad, &format!("{field}.p_good_to_bad"))?;
        check_probability(self.p_bad_to_good, &format!("{field}.p_bad_to_good"))?;
        check_probability(self.loss_good, &format!("{field}.loss_good"))?;
        check_probability(self.loss_bad, &format!("{field}.loss_bad"))?;
        if self.p_good_to_bad + self.p_bad_to_good == 0.0 {
            return Err(ScenarioError::invalid(
                format!("{field}.p_good_to_bad"),
                "p_good_to_bad and p_bad_to_good cannot both be 0 (no stationary state)",
            ));
        }
        Ok(())
    }

    /// Stationary probability of the bad state.
    pub fn stationary_bad(&self) -> f64 {
        self.p_good_to_bad / (self.p_good_to_bad + self.p_bad_to_good)
    }

    /// Long-run loss rate.
    pub fn loss_rate(&self) -> f64 {
        let pb = self.stationary_bad();
        pb * self.loss_bad + (1.0 - pb) * self.loss_good
    }
}

impl StageSpec for GilbertElliottLoss {
    fn name(&self) -> &'static str {
        "gilbert-elliott"
    }
    fn build(&self, nodes: usize) -> Box<dyn Stage> {
        Box::new(GilbertElliottState {
            spec: *self,
            bad: None,
            nodes,
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// Per-run state: each node's channel state (drawn lazily at the first instant, from the
/// channel stream, so building a stage consumes no randomness).
#[derive(Debug)]
struct GilbertElliottState {
    spec: GilbertElliottLoss,
    bad: Option<Vec<bool>>,
    nodes: usize,
}

impl Stage for GilbertElliottState {
    fn apply(&mut self, _k: u32, _truth: &[f64], obs: &mut [Observation], rng: &mut SimRng) {
        let s = self.spec;
        let bad = self.bad.get_or_insert_with(|| {
            (0..self.nodes)
                .map(|_| uniform(rng) < s.stationary_bad())
                .collect()
        });
        for (o, bad) in obs.iter_mut().zip(bad.iter_mut()) {
            let flip = uniform(rng);
            *bad = if *bad {
                flip >= s.p_bad_to_good
            } else {
                flip < s.p_good_to_bad
            };
            let p_loss = if *bad { s.loss_bad } else { s.loss_good };
            let lost = uniform(rng) < p_loss;
            if lost && o.delivered {
                drop_packet(o, FLAG_RANDOM_LOSS);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{run_rng, Stream};

    fn fresh(nodes: usize, k: u32) -> Vec<Observation> {
        (0..nodes)
            .map(|m| Observation {
                k,
                node: m as u8,
                delivered: true,
                ny: 1,
                y: [1.0, 0.0, 0.0, 0.0],
                flags: 0,
                tokens: None,
            })
            .collect()
    }

    /// Loss count over n i.i.d. packets is Binomial(n, p): tolerance 5 standard deviations
    /// sqrt(n p (1 − p)) (false-alarm probability ≈ 6e-7).
    #[test]
    fn bernoulli_loss_rate_within_binomial_tolerance() {
        let spec = BernoulliLoss { p_loss: 0.3 };
        let mut stage = spec.build(3);
        let mut rng = run_rng(1, 0, Stream::Channel);
        let mut lost = [0u64; 3];
        let n = 100_000u64;
        for k in 1..=n as u32 {
            let mut obs = fresh(3, k);
            stage.apply(k, &[], &mut obs, &mut rng);
            for (m, o) in obs.iter().enumerate() {
                if !o.delivered {
                    assert_eq!(o.flags, FLAG_RANDOM_LOSS);
                    assert_eq!(o.y, [0.0; 4]);
                    lost[m] += 1;
                }
            }
        }
        let sd = (n as f64 * 0.3 * 0.7).sqrt();
        for l in lost {
            assert!((l as f64 - 0.3 * n as f64).abs() < 5.0 * sd, "{l}");
        }
    }

    /// With loss_good = 0 and loss_bad = 1 the loss indicator is the chain itself. Given the
    /// number of visits to a state, the number of transitions out of it is exactly
    /// Binomial(visits, p) by the Markov property: 5 standard deviations again. The overall
    /// rate is checked against the stationary π_bad with the Markov-chain variance
    /// n π(1−π)(1+ρ)/(1−ρ), ρ = 1 − p_gb − p_bg.
    #[test]
    fn gilbert_elliott_transitions_and_rate_within_tolerance() {
        let spec = GilbertElliottLoss {
            p_good_to_bad: 0.05,
            p_bad_to_good: 0.25,
            loss_good: 0.0,
            loss_bad: 1.0,
        };
        let mut stage = spec.build(1);
        let mut rng = run_rng(2, 0, Stream::Channel);
        let n = 200_000u32;
        let (mut prev, mut lost) = (None::<bool>, 0u64);
        let (mut visits_good, mut to_bad, mut visits_bad, mut to_good) = (0u64, 0u64, 0u64, 0u64);
        for k in 1..=n {
            let mut obs = fresh(1, k);
            stage.apply(k, &[], &mut obs, &mut rng);
            let bad = !obs[0].delivered;
            lost += bad as u64;
            match prev {
                Some(false) => {
                    visits_good += 1;
                    to_bad += bad as u64;
                }
                Some(true) => {
                    visits_bad += 1;
                    to_good += !bad as u64;
                }
                None => {}
            }
            prev = Some(bad);
        }
        let binom = |count: u64, trials: u64, p: f64| {
            let sd = (trials as f64 * p * (1.0 - p)).sqrt();
            assert!(
                (count as f64 - p * trials as f64).abs() < 5.0 * sd,
                "{count}/{trials} vs {p}"
            );
        };
        binom(to_bad, visits_good, 0.05);
        binom(to_good, visits_bad, 0.25);
        let pi = spec.stationary_bad();
        let rho = 1.0 - 0.05 - 0.25;
        let sd = (n as f64 * pi * (1.0 - pi) * (1.0 + rho) / (1.0 - rho)).sqrt();
        assert!((lost as f64 - pi * n as f64).abs() < 5.0 * sd);
        assert!((spec.loss_rate() - 1.0 / 6.0).abs() < 1e-15);
    }

    #[test]
    fn validation_names_the_field() {
        let e = BernoulliLoss { p_loss: 1.5 }
            .validate("stages[0]")
            .unwrap_err();
        assert!(e.to_string().contains("stages[0].p_loss"), "{e}");
        let e = GilbertElliottLoss {
            p_good_to_bad: 0.1,
            p_bad_to_good: -0.1,
            loss_good: 0.0,
            loss_bad: 1.0,
        }
        .validate("stages[2]")
        .unwrap_err();
        assert!(e.to_string().contains("stages[2].p_bad_to_good"), "{e}");
    }
}
