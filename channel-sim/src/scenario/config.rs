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
//! Stage kinds: `bernoulli`, `gilbert-elliott`, `token-bucket` (seed 003), `tobit` and
//! `event-trigger` (seed 004; triggers sharing one token bucket), see [`StageConfig`].
//!
//! Matrices are arrays of rows. A stage kind is one variant of [`StageConfig`]: adding a kind
//! is one variant (its spec type deriving `Deserialize`, `#[serde(deny_unknown_fields)]`) and
//! one arm in [`StageConfig::into_spec`] that validates it, naming fields as
//! `{field}.<name>` (e.g. `stages[2].b`), and a case in this file's test that each bad field
//! is rejected. Accepted parameters that break a paper's own assumption are reported through
//! `StageSpec::warnings`, which `eval` prints.

use std::path::Path;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use serde::Deserialize;

use super::composed::ComposedScenario;
use super::initial::InitialDistribution;
use crate::channel::event_trigger::{TriggerParams, TriggeredTokenBucket};
use crate::channel::loss::{BernoulliLoss, GilbertElliottLoss};
use crate::channel::tobit::TobitCensoring;
use crate::channel::token_bucket::TokenBucketStage;
use crate::channel::StageSpec;
use crate::error::ScenarioError;
use crate::plant::linear::{LinearPlant, LinearSensor};
use crate::validate::check_finite;

/// A matrix as an array of rows.
pub type Rows = Vec<Vec<f64>>;

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
}

/// `[model]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// A (nx × nx).
    pub a: Rows,
    /// B (nx × nw); default I.
    pub b: Option<Rows>,
    /// Q (nw × nw), symmetric positive definite.
    pub q: Rows,
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

/// `[[sensors]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    /// C (ny × nx).
    pub c: Rows,
    /// D (ny × nv); default I.
    pub d: Option<Rows>,
    /// R (nv × nv), symmetric positive definite.
    pub r: Rows,
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
}

/// `kind = "tobit"`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TobitConfig {
    /// τ_m per node, one entry per measurement component.
    pub thresholds: Vec<Vec<f64>>,
}

/// `kind = "event-trigger"`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventTriggerToml {
    /// Tokens in the shared bucket at k = 0.
    pub initial_tokens: u32,
    /// Tokens added per instant.
    pub rate: u32,
    /// Bucket capacity.
    pub capacity: u32,
    /// Accept λχ ≤ 1 (the seed 004 example does); every eval then prints a warning.
    #[serde(default)]
    pub allow_paper_violation: bool,
    /// One table per node.
    pub nodes: Vec<TriggerNodeToml>,
}

/// One node of `kind = "event-trigger"`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TriggerNodeToml {
    /// σ_m.
    pub sigma: f64,
    /// χ_m.
    pub chi: f64,
    /// λ_m.
    pub lambda: f64,
    /// η_{m,0}.
    pub eta0: f64,
    /// Initial reference measurement ȳ (e.g. the censoring threshold τ_m).
    pub reference: Vec<f64>,
    /// Tokens one transmission of this node costs.
    pub cost: u32,
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
                .trim_start_matches("trigger");
            ScenarioError::invalid(format!("{field}{inner}"), reason)
        }
        other => ScenarioError::invalid(field, other.to_string()),
    }
}

impl StageConfig {
    /// Validates the stage (fields named under `field`) and returns its spec.
    pub fn into_spec(self, field: &str) -> Result<Arc<dyn StageSpec>, ScenarioError> {
        Ok(match self {
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
                Arc::new(TobitCensoring::new(t.thresholds).map_err(|e| at(field, e))?)
            }
            StageConfig::EventTrigger(t) => {
                let params: Vec<TriggerParams> = t
                    .nodes
                    .iter()
                    .map(|n| TriggerParams {
                        sigma: n.sigma,
                        chi: n.chi,
                        lambda: n.lambda,
                        eta0: n.eta0,
                    })
                    .collect();
                Arc::new(
                    TriggeredTokenBucket::new(
                        &params,
                        t.nodes.iter().map(|n| n.reference.clone()).collect(),
                        t.initial_tokens,
                        t.rate,
                        t.capacity,
                        t.nodes.iter().map(|n| n.cost).collect(),
                        t.allow_paper_violation,
                    )
                    .map_err(|e| at(field, e))?,
                )
            }
        })
    }
}

/// Reads and validates a scenario file.
pub fn load(path: &Path) -> Result<ComposedScenario, ScenarioError> {
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::File {
        path: shown.clone(),
        reason: e.to_string(),
    })?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "config".into());
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
    build(file, default_name)
}

/// Builds the scenario from a parsed file.
pub fn build(file: ScenarioFile, default_name: &str) -> Result<ComposedScenario, ScenarioError> {
    let a = matrix(&file.model.a, "model.a")?;
    let nx = a.nrows();
    let q = matrix(&file.model.q, "model.q")?;
    let b = match &file.model.b {
        Some(b) => matrix(b, "model.b")?,
        None => DMatrix::identity(nx, nx),
    };
    let mut sensors = Vec::with_capacity(file.sensors.len());
    for (m, s) in file.sensors.iter().enumerate() {
        let c = matrix(&s.c, &format!("sensors[{m}].c"))?;
        let r = matrix(&s.r, &format!("sensors[{m}].r"))?;
        let d = match &s.d {
            Some(d) => matrix(d, &format!("sensors[{m}].d"))?,
            None => DMatrix::identity(c.nrows(), c.nrows()),
        };
        sensors.push(LinearSensor {
            c: c.into(),
            d: d.into(),
            r,
        });
    }
    let plant = LinearPlant::new(a.into(), b.into(), q, sensors)?;

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

    let stages = file
        .stages
        .into_iter()
        .enumerate()
        .map(|(i, s)| s.into_spec(&format!("stages[{i}]")))
        .collect::<Result<Vec<_>, _>>()?;
    let name = file.name.unwrap_or_else(|| default_name.to_owned());
    ComposedScenario::new(name, Arc::new(plant), initial, stages)
}

/// A dense matrix from rows; errors unless non-empty, rectangular and finite.
pub fn matrix(rows: &Rows, field: &str) -> Result<DMatrix<f64>, ScenarioError> {
    let cols = rows.first().map_or(0, Vec::len);
    if cols == 0 {
        return Err(ScenarioError::invalid(
            field,
            "must be a non-empty array of rows",
        ));
    }
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
        return Err(ScenarioError::invalid(
            field,
            format!("row {i} has {} entries, row 0 has {cols}", r.len()),
        ));
    }
    let m = DMatrix::from_fn(rows.len(), cols, |i, j| rows[i][j]);
    check_finite(&m, field)?;
    Ok(m)
}

/// A TOML error as one line: `line L: message`.
fn one_line(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            format!("line {line}: {msg}")
        }
        None => msg,
    }
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
