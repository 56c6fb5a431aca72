//! Scenarios from a TOML file, every field validated with an error naming it.
//!
//! ```toml
//! name = "example"                     # optional, defaults to the file stem
//! [model]                              # x_{k+1} = A x_k + B w_k, w_k ~ N(0, Q)
//! a = [[0.95, 0.1], [-0.1, 0.95]]
//! b = [[1.0, 0.0], [0.0, 1.0]]         # optional, default I (then Q is nx×nx)
//! q = [[0.01, 0.0], [0.0, 0.04]]
//! [initial]                            # x_0 ~ N(mean, cov); estimators start from
//! mean = [0.0, 0.0]                    # (estimator_mean, estimator_cov), default (mean, cov)
//! cov = [[1.0, 0.0], [0.0, 1.0]]
//! [[sensors]]                          # one table per node: z = C x + D v, v ~ N(0, R)
//! c = [[1.0, 0.0]]
//! r = [[0.25]]                         # d optional, default I
//! [[stages]]                           # channel stages, applied in this order
//! kind = "bernoulli"
//! p_loss = 0.2
//! ```
//!
//! A known control input, `x_{k+1} = A x_k + B_u u_k + B w_k` (u_k known to the plant and to
//! every estimator's time update):
//!
//! ```toml
//! [control]
//! b = [[0.0], [1.0]]                   # B_u (nx × nu)
//! u = { kind = "sinusoid", amplitude = [2.0], period = 50.0 }   # phase, offset optional
//! # or u = { kind = "constant", value = [1.0] }
//! # or u = { kind = "list", values = [[1.0], [0.0], [-1.0]] }  # repeated cyclically
//! ```
//!
//! Stage kinds: `bernoulli`, `gilbert-elliott`, `occlusion` (seed 001's state-dependent
//! dropouts), `token-bucket` (seed 003), `tobit` and `event-trigger` (seed 004; triggers
//! sharing one token bucket), see [`StageConfig`]. `scenarios/occlusion.toml` is the
//! `occlusion` preset as a file.
//!
//! Matrices are arrays of rows. A stage kind is one variant of [`StageConfig`]: adding a kind
//! is one variant (its spec type deriving `Deserialize`, `#[serde(deny_unknown_fields)]`) and
//! one arm in [`StageConfig::into_spec`] that validates it, naming fields as
//! `{field}.<name>` (e.g. `stages[2].b`), and a case in this file's test that each bad field
//! is rejected. Accepted parameters that break a paper's own assumption are reported through
//! `StageSpec::warnings`, which `eval` prints.

use std::path::Path;
use std::sync::Arc;

use estpipe_spec::file::linear_model;
pub use estpipe_spec::file::{
    matrix, one_line, ControlConfig, EventTriggerToml, ModelConfig, OcclusionToml, Rows,
    ScheduleConfig, SensorConfig, TobitConfig, TriggerNodeToml, MAX_OCCLUSION_REGIONS,
};
use estpipe_spec::overflow::{self, FromPrior, Written};
use nalgebra::DVector;
use serde::Deserialize;

use super::composed::ComposedScenario;
use super::initial::InitialDistribution;
use crate::channel::loss::{BernoulliLoss, GilbertElliottLoss};
use crate::channel::occlusion::OcclusionSpec;
use crate::channel::tobit::TobitCensoring;
use crate::channel::token_bucket::TokenBucketStage;
use crate::channel::StageSpec;
use crate::error::ScenarioError;
use crate::plant::linear::LinearPlant;

/// The whole file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Scenario name (defaults to the file stem).
    pub name: Option<String>,
    /// The plant.
    pub model: ModelConfig,
    /// x_0's distribution and the estimators' prior.
    pub initial: InitialConfig,
    /// One entry per sensor node.
    pub sensors: Vec<SensorConfig>,
    /// Channel stages in application order (none: a perfect channel).
    #[serde(default)]
    pub stages: Vec<StageConfig>,
    /// A known control input (none: the plant is driven by noise only).
    pub control: Option<ControlConfig>,
}

/// `[initial]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialConfig {
    /// Mean of x_0.
    pub mean: Vec<f64>,
    /// Covariance of x_0 (positive semi-definite; all zeros = known start).
    pub cov: Rows,
    /// x̂_0 (default `mean`).
    pub estimator_mean: Option<Vec<f64>>,
    /// P_0 (default `cov`), positive definite.
    pub estimator_cov: Option<Rows>,
}

/// `[[stages]]`, selected by `kind`.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum StageConfig {
    /// `kind = "bernoulli"`: [`BernoulliLoss`].
    Bernoulli(BernoulliLoss),
    /// `kind = "gilbert-elliott"`: [`GilbertElliottLoss`].
    GilbertElliott(GilbertElliottLoss),
    /// `kind = "token-bucket"`: one bucket per node, seed 003 eq. (2) (`a`, `b`, `s`, `z0`;
    /// the paper requires a ≥ 1, b ≥ a, S ≥ b).
    TokenBucket(TokenBucketStage),
    /// `kind = "tobit"`: censoring below `thresholds[m]` (τ_m), seed 004 eq. (2).
    Tobit(TobitConfig),
    /// `kind = "event-trigger"`: dynamic event triggers sharing one token bucket, seed 004
    /// eqs. (11)-(20). λχ ≤ 1 is refused unless `allow_paper_violation = true` (then warned).
    EventTrigger(EventTriggerToml),
    /// `kind = "occlusion"`: state-dependent dropouts, seed 001 eqs. (2)-(3) — every packet of
    /// instant k is lost iff `u_k = e·x_k + n_k`, `n_k ~ N(0, psi)`, lies in one of the
    /// intervals `[centres[i] − radii[i], centres[i] + radii[i]]` (1 to
    /// [`MAX_OCCLUSION_REGIONS`], disjoint). The `occlusion` preset's stage is
    /// `e = [1, 0, 0]`, `psi = 0.1`, `centres = [20, 40, 60, 80]`, `radii = [5, 5, 5, 5]`.
    Occlusion(OcclusionToml),
}

/// The occlusion stage of `o` at `S` regions.
fn occlusion_stage<const S: usize>(
    o: &OcclusionToml,
    nx: usize,
) -> Result<Arc<dyn StageSpec>, ScenarioError> {
    let arr = |v: &[f64]| -> [f64; S] { core::array::from_fn(|i| v[i]) };
    Ok(Arc::new(OcclusionSpec::<S>::new(
        o.e.clone(),
        o.psi,
        arr(&o.centres),
        arr(&o.radii),
        nx,
    )?))
}

/// The plant's dimensions, which every stage is checked against.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlantDims {
    /// n_x.
    pub nx: usize,
    /// n_y of every node, in node order.
    pub ny: Vec<usize>,
}

impl PlantDims {
    /// The dimensions of `plant`.
    pub fn of(plant: &dyn crate::plant::Plant) -> Self {
        Self {
            nx: plant.nx(),
            ny: (0..plant.nodes()).map(|m| plant.node_ny(m)).collect(),
        }
    }

    /// The number of sensor nodes.
    pub fn nodes(&self) -> usize {
        self.ny.len()
    }

    /// Errors unless `{field}.{list}` has one entry per sensor node.
    fn per_node(&self, field: &str, list: &str, got: usize) -> Result<(), ScenarioError> {
        let nodes = self.nodes();
        if got == nodes {
            return Ok(());
        }
        Err(ScenarioError::invalid(
            format!("{field}.{list}"),
            format!("must have one entry per sensor node ({nodes} `[[sensors]]`), got {got}"),
        ))
    }

    /// Errors unless the vector `field` of node `m` has that node's ny entries.
    fn node_vector(&self, field: &str, m: usize, got: usize) -> Result<(), ScenarioError> {
        let ny = self.ny[m];
        if got == ny {
            return Ok(());
        }
        Err(ScenarioError::invalid(
            field,
            format!("must have ny = {ny} entries (the rows of sensors[{m}].c), got {got}"),
        ))
    }
}

/// Re-roots an error of a stage constructor (`invalid `trigger.nodes[0]`: why`) at the
/// stage's TOML path (`invalid `stages[2].nodes[0]`: why`).
fn at(field: &str, e: ScenarioError) -> ScenarioError {
    match e {
        ScenarioError::Invalid {
            field: inner,
            reason,
        } => {
            let inner = inner
                .trim_start_matches("tobit")
                .trim_start_matches("trigger")
                .trim_start_matches("occlusion");
            ScenarioError::invalid(format!("{field}{inner}"), reason)
        }
        other => ScenarioError::invalid(field, other.to_string()),
    }
}

impl StageConfig {
    /// Validates the stage (fields named under `field`) against the plant's dimensions and
    /// returns its spec.
    pub fn into_spec(
        self,
        field: &str,
        dims: &PlantDims,
    ) -> Result<Arc<dyn StageSpec>, ScenarioError> {
        Ok(match self {
            StageConfig::Occlusion(o) => {
                let n = o.centres.len();
                if n == 0 || n > MAX_OCCLUSION_REGIONS {
                    return Err(ScenarioError::invalid(
                        format!("{field}.centres"),
                        format!("must have 1 to {MAX_OCCLUSION_REGIONS} entries, got {n}"),
                    ));
                }
                if o.radii.len() != n {
                    return Err(ScenarioError::invalid(
                        format!("{field}.radii"),
                        format!(
                            "must have one entry per centre ({n}), got {}",
                            o.radii.len()
                        ),
                    ));
                }
                let nx = dims.nx;
                match n {
                    1 => occlusion_stage::<1>(&o, nx),
                    2 => occlusion_stage::<2>(&o, nx),
                    3 => occlusion_stage::<3>(&o, nx),
                    _ => occlusion_stage::<4>(&o, nx),
                }
                .map_err(|e| at(field, e))?
            }
            StageConfig::Bernoulli(s) => {
                s.validate(field)?;
                Arc::new(s)
            }
            StageConfig::GilbertElliott(s) => {
                s.validate(field)?;
                Arc::new(s)
            }
            StageConfig::TokenBucket(s) => {
                s.config(field)?;
                Arc::new(s)
            }
            StageConfig::Tobit(t) => {
                dims.per_node(field, "thresholds", t.thresholds.len())?;
                for (m, tau) in t.thresholds.iter().enumerate() {
                    dims.node_vector(&format!("{field}.thresholds[{m}]"), m, tau.len())?;
                }
                Arc::new(TobitCensoring::new(t.thresholds).map_err(|e| at(field, e.into()))?)
            }
            StageConfig::EventTrigger(t) => {
                dims.per_node(field, "nodes", t.nodes.len())?;
                for (m, n) in t.nodes.iter().enumerate() {
                    dims.node_vector(
                        &format!("{field}.nodes[{m}].reference"),
                        m,
                        n.reference.len(),
                    )?;
                }
                Arc::new(t.knowledge().map_err(|e| at(field, e.into()))?)
            }
        })
    }
}

/// Largest scenario file read (bytes): the spec's bound, for the same reason
/// ([`estpipe_spec::file::MAX_FILE_BYTES`]).
pub const MAX_SCENARIO_BYTES: u64 = estpipe_spec::file::MAX_FILE_BYTES;

/// Reads and validates a scenario file (at most [`MAX_SCENARIO_BYTES`]).
pub fn load(path: &Path) -> Result<ComposedScenario, ScenarioError> {
    let (text, stem) = estpipe_spec::file::read_bounded(path, "scenario")?;
    let shown = path.display().to_string();
    parse(&text, &shown, &stem)
}

/// Parses and validates scenario TOML; `origin` names the source in errors, `default_name` is
/// used when the file has no `name`.
pub fn parse(
    text: &str,
    origin: &str,
    default_name: &str,
) -> Result<ComposedScenario, ScenarioError> {
    let file: ScenarioFile = toml::from_str(text).map_err(|e| ScenarioError::File {
        path: origin.to_owned(),
        reason: one_line(text, &e),
    })?;
    // Every error of a file names the file, then the field.
    build(file, default_name).map_err(|e| match e {
        e @ ScenarioError::File { .. } => e,
        e => ScenarioError::File {
            path: origin.to_owned(),
            reason: e.to_string(),
        },
    })
}

/// Builds the scenario from a parsed file.
pub fn build(file: ScenarioFile, default_name: &str) -> Result<ComposedScenario, ScenarioError> {
    let plant = LinearPlant::of(linear_model(
        &file.model,
        &file.sensors,
        file.control.as_ref(),
    )?);
    let nx = plant.model().nx();

    let init = &file.initial;
    let mean = DVector::from_vec(init.mean.clone());
    if mean.len() != nx {
        return Err(ScenarioError::invalid(
            "initial.mean",
            format!("must have nx = {nx} entries, got {}", mean.len()),
        ));
    }
    let cov = matrix(&init.cov, "initial.cov")?;
    let est_mean = init
        .estimator_mean
        .clone()
        .map(DVector::from_vec)
        .unwrap_or_else(|| mean.clone());
    let est_cov = match &init.estimator_cov {
        Some(p) => matrix(p, "initial.estimator_cov")?,
        None => cov.clone(),
    };
    let initial = InitialDistribution::new(mean, cov, est_mean, est_cov)?;
    let written = Written {
        model: &file.model,
        control: file.control.as_ref(),
        sensors: &file.sensors,
    };
    let estimator_cov_rows = file
        .initial
        .estimator_cov
        .as_ref()
        .unwrap_or(&file.initial.cov);
    overflow::check(
        plant.model(),
        written,
        &[
            FromPrior {
                mean: &initial.mean,
                cov: &initial.cov,
                mean_field: "initial.mean",
                cov_field: "initial.cov",
                cov_rows: &file.initial.cov,
            },
            FromPrior {
                mean: &initial.estimator_mean,
                cov: &initial.estimator_cov,
                mean_field: "initial.estimator_mean",
                cov_field: "initial.estimator_cov",
                cov_rows: estimator_cov_rows,
            },
        ],
    )?;

    let dims = PlantDims::of(&plant);
    let stages = file
        .stages
        .into_iter()
        .enumerate()
        .map(|(i, s)| s.into_spec(&format!("stages[{i}]"), &dims))
        .collect::<Result<Vec<_>, _>>()?;
    let name = file.name.unwrap_or_else(|| default_name.to_owned());
    ComposedScenario::new(name, Arc::new(plant), initial, stages)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Scenario;

    const EXAMPLE: &str = include_str!("../../scenarios/example.toml");

    #[test]
    fn example_file_loads() {
        let s = load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenarios/example.toml"
        )))
        .unwrap();
        assert_eq!(s.name(), "example");
        assert_eq!((s.nx(), s.ny(), s.nodes()), (2, 1, 2));
        assert_eq!(s.stages().len(), 2);
        assert!(s.stage::<GilbertElliottLoss>().is_some());
    }

    /// Replaces the first occurrence of `from` in the example and expects an error whose text
    /// contains `needle`.
    fn rejects(from: &str, to: &str, needle: &str) {
        assert!(EXAMPLE.contains(from), "example has no {from:?}");
        let text = EXAMPLE.replacen(from, to, 1);
        let err = parse(&text, "example.toml", "example")
            .unwrap_err()
            .to_string();
        assert!(err.contains(needle), "expected {needle:?} in {err:?}");
        assert!(!err.contains('\n'), "not one line: {err:?}");
    }

    #[test]
    fn each_kind_of_bad_field_is_named() {
        // Wrong matrix sizes.
        rejects(
            "a = [[0.95, 0.10], [-0.10, 0.95]]",
            "a = [[0.95, 0.10]]",
            "model.a",
        );
        rejects(
            "a = [[0.95, 0.10], [-0.10, 0.95]]",
            "a = [[0.95, 0.10], [1.0]]",
            "model.a",
        );
        rejects("c = [[1.0, 0.0]]", "c = [[1.0, 0.0, 0.0]]", "sensors[0].c");
        rejects("mean = [0.0, 0.0]", "mean = [0.0]", "initial.mean");
        // Non-PD / non-symmetric covariances.
        rejects(
            "q = [[0.01, 0.0], [0.0, 0.04]]",
            "q = [[0.01, 0.0], [0.0, -0.04]]",
            "model.q",
        );
        rejects(
            "q = [[0.01, 0.0], [0.0, 0.04]]",
            "q = [[0.01, 0.5], [0.0, 0.04]]",
            "model.q",
        );
        rejects("r = [[0.25]]", "r = [[0.0]]", "sensors[0].r");
        rejects(
            "cov = [[1.0, 0.0], [0.0, 1.0]]",
            "cov = [[1.0, 2.0], [2.0, 1.0]]",
            "initial.cov",
        );
        // Probabilities outside [0, 1].
        rejects("p_loss = 0.1", "p_loss = 1.1", "stages[0].p_loss");
        rejects(
            "p_bad_to_good = 0.3",
            "p_bad_to_good = -0.3",
            "stages[1].p_bad_to_good",
        );
        // Unknown fields and kinds, type errors: the TOML parser names them with the line.
        rejects("p_loss = 0.1", "p_los = 0.1", "p_los");
        rejects("kind = \"bernoulli\"", "kind = \"teleport\"", "teleport");
        rejects("p_loss = 0.1", "p_loss = \"high\"", "line");
    }

    /// Appends one stage table to the example and parses it.
    fn with_stage(stage: &str) -> Result<ComposedScenario, ScenarioError> {
        parse(
            &format!("{EXAMPLE}\n[[stages]]\n{stage}\n"),
            "example.toml",
            "example",
        )
    }

    #[test]
    fn paper_stages_load_and_their_constraints_are_named() {
        // Token bucket (seed 003): a ≥ 1, b ≥ a, S ≥ b.
        let ok = "kind = \"token-bucket\"\na = 2\nb = 3\ns = 10\nz0 = 6";
        assert_eq!(with_stage(ok).unwrap().stages().len(), 3);
        for (bad, field) in [("a = 2", "a = 0"), ("b = 3", "b = 1"), ("s = 10", "s = 2")]
            .map(|(from, to)| (ok.replacen(from, to, 1), to.split(' ').next().unwrap()))
        {
            let e = with_stage(&bad).unwrap_err().to_string();
            assert!(e.contains(&format!("stages[2].{field}")), "{e}");
        }
        // Tobit censoring: finite thresholds, one per measurement component.
        assert!(with_stage("kind = \"tobit\"\nthresholds = [[0.5], [0.5]]").is_ok());
        let e = with_stage("kind = \"tobit\"\nthresholds = [[0.5], [0.5, 1.0]]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("stages[2].thresholds[1]"), "{e}");
        // Event trigger: λχ ≤ 1 refused by default, accepted (with a warning) on opt-in.
        let trig = |lambda: f64, opt_in: bool| {
            format!(
                "kind = \"event-trigger\"\ninitial_tokens = 3\nrate = 2\ncapacity = 6\n\
                 allow_paper_violation = {opt_in}\n\
                 [[stages.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = {lambda}\neta0 = 1.0\n\
                 reference = [0.0]\ncost = 1\n\
                 [[stages.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = {lambda}\neta0 = 1.0\n\
                 reference = [0.0]\ncost = 1"
            )
        };
        let s = with_stage(&trig(0.5, false)).unwrap();
        assert!(s.warnings().is_empty());
        let e = with_stage(&trig(0.1, false)).unwrap_err().to_string();
        assert!(
            e.contains("stages[2].nodes[0]") && e.contains("lambda"),
            "{e}"
        );
        let s = with_stage(&trig(0.1, true)).unwrap();
        assert_eq!(s.warnings().len(), 2, "{:?}", s.warnings());
    }
}
