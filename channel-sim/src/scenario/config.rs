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

use nalgebra::{DMatrix, DVector};
use serde::Deserialize;

use super::composed::ComposedScenario;
use super::initial::InitialDistribution;
use crate::channel::event_trigger::{TriggerParams, TriggeredTokenBucket};
use crate::channel::loss::{BernoulliLoss, GilbertElliottLoss};
use crate::channel::occlusion::OcclusionSpec;
use crate::channel::tobit::TobitCensoring;
use crate::channel::token_bucket::TokenBucketStage;
use crate::channel::StageSpec;
use crate::error::ScenarioError;
use crate::plant::control::{Control, Schedule};
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
    /// A known control input (none: the plant is driven by noise only).
    pub control: Option<ControlConfig>,
}

/// `[control]`: `x_{k+1} = A x_k + B_u u_k + B w_k`, `u_k` known to the plant and to every
/// estimator's time update.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// B_u (nx × nu).
    pub b: Rows,
    /// The schedule of u_k.
    pub u: ScheduleConfig,
}

/// `[control.u]`, selected by `kind`.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ScheduleConfig {
    /// `kind = "constant"`: `u_k = value`.
    Constant {
        /// u (nu entries).
        value: Vec<f64>,
    },
    /// `kind = "sinusoid"`: `u_k = offset + amplitude · sin(2π k / period + phase)`.
    Sinusoid {
        /// Amplitude per entry.
        amplitude: Vec<f64>,
        /// Period in instants.
        period: f64,
        /// Phase in radians (default 0).
        #[serde(default)]
        phase: f64,
        /// Mean per entry (default 0).
        offset: Option<Vec<f64>>,
    },
    /// `kind = "list"`: `u_k = values[k mod len]`.
    List {
        /// The vectors, repeated cyclically.
        values: Vec<Vec<f64>>,
    },
}

impl ScheduleConfig {
    fn schedule(self) -> Schedule {
        match self {
            ScheduleConfig::Constant { value } => Schedule::Constant(value),
            ScheduleConfig::Sinusoid {
                amplitude,
                period,
                phase,
                offset,
            } => Schedule::Sinusoid {
                offset: offset.unwrap_or_else(|| vec![0.0; amplitude.len()]),
                amplitude,
                period,
                phase,
            },
            ScheduleConfig::List { values } => Schedule::List(values),
        }
    }
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
    /// `kind = "occlusion"`: state-dependent dropouts, seed 001 eqs. (2)-(3) — every packet of
    /// instant k is lost iff `u_k = e·x_k + n_k`, `n_k ~ N(0, psi)`, lies in one of the
    /// intervals `[centres[i] − radii[i], centres[i] + radii[i]]` (1 to
    /// [`MAX_OCCLUSION_REGIONS`], disjoint). The `occlusion` preset's stage is
    /// `e = [1, 0, 0]`, `psi = 0.1`, `centres = [20, 40, 60, 80]`, `radii = [5, 5, 5, 5]`.
    Occlusion(OcclusionToml),
}

/// The most occlusion regions a TOML stage may declare (the estimators are built per count).
pub const MAX_OCCLUSION_REGIONS: usize = 4;

/// `kind = "occlusion"`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcclusionToml {
    /// The row E of `u = E x + n` (n_x entries).
    pub e: Vec<f64>,
    /// Ψ, the variance of n (positive).
    pub psi: f64,
    /// ζ_i, the regions' centres.
    pub centres: Vec<f64>,
    /// r_i, the regions' half-widths (positive, one per centre).
    pub radii: Vec<f64>,
}

impl OcclusionToml {
    fn spec<const S: usize>(&self, nx: usize) -> Result<Arc<dyn StageSpec>, ScenarioError> {
        let arr = |v: &[f64]| -> [f64; S] { core::array::from_fn(|i| v[i]) };
        Ok(Arc::new(OcclusionSpec::<S>::new(
            self.e.clone(),
            self.psi,
            arr(&self.centres),
            arr(&self.radii),
            nx,
        )?))
    }
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
                    1 => o.spec::<1>(nx),
                    2 => o.spec::<2>(nx),
                    3 => o.spec::<3>(nx),
                    _ => o.spec::<4>(nx),
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
                Arc::new(TobitCensoring::new(t.thresholds).map_err(|e| at(field, e))?)
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

/// Largest scenario file read (bytes). A scenario is a few kB (the largest part, an 8 × 8
/// matrix, a few hundred bytes); TOML parsing holds about 50× the text, so without a bound
/// `--config /dev/zero` or an 80 MB file grew until the allocator aborted the process.
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;

/// Reads and validates a scenario file (at most [`MAX_SCENARIO_BYTES`]).
pub fn load(path: &Path) -> Result<ComposedScenario, ScenarioError> {
    use std::io::Read as _;
    let shown = path.display().to_string();
    let fail = |reason: String| ScenarioError::File {
        path: shown.clone(),
        reason,
    };
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_SCENARIO_BYTES + 1).read_to_end(&mut bytes))
        .map_err(|e| fail(e.to_string()))?;
    if bytes.len() as u64 > MAX_SCENARIO_BYTES {
        return Err(fail(format!(
            "larger than {} KiB; a scenario file is a few kB",
            MAX_SCENARIO_BYTES >> 10
        )));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        fail(format!(
            "not UTF-8 text (byte {})",
            e.utf8_error().valid_up_to()
        ))
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
    let mut plant = LinearPlant::new(a.into(), b.into(), q, sensors)?;
    if let Some(c) = &file.control {
        let bu = matrix(&c.b, "control.b")?;
        plant = plant.with_control(Control::new(bu, c.u.clone().schedule(), nx)?)?;
    }

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
    check_overflow(&plant, &initial, &file)?;

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

/// Instants over which the overflow check of [`build`] follows the model's moments.
pub const OVERFLOW_CHECK_STEPS: usize = 20;

/// The largest magnitude a moment may reach in the overflow check of [`build`]: f64's range
/// less a margin of 10⁸ for the estimators' own sums and products of those moments (an MSE
/// sums squared errors over runs; a Joseph update adds congruences).
pub const MOMENT_LIMIT: f64 = 1e300;

/// Refuses a model whose numbers are finite but whose products are not: from both priors
/// (the truth's `initial.cov` and the estimators' `initial.estimator_cov`) the mean and
/// covariance of x_k, `E‖x_k‖²`, and every node's `C x_k` and `C Σ_k Cᵀ + D R Dᵀ` must stay
/// within [`MOMENT_LIMIT`] for k = 0..[`OVERFLOW_CHECK_STEPS`]; otherwise every run would end
/// in NaN ("diverged") or a later error. The field named is the input with the largest entry
/// among those the failing product used (1e308 in `model.a` names `model.a`).
fn check_overflow(
    plant: &LinearPlant,
    initial: &InitialDistribution,
    file: &ScenarioFile,
) -> Result<(), ScenarioError> {
    use crate::plant::{LinearDescription, Plant};
    let amax = |rows: &[Vec<f64>]| rows.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
    let vmax = |v: &[f64]| v.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut model_fields: Vec<(String, f64)> = vec![
        ("model.a".into(), amax(&file.model.a)),
        ("model.q".into(), amax(&file.model.q)),
    ];
    if let Some(b) = &file.model.b {
        model_fields.push(("model.b".into(), amax(b)));
    }
    if let Some(c) = &file.control {
        model_fields.push(("control.b".into(), amax(&c.b)));
        let u = match &c.u {
            ScheduleConfig::Constant { value } => vmax(value),
            ScheduleConfig::Sinusoid {
                amplitude, offset, ..
            } => vmax(amplitude) + offset.as_deref().map_or(0.0, vmax),
            ScheduleConfig::List { values } => values.iter().map(|v| vmax(v)).fold(0.0, f64::max),
        };
        model_fields.push(("control.u".into(), u));
    }
    for (m, s) in file.sensors.iter().enumerate() {
        model_fields.push((format!("sensors[{m}].c"), amax(&s.c)));
        model_fields.push((format!("sensors[{m}].r"), amax(&s.r)));
        if let Some(d) = &s.d {
            model_fields.push((format!("sensors[{m}].d"), amax(d)));
        }
    }
    let ok = |m: &[f64]| m.iter().all(|v| v.is_finite() && v.abs() <= MOMENT_LIMIT);
    let priors = [
        (
            &initial.mean,
            &initial.cov,
            "initial.mean",
            "initial.cov",
            file.initial.cov.as_slice(),
        ),
        (
            &initial.estimator_mean,
            &initial.estimator_cov,
            "initial.estimator_mean",
            "initial.estimator_cov",
            file.initial
                .estimator_cov
                .as_deref()
                .unwrap_or(file.initial.cov.as_slice()),
        ),
    ];
    for (mean, cov, mean_field, cov_field, cov_rows) in priors {
        let mut blame = model_fields.clone();
        blame.push((mean_field.into(), vmax(mean.as_slice())));
        blame.push((cov_field.into(), amax(cov_rows)));
        let fail = |k: usize, what: &str| {
            let (field, v) = blame
                .iter()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .cloned()
                .unwrap_or_default();
            ScenarioError::invalid(
                field,
                format!(
                    "entries up to {v:e} make {what} overflow f64 by k = {k} (beyond \
                     {MOMENT_LIMIT:e}); scale the model down"
                ),
            )
        };
        let (mut m, mut s) = (mean.clone(), cov.clone());
        for k in 0..=OVERFLOW_CHECK_STEPS {
            let second = s.trace() + m.norm_squared();
            if !(ok(m.as_slice())
                && ok(s.as_slice())
                && second.is_finite()
                && second <= MOMENT_LIMIT)
            {
                return Err(fail(k, "the state's mean or covariance"));
            }
            for node in 0..plant.nodes() {
                let c = plant.c(node, k);
                let sy = &c * &s * c.transpose() + plant.measurement_cov(node, k);
                if !(ok((&c * &m).as_slice()) && ok(sy.as_slice())) {
                    return Err(fail(k, "the measurement's mean or covariance"));
                }
            }
            let (a, q) = (plant.a(k), plant.process_cov(k));
            if !ok(q.as_slice()) {
                return Err(fail(k, "B Q Bᵀ"));
            }
            m = &a * m;
            if let Some(bu) = plant.input(k) {
                m += bu;
            }
            s = &a * s * a.transpose() + q;
        }
    }
    Ok(())
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

/// A TOML error as one line: `line L (`key`): message`, with the key assigned on that line.
/// The parser's message names the value's problem, not always the field, and inside a
/// `[[stages]]` table (a tagged enum) it points at the table: then the line is the first one
/// from there whose value holds the literal the message quotes (`-3` in "invalid value:
/// integer `-3`, expected u32").
fn one_line(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    let Some(span) = e.span() else {
        return msg;
    };
    let start = span.start.min(text.len());
    let mut line = text[..start].matches('\n').count() + 1;
    fn key_of(source: &str) -> Option<(&str, &str)> {
        source
            .split_once('=')
            .map(|(k, v)| (k.trim(), v))
            .filter(|(k, _)| {
                !k.is_empty()
                    && k.len() <= 40
                    && k.chars()
                        .all(|c| c.is_alphanumeric() || "_-.\"".contains(c))
            })
    }
    let quoted = msg.split('`').nth(1).filter(|q| !q.is_empty());
    if let Some(q) = quoted {
        if let Some((i, _)) = text.lines().enumerate().skip(line - 1).find(|(_, l)| {
            key_of(l).is_some_and(|(_, v)| v.split('#').next().unwrap_or("").contains(q))
        }) {
            line = i + 1;
        }
    }
    match text.lines().nth(line - 1).and_then(key_of) {
        Some((key, _)) => format!("line {line} (`{key}`): {msg}"),
        None => format!("line {line}: {msg}"),
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
