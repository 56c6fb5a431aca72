//! The estimator options of `eval`, `run`, `demo` and `replay` (`--estimators`,
//! `--particles`, `--loss-rate`, `--gate`, `--lag`), declared once, and the one check of what they
//! select from the estimators built for a scenario: the commands can never disagree about
//! what a name means.

use crate::estimators::names_match;

use crate::eval::EvalOptions;
use crate::limits::BadInput;
use crate::Estimator;

/// The estimator options every estimating command flattens into its own.
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct EstimatorArgs {
    /// Estimators to run, comma-separated (default: every one that applies to the scenario;
    /// `run`, `demo` and `replay` leave out `eval`'s full-information oracles; `pf` only with
    /// `--particles N` or when named here). Under `--gate P` a name selects its gated
    /// variant (`cce` selects `cce+gate`).
    #[arg(long, value_delimiter = ',')]
    pub estimators: Vec<String>,
    /// Particles of the `pf` reference filter (single-node scenarios with occlusion regions,
    /// a preset or a TOML file, `nn-token-bucket`, and Tobit sensors behind event triggers
    /// sharing a token bucket such as `tobit-fusion`; far slower per step than all the other
    /// estimators together). Default: `pf` is not run unless `--estimators` names `pf`
    /// or `pf-mix` (then 5000).
    #[arg(long)]
    pub particles: Option<usize>,
    /// Known loss rate P of the occlusion estimators' mixture option: adds `cce-mix`,
    /// `kf-io-mix`, `adf-mix` (and `pf-mix`), which read a dropout as "occluded, or lost in
    /// transport with probability P" (docs/occlusion.md, "Losses"). 0 (default): not built.
    #[arg(long, default_value_t = 0.0, value_name = "P",
          value_parser = estpipe_process::flags::probability_below_one)]
    pub loss_rate: f64,
    /// Innovation gate of probability P (docs/gate.md): every estimator with an innovation
    /// ignores a measurement whose NIS exceeds the χ² quantile of P, and is named
    /// `<name>+gate`; the summary counts the rejections. Default: off.
    #[arg(long, value_name = "P", value_parser = crate::estimators::gate_probability)]
    pub gate: Option<f64>,
    /// Fixed lag L in instants (docs/pipeline.md, "Late packets"): a slot that arrives after
    /// its instant was stepped, at most L instants late, is folded into its instant and the
    /// estimators step again from there, so the estimate is the one an on-time arrival would
    /// have given (the next published estimate carries it). 0 (default): late slots are lost.
    #[arg(long, default_value_t = 0, value_name = "L",
          value_parser = clap::value_parser!(u32).range(0..=i64::from(crate::estimators::MAX_LAG)))]
    pub lag: u32,
}

/// Where a command's estimators get their observations, which decides what it can run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feed {
    /// `eval`'s simulation, which also feeds the full-information oracles
    /// ([`Estimator::full_information`]) the observations from before the channel.
    Simulation,
    /// Slots (`run`, `demo`, `replay`): what came through the channel only, so no oracles.
    Slots,
}

impl EstimatorArgs {
    /// The particle count of `pf`: `--particles` when given, else 0 unless `--estimators`
    /// names `pf` or `pf-mix` (then the default count). The particle filter is opt-in for
    /// every command: it is the one estimator too slow for the others' time budget.
    pub fn particle_count(&self) -> usize {
        self.particles.unwrap_or(
            if self.estimators.iter().any(|n| n == "pf" || n == "pf-mix") {
                crate::estimators::pf::DEFAULT_PARTICLES
            } else {
                0
            },
        )
    }

    /// Evaluation options that build every estimator these flags can select (particles,
    /// loss rate, gate; no name filter), the rest defaults: the list [`Self::select`] picks
    /// from. Callers set the fields of their own flags with struct-update syntax.
    pub fn options(&self) -> EvalOptions {
        // Estimator families add fields to EvalOptions; the rest default.
        #[allow(clippy::needless_update)]
        EvalOptions {
            particles: self.particle_count(),
            estimators: Vec::new(),
            loss_rate: self.loss_rate,
            gate: self.gate,
            lag: self.lag,
            ..EvalOptions::default()
        }
    }

    /// The names (as built, in `built`'s order) of the estimators `--estimators` selects from
    /// `built` (what [`Self::options`] builds for `scenario`), for [`EvalOptions::estimators`].
    /// A wanted name selects the estimator of that name or its gated variant
    /// ([`names_match`]). Bad input, one line naming what is available: a name that
    /// selects nothing that `feed` can run, or an empty selection.
    pub fn select(
        &self,
        built: &[Box<dyn Estimator>],
        scenario: &str,
        feed: Feed,
    ) -> Result<Vec<String>, BadInput> {
        let available: Vec<&'static str> = built
            .iter()
            .filter(|e| feed == Feed::Simulation || !e.full_information())
            .map(|e| e.name())
            .collect();
        let listed = || {
            if available.is_empty() {
                "none".to_string()
            } else {
                available.join(", ")
            }
        };
        for n in &self.estimators {
            if available.iter().any(|a| names_match(a, n)) {
                continue;
            }
            let oracle = built
                .iter()
                .any(|e| names_match(e.name(), n) && e.full_information());
            let why = if oracle {
                "is a full-information oracle (offline `eval` only)".to_string()
            } else if n.ends_with("-mix") && self.loss_rate == 0.0 {
                // Both phrasings: the name's own need, and the rule for its family.
                "needs --loss-rate P (the -mix estimators need --loss-rate P)".to_string()
            } else if n.ends_with("+gate") && self.gate.is_none() {
                "needs --gate P".to_string()
            } else if (n == "pf" || n == "pf-mix") && self.particle_count() == 0 {
                "needs --particles N above 0".to_string()
            } else {
                format!("does not apply to scenario {scenario:?}")
            };
            return Err(BadInput(format!(
                "estimator {n:?} {why}; available: {}",
                listed()
            )));
        }
        let selected: Vec<String> = available
            .iter()
            .filter(|a| {
                self.estimators.is_empty() || self.estimators.iter().any(|n| names_match(a, n))
            })
            .map(|a| a.to_string())
            .collect();
        if selected.is_empty() {
            return Err(BadInput(format!(
                "no estimator selected: none {} to scenario {scenario:?}",
                match feed {
                    Feed::Simulation => "applies",
                    Feed::Slots => "that runs on slots applies",
                }
            )));
        }
        Ok(selected)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::{build_all, FACTORIES};

    fn select(args: &EstimatorArgs, feed: Feed) -> Result<Vec<String>, BadInput> {
        let spec = crate::source::preset_spec("occlusion");
        let options = EvalOptions {
            horizon: 10,
            ..args.options()
        };
        let built = build_all(FACTORIES, &spec, &options, &Default::default()).unwrap();
        args.select(&built, &spec.name, feed)
    }

    fn args(names: &[&str], gate: Option<f64>) -> EstimatorArgs {
        EstimatorArgs {
            estimators: names.iter().map(|n| n.to_string()).collect(),
            gate,
            ..EstimatorArgs::default()
        }
    }

    #[test]
    fn a_name_under_the_gate_selects_its_gated_variant_in_every_command() {
        for feed in [Feed::Simulation, Feed::Slots] {
            assert_eq!(
                select(&args(&["cce"], Some(0.99)), feed).unwrap(),
                ["cce+gate"]
            );
            assert_eq!(
                select(&args(&["adf+gate", "ikf"], Some(0.99)), feed).unwrap(),
                ["ikf+gate", "adf+gate"]
            );
        }
    }

    #[test]
    fn what_selects_nothing_is_bad_input_naming_why() {
        let e = select(&args(&["cce+gate"], None), Feed::Slots).unwrap_err();
        assert!(e.0.contains("\"cce+gate\" needs --gate P"), "{e}");
        let e = select(&args(&["nn"], Some(0.99)), Feed::Slots).unwrap_err();
        assert!(
            e.0.contains("\"nn\" does not apply to scenario \"occlusion\"; available: ikf+gate"),
            "{e}"
        );
        let e = select(&args(&["kf"], None), Feed::Slots).unwrap_err();
        assert!(e.0.contains("full-information oracle"), "{e}");
        assert_eq!(
            select(&args(&["kf"], None), Feed::Simulation).unwrap(),
            ["kf"]
        );
        let pf = EstimatorArgs {
            particles: Some(0),
            ..args(&["pf"], None)
        };
        let e = select(&pf, Feed::Slots).unwrap_err();
        assert!(e.0.contains("\"pf\" needs --particles N above 0"), "{e}");
        // Nothing built at all: an empty selection is refused, never an empty run.
        let e = args(&[], None)
            .select(&[], "occlusion", Feed::Slots)
            .unwrap_err();
        assert!(e.0.starts_with("no estimator selected"), "{e}");
    }
}
