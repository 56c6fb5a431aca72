use std::sync::Arc;

use estpipe_spec::EstimatorSpec;
use estpipe_wire::Observation;

use crate::{ikf, kf, nn, occlusion, pf, pf_tobit, silence_kf, tobit, tobit_central, Estimator};

/// What a run's estimators are built for beyond the spec: the seed and run index (the
/// particle filters draw their own random streams from them) and the observations of instant
/// 0 of a model whose sensors measure at k = 0 (seed 003's y₀, docs/design.md "Seed 003";
/// `None` otherwise, and for a stream whose y₀ the receiver cannot know).
#[derive(Clone, Copy, Debug, Default)]
pub struct RunStart<'a> {
    /// Experiment seed.
    pub seed: u64,
    /// Run index.
    pub run: u64,
    /// The observations of instant 0, node by node, if the run has them.
    pub initial: Option<&'a [Observation]>,
}

/// What the factories build beyond the spec: the options of `eval`, `run` and `replay` that
/// choose or shape estimators. Families add their own fields (with a default in [`Default`])
/// and the matching CLI flag.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Particles of the `pf` reference filters (0 disables them).
    pub particles: usize,
    /// The estimators to build, by name (empty: every one that applies). [`build_all`]
    /// keeps only these; a name no family builds is not an error here (the commands check
    /// their `--estimators` against what applies).
    pub estimators: Vec<String>,
    /// `p_loss` of the occlusion estimators' known-loss-rate option (`--loss-rate`): above 0,
    /// `cce-mix`, `kf-io-mix`, `adf-mix` (and `pf-mix` when `pf` runs) read a dropout as
    /// "occluded, or lost in transport with probability `p_loss`" beside the estimators that
    /// read it as occluded (docs/occlusion.md, "Losses"). 0 builds none of them.
    pub loss_rate: f64,
    /// Probability `P` of the innovation gate (`--gate P`, docs/gate.md): every estimator
    /// with an innovation runs behind the χ² gate of `P` and is named `<name>+gate`; its
    /// diagnostics `gate_tested`, `gate_rejected` count the measurements so far. `None`: no
    /// gate, the estimators of today, bit for bit.
    pub gate: Option<f64>,
    /// `--lag L` (docs/pipeline.md, "Late packets"): the estimators keep the last
    /// [`MAX_LAG`](crate::MAX_LAG) instants and fold in a slot that arrives up to `L` instants
    /// late, as if it had come on time. 0: no history, the estimators of today, bit for bit.
    pub lag: u32,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            particles: pf::DEFAULT_PARTICLES,
            estimators: Vec::new(),
            loss_rate: 0.0,
            gate: None,
            lag: 0,
        }
    }
}

impl From<&BuildOptions> for BuildOptions {
    fn from(options: &BuildOptions) -> Self {
        options.clone()
    }
}

/// The `--gate P` flag's value: a probability in `(0, 1)` (docs/gate.md).
pub fn gate_probability(s: &str) -> Result<f64, String> {
    let p: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if p.is_finite() && p > 0.0 && p < 1.0 {
        Ok(p)
    } else {
        Err(format!("{s} is not a probability in (0, 1)"))
    }
}

/// `name` is what `--estimators` asked for by `wanted`: the same name, or `wanted` gated
/// (`cce` selects `cce+gate` under `--gate P`).
pub fn names_match(name: &str, wanted: &str) -> bool {
    name == wanted || name.strip_suffix("+gate") == Some(wanted)
}

/// `(tested, rejected)` of an estimator's innovation gate so far (its diagnostics
/// `gate_tested`, `gate_rejected`), or `None` for an ungated estimator.
pub fn gate_counts(est: &dyn Estimator) -> Option<(u64, u64)> {
    let (mut tested, mut rejected) = (None, None);
    est.diagnostics(&mut |name, v| match name {
        "gate_tested" => tested = Some(v as u64),
        "gate_rejected" => rejected = Some(v as u64),
        _ => {}
    });
    Some((tested?, rejected?))
}

/// Builds a family's estimators for `spec` and the run `start` (empty when the family does not
/// apply). An error means the spec's parameters are unusable for this family.
pub type Factory = fn(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>>;

/// Every estimator family, in the order they appear in tables, JSON and plots.
pub const FACTORIES: &[Factory] = &[
    kf::build,
    ikf::build,
    occlusion::build,
    pf::build,
    nn::build,
    tobit::build,
    tobit_central::build,
    pf_tobit::build,
    silence_kf::build,
];

/// All estimators that apply to `spec`, from `factories` in order; only those named in
/// `options.estimators` when it is not empty. The spec's own loss rate and gate apply where
/// `options` sets none (a flag overrides the file). `options` is a [`BuildOptions`] or what
/// a command turns into one (`eval`'s options).
pub fn build_all(
    factories: &[Factory],
    spec: &Arc<EstimatorSpec>,
    options: impl Into<BuildOptions>,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let options: BuildOptions = options.into();
    let options = &BuildOptions {
        loss_rate: match options.loss_rate {
            0.0 => spec.loss_rate.unwrap_or(0.0),
            p => p,
        },
        gate: options.gate.or(spec.gate),
        ..options.clone()
    };
    let mut all = Vec::new();
    for f in factories {
        all.extend(f(spec, options, start)?);
    }
    if !options.estimators.is_empty() {
        // `--estimators cce --gate P` selects `cce+gate`.
        all.retain(|e| options.estimators.iter().any(|n| names_match(e.name(), n)));
    }
    if options.lag > 0 {
        for e in &mut all {
            e.set_lag(options.lag);
        }
    }
    Ok(all)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every estimator of every preset, `-mix` and `pf` included, keeps its whole name in the
    /// wire's estimate slot (docs/wire.md); the gated ones (`+gate`, cut on the wire when
    /// longer) stay distinct in what a subscriber reads.
    #[test]
    fn every_built_in_name_fits_the_wire_name_field() {
        let field = estpipe_wire::Estimate::none_yet(0, Default::default())
            .name
            .len();
        for (preset, _) in channel_sim::scenario::presets::PRESETS {
            let spec = crate::presets::preset_spec(preset);
            for gate in [None, Some(0.99)] {
                let spec = Arc::new((*spec).clone().with_gate(gate).unwrap());
                let options = BuildOptions {
                    particles: 10,
                    loss_rate: 0.2,
                    ..BuildOptions::default()
                };
                let all = build_all(FACTORIES, &spec, &options, &RunStart::default()).unwrap();
                let mut cut: Vec<&[u8]> = all
                    .iter()
                    .map(|e| &e.name().as_bytes()[..e.name().len().min(field)])
                    .collect();
                if gate.is_none() {
                    let long: Vec<_> = all.iter().filter(|e| e.name().len() > field).collect();
                    assert!(
                        long.is_empty(),
                        "{preset}: {:?}",
                        long.iter().map(|e| e.name()).collect::<Vec<_>>()
                    );
                }
                cut.sort();
                let n = cut.len();
                cut.dedup();
                assert_eq!(cut.len(), n, "{preset}: names cut on the wire collide");
            }
        }
    }

    /// A spec's own `gate` and `loss_rate` build the gated and `-mix` estimators as the flags
    /// do; a flag given on the command line wins over the file's value.
    #[test]
    fn the_specs_gate_and_loss_rate_apply_unless_a_flag_is_given() {
        let names = |spec: &EstimatorSpec, options: &BuildOptions| -> Vec<&'static str> {
            let spec = Arc::new(spec.clone());
            build_all(FACTORIES, &spec, options, &RunStart::default())
                .unwrap()
                .iter()
                .map(|e| e.name())
                .collect()
        };
        let plain = BuildOptions {
            particles: 0,
            ..BuildOptions::default()
        };
        let spec = (*crate::presets::preset_spec("occlusion")).clone();
        let with = spec
            .clone()
            .with_gate(Some(0.99))
            .unwrap()
            .with_loss_rate(Some(0.2))
            .unwrap();
        assert_eq!(names(&spec, &plain), ["kf", "ikf", "cce", "kf-io", "adf"]);
        let from_file = names(&with, &plain);
        assert_eq!(
            from_file,
            [
                "kf+gate",
                "ikf+gate",
                "cce+gate",
                "kf-io+gate",
                "adf+gate",
                "cce-mix+gate",
                "kf-io-mix+gate",
                "adf-mix+gate"
            ]
        );
        // The flags' values: the same names, and the estimates of the flags' gate (a 0.5 gate
        // rejects far more than the file's 0.99 on the same instants).
        let flags = BuildOptions {
            gate: Some(0.5),
            loss_rate: 0.2,
            ..plain.clone()
        };
        assert_eq!(names(&spec, &flags), from_file);
        let rejected = |spec: &EstimatorSpec, options: &BuildOptions| -> u64 {
            let spec = Arc::new(spec.clone());
            let mut ests = build_all(FACTORIES, &spec, options, &RunStart::default()).unwrap();
            let (_, mut sim) = crate::presets::preset_run("occlusion", 1, 0);
            for _ in 0..200 {
                let i = sim.next_instant();
                let _ = ests[1].step(i.k, &i.obs);
            }
            gate_counts(&*ests[1]).unwrap().1
        };
        assert!(rejected(&with, &flags) > rejected(&with, &plain));
    }
}
