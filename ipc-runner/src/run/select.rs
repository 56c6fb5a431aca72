//! Estimator lookup for `run`, `demo` and `replay`: the same [`crate::estimators::FACTORIES`]
//! as `eval`, so the commands can never disagree about what a name means, built from the
//! estimators' [`Source`] (a spec, from a scenario or a spec file) alone.

use crate::estimators::{build_all, EvalOptions, FACTORIES};
use crate::source::Source;
use crate::Estimator;
use anyhow::{bail, Result};
use std::sync::Arc;

/// A factory for a fresh set of estimators (called again when a stream restarts).
pub type EstimatorFactory = Box<dyn Fn() -> Result<Vec<Box<dyn Estimator>>>>;

/// What the estimator factories are built for (as in `eval`: estimators may depend on the
/// seed, the run and the horizon).
#[derive(Clone, Copy, Debug)]
pub struct Experiment {
    /// Experiment seed.
    pub seed: u64,
    /// Run index.
    pub run: u64,
    /// Horizon T.
    pub horizon: u32,
}

/// What the commands choose beside the names: `--particles` and `--loss-rate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Choice {
    /// Particles of `pf` (0: not built).
    pub particles: usize,
    /// `p_loss` of the occlusion estimators' `-mix` variants (0: not built).
    pub loss_rate: f64,
    /// `--gate P`: the innovation gate's probability (None: off; docs/gate.md).
    pub gate: Option<f64>,
}

impl Choice {
    /// What [`estimators`] builds: `pf` at its default particle count, no `-mix` variants.
    pub const EVERY: Self = Self {
        particles: crate::estimators::pf::DEFAULT_PARTICLES,
        loss_rate: 0.0,
        gate: None,
    };

    /// The choice of `run`, `replay` and `demo`: `pf` only when asked for (`--particles N`,
    /// or named in `--estimators`), as in `eval`, and the `-mix` estimators with
    /// `--loss-rate P`.
    pub fn of(particles: Option<usize>, names: &[String], loss_rate: f64) -> Self {
        Self {
            particles: crate::eval::cli::particles(particles, names),
            loss_rate,
            gate: None,
        }
    }

    /// With the innovation gate of `--gate P` (docs/gate.md).
    #[must_use]
    pub fn gated(mut self, gate: Option<f64>) -> Self {
        self.gate = gate;
        self
    }
}

/// The estimators that can run on live data for `source`: `names` (all when empty), with
/// `pf` and without the `-mix` variants ([`Choice::EVERY`]; the commands use
/// [`estimators_with`]). The full-information oracles of `eval`
/// (`Estimator::full_information`) read observations from before the channel, which a
/// real-time loop does not have; they are left out.
pub fn estimators(
    source: Arc<Source>,
    names: &[String],
    exp: Experiment,
) -> Result<EstimatorFactory> {
    estimators_with(source, names, exp, Choice::EVERY)
}

/// [`estimators`] with the particle count and loss rate of `choice`.
pub fn estimators_with(
    source: Arc<Source>,
    names: &[String],
    exp: Experiment,
    choice: Choice,
) -> Result<EstimatorFactory> {
    // Estimator families add fields to EvalOptions; the rest default, as in `eval`.
    #[allow(clippy::needless_update)]
    let options = EvalOptions {
        runs: 1,
        horizon: exp.horizon,
        seed: exp.seed,
        particles: choice.particles,
        loss_rate: choice.loss_rate,
        gate: choice.gate,
        ..EvalOptions::default()
    };
    let all = build_all(
        FACTORIES,
        &source.spec,
        &options,
        &source.start(exp.seed, exp.run),
    )?;
    let available: Vec<&'static str> = all
        .iter()
        .filter(|e| !e.full_information())
        .map(|e| e.name())
        .collect();
    for n in names {
        if !available
            .iter()
            .any(|a| crate::estimators::names_match(a, n))
        {
            let oracle = all.iter().any(|e| e.name() == n && e.full_information());
            bail!(
                "estimator {n:?} {} for scenario {:?}; available: {}",
                if oracle {
                    "is a full-information oracle (offline `eval` only)"
                } else if n.ends_with("-mix") && choice.loss_rate == 0.0 {
                    "needs --loss-rate P"
                } else {
                    "does not exist"
                },
                source.spec.name,
                available.join(", ")
            );
        }
    }
    if available.is_empty() {
        bail!(
            "no real-time estimator applies to scenario {:?}",
            source.spec.name
        );
    }
    let names = names.to_vec();
    Ok(Box::new(move || {
        let built = build_all(
            FACTORIES,
            &source.spec,
            &options,
            &source.start(exp.seed, exp.run),
        )?;
        Ok(built
            .into_iter()
            .filter(|e| !e.full_information())
            .filter(|e| names.is_empty() || names.iter().any(|n| n == e.name()))
            .collect())
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(names: &[&str], particles: Option<usize>, loss_rate: f64) -> Result<Vec<String>> {
        let scenario = Arc::new(Source::of_spec(crate::source::preset_spec("occlusion")));
        let names: Vec<String> = names.iter().map(|n| n.to_string()).collect();
        let exp = Experiment {
            seed: 0,
            run: 0,
            horizon: 10,
        };
        let choice = Choice::of(particles, &names, loss_rate);
        let make = estimators_with(scenario, &names, exp, choice)?;
        Ok(make()?.iter().map(|e| e.name().to_string()).collect())
    }

    #[test]
    fn the_particle_filter_is_opt_in_and_the_mixtures_need_a_loss_rate() {
        assert_eq!(
            names(&[], None, 0.0).unwrap(),
            ["ikf", "cce", "kf-io", "adf"]
        );
        assert_eq!(names(&["pf"], None, 0.0).unwrap(), ["pf"]);
        assert_eq!(
            names(&[], Some(100), 0.2).unwrap(),
            [
                "ikf",
                "cce",
                "kf-io",
                "adf",
                "cce-mix",
                "kf-io-mix",
                "adf-mix",
                "pf",
                "pf-mix"
            ]
        );
        let e = names(&["cce-mix"], None, 0.0).unwrap_err().to_string();
        assert!(e.contains("needs --loss-rate P"), "{e}");
        // The library default keeps pf.
        let scenario = Arc::new(Source::of_spec(crate::source::preset_spec("occlusion")));
        let exp = Experiment {
            seed: 0,
            run: 0,
            horizon: 10,
        };
        let all = estimators(scenario, &[], exp).unwrap()().unwrap();
        assert!(all.iter().any(|e| e.name() == "pf"));
    }
}
