//! Estimator lookup for `run`, `demo` and `replay`: the same [`crate::estimators::FACTORIES`]
//! as `eval`, so the commands can never disagree about what a name means, built from the
//! estimators' [`Source`] (a spec, from a scenario or a spec file) alone.

use crate::estimator_args::{EstimatorArgs, Feed};
use crate::estimators::{build_all, FACTORIES};
use crate::eval::EvalOptions;
use crate::source::Source;
use crate::Estimator;
use anyhow::Result;
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

/// The estimators that can run on live data for `source`: `names` (all when empty), with
/// `pf` at its default particle count and without the `-mix` variants (the commands use
/// [`estimators_with`] and their flags). The full-information oracles of `eval`
/// (`Estimator::full_information`) read observations from before the channel, which a
/// real-time loop does not have; they are left out.
pub fn estimators(
    source: Arc<Source>,
    names: &[String],
    exp: Experiment,
) -> Result<EstimatorFactory> {
    let every = EstimatorArgs {
        estimators: names.to_vec(),
        particles: Some(crate::estimators::pf::DEFAULT_PARTICLES),
        ..EstimatorArgs::default()
    };
    estimators_with(source, &every, exp)
}

/// [`estimators`] as the estimator flags `args` select them ([`EstimatorArgs::select`]);
/// what they select is checked here, once, and every call of the factory builds the same
/// estimators.
pub fn estimators_with(
    source: Arc<Source>,
    args: &EstimatorArgs,
    exp: Experiment,
) -> Result<EstimatorFactory> {
    let mut options = EvalOptions {
        runs: 1,
        horizon: exp.horizon,
        seed: exp.seed,
        ..args.options()
    };
    let start = source.start(exp.seed, exp.run);
    let all = build_all(FACTORIES, &source.spec, &options, &start)?;
    options.estimators = args.select(&all, &source.spec.name, Feed::Slots)?;
    Ok(Box::new(move || {
        build_all(
            FACTORIES,
            &source.spec,
            &options,
            &source.start(exp.seed, exp.run),
        )
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
        let args = EstimatorArgs {
            estimators: names,
            particles,
            loss_rate,
            gate: None,
            lag: 0,
        };
        let make = estimators_with(scenario, &args, exp)?;
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
