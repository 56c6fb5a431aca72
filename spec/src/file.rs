//! The TOML form of an [`EstimatorSpec`], every field validated with an error naming it, and
//! the TOML parts a simulated scenario file shares with it (`[model]`, `[control]`,
//! `[[sensors]]`, the channel effects the estimators know of).
//!
//! ```toml
//! name = "tracker"                     # optional, defaults to the file stem
//! [model]                              # x_{k+1} = A x_k + B w_k, w_k ~ N(0, Q)
//! a = [[0.95, 0.1], [-0.1, 0.95]]
//! b = [[1.0, 0.0], [0.0, 1.0]]         # optional, default I (then Q is nx×nx)
//! q = [[0.01, 0.0], [0.0, 0.04]]
//! [prior]                              # the estimators' x̂₀ and P₀
//! mean = [0.0, 0.0]
//! cov = [[1.0, 0.0], [0.0, 1.0]]
//! [[sensors]]                          # one table per node: z = C x + D v, v ~ N(0, R)
//! c = [[1.0, 0.0]]
//! r = [[0.25]]                         # d optional, default I
//! ```
//!
//! Optional: `[control]` (a known input, as in a scenario file), what the estimators know of
//! the channel (`[occlusion]`, `[token_bucket]`, `[tobit]`, `[event_trigger]`, each with the
//! fields of the scenario file's stage of that kind), `loss_rate` and `gate`. A scenario file's
//! simulation sections (`[initial]` of the truth, `[[stages]]`) have no place here: a spec
//! says what the estimators know, not what the world does. docs/pipeline.md, "Estimator
//! specs", has the whole format.

use std::path::Path;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use serde::Deserialize;

use crate::channel::{
    ChannelKnowledge, Occlusion, TobitCensoring, TokenBucket, TriggerParams, TriggeredTokenBucket,
};
use crate::control::{Control, Schedule};
use crate::error::SpecError;
use crate::linear::{LinearModel, Sensor};
use crate::overflow::{self, FromPrior, Written};
use crate::validate::{check_finite, check_shape};
use crate::{EstimatorSpec, Model, Prior};

/// A matrix as an array of rows.
pub type Rows = Vec<Vec<f64>>;

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
    /// The schedule this table describes.
    pub fn schedule(self) -> Schedule {
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

/// The most occlusion regions a TOML stage may declare (the estimators are built per count).
pub use crate::channel::MAX_OCCLUSION_REGIONS;

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
    /// Accept λχ ≤ 1 (the seed 004 example does); `eval`, and `run`/`replay` of a spec file,
    /// then print a warning.
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

/// A dense matrix from rows; errors unless non-empty, rectangular and finite.
pub fn matrix(rows: &Rows, field: &str) -> Result<DMatrix<f64>, SpecError> {
    let cols = rows.first().map_or(0, Vec::len);
    if cols == 0 {
        return Err(SpecError::invalid(
            field,
            "must be a non-empty array of rows",
        ));
    }
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != cols) {
        return Err(SpecError::invalid(
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
pub fn one_line(text: &str, e: &toml::de::Error) -> String {
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

/// The linear model of `[model]`, `[[sensors]]` and `[control]`, validated.
pub fn linear_model(
    model: &ModelConfig,
    sensors: &[SensorConfig],
    control: Option<&ControlConfig>,
) -> Result<LinearModel, SpecError> {
    let a = matrix(&model.a, "model.a")?;
    let nx = a.nrows();
    let q = matrix(&model.q, "model.q")?;
    let b = match &model.b {
        Some(b) => matrix(b, "model.b")?,
        None => DMatrix::identity(nx, nx),
    };
    let mut out = Vec::with_capacity(sensors.len());
    for (m, s) in sensors.iter().enumerate() {
        let c = matrix(&s.c, &format!("sensors[{m}].c"))?;
        let r = matrix(&s.r, &format!("sensors[{m}].r"))?;
        let d = match &s.d {
            Some(d) => matrix(d, &format!("sensors[{m}].d"))?,
            None => DMatrix::identity(c.nrows(), c.nrows()),
        };
        out.push(Sensor { c, d, r });
    }
    let mut linear = LinearModel::new(a, b, q, out)?;
    if let Some(c) = control {
        let bu = matrix(&c.b, "control.b")?;
        linear = linear.with_control(Control::new(bu, c.u.clone().schedule(), nx)?)?;
    }
    Ok(linear)
}

impl OcclusionToml {
    /// The occlusion model of this table, validated against n_x.
    pub fn knowledge(&self, nx: usize) -> Result<Occlusion, SpecError> {
        Occlusion::new(
            self.e.clone(),
            self.psi,
            self.centres.clone(),
            self.radii.clone(),
            nx,
        )
    }
}

impl EventTriggerToml {
    /// The triggers and the shared bucket of this table, validated (node counts and reference
    /// lengths are checked against the model by [`EstimatorSpec::new`]).
    pub fn knowledge(&self) -> Result<TriggeredTokenBucket, SpecError> {
        let params: Vec<TriggerParams> = self
            .nodes
            .iter()
            .map(|n| TriggerParams {
                sigma: n.sigma,
                chi: n.chi,
                lambda: n.lambda,
                eta0: n.eta0,
            })
            .collect();
        TriggeredTokenBucket::new(
            &params,
            self.nodes.iter().map(|n| n.reference.clone()).collect(),
            self.initial_tokens,
            self.rate,
            self.capacity,
            self.nodes.iter().map(|n| n.cost).collect(),
            self.allow_paper_violation,
        )
    }
}

/// `[prior]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorConfig {
    /// x̂₀.
    pub mean: Vec<f64>,
    /// P₀, symmetric positive definite.
    pub cov: Rows,
}

/// A whole spec file (see the module documentation).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecFile {
    /// A name for reports (defaults to the file stem).
    pub name: Option<String>,
    /// The model.
    pub model: ModelConfig,
    /// A known control input.
    pub control: Option<ControlConfig>,
    /// One entry per sensor node.
    pub sensors: Vec<SensorConfig>,
    /// The estimators' prior.
    pub prior: PriorConfig,
    /// Seed 001's occlusion regions.
    pub occlusion: Option<OcclusionToml>,
    /// Seed 003's token bucket per node.
    pub token_bucket: Option<TokenBucket>,
    /// Seed 004's Tobit censoring thresholds.
    pub tobit: Option<TobitConfig>,
    /// Seed 004's event triggers sharing one token bucket.
    pub event_trigger: Option<EventTriggerToml>,
    /// A known loss rate in `[0, 1)` (`--loss-rate` overrides it).
    pub loss_rate: Option<f64>,
    /// The innovation gate's probability in `(0, 1)` (`--gate` overrides it).
    pub gate: Option<f64>,
}

/// Re-roots an error of a part (`invalid `occlusion.psi`: …`) at the table it came from
/// (`invalid `event_trigger.nodes[0]`: …` for the trigger's `trigger.nodes[0]`).
fn under(table: &str, e: SpecError) -> SpecError {
    match e {
        SpecError::Invalid { field, reason } => {
            let rest = field
                .trim_start_matches("tobit")
                .trim_start_matches("trigger")
                .trim_start_matches("occlusion")
                .trim_start_matches("bucket");
            SpecError::invalid(format!("{table}{rest}"), reason)
        }
        other => other,
    }
}

/// Builds the spec of a parsed file.
pub fn build(file: SpecFile, default_name: &str) -> Result<EstimatorSpec, SpecError> {
    let linear = linear_model(&file.model, &file.sensors, file.control.as_ref())?;
    let nx = linear.nx();
    let mean = DVector::from_vec(file.prior.mean.clone());
    if mean.len() != nx {
        return Err(SpecError::invalid(
            "prior.mean",
            format!("must have nx = {nx} entries, got {}", mean.len()),
        ));
    }
    let cov = matrix(&file.prior.cov, "prior.cov")?;
    // Before the overflow check, which multiplies by it (a 3×3 P₀ for n_x = 2 panicked there).
    check_shape(cov.shape(), (nx, nx), "prior.cov")?;
    check_finite(
        &DMatrix::from_column_slice(nx, 1, mean.as_slice()),
        "prior.mean",
    )?;
    let mut channel = ChannelKnowledge::default();
    if let Some(o) = &file.occlusion {
        channel.occlusion = Some(o.knowledge(nx).map_err(|e| under("occlusion", e))?);
    }
    if let Some(b) = file.token_bucket {
        b.config("token_bucket")?;
        channel.token_bucket = Some(b);
    }
    if let Some(t) = &file.tobit {
        channel.tobit =
            Some(TobitCensoring::new(t.thresholds.clone()).map_err(|e| under("tobit", e))?);
    }
    if let Some(t) = &file.event_trigger {
        channel.event_trigger = Some(t.knowledge().map_err(|e| under("event_trigger", e))?);
    }
    overflow::check(
        &linear,
        Written {
            model: &file.model,
            control: file.control.as_ref(),
            sensors: &file.sensors,
        },
        &[FromPrior {
            mean: &mean,
            cov: &cov,
            mean_field: "prior.mean",
            cov_field: "prior.cov",
            cov_rows: &file.prior.cov,
        }],
    )?;
    let name = file.name.unwrap_or_else(|| default_name.to_owned());
    EstimatorSpec::new(name, Model::Linear(linear), Prior { mean, cov }, channel)?
        .with_loss_rate(file.loss_rate)?
        .with_gate(file.gate)
}

/// Largest spec or scenario file read (bytes). A spec is a few kB (the largest part, an 8 × 8
/// matrix, a few hundred bytes); TOML parsing holds about 50× the text, so without a bound
/// `--estimator-spec /dev/zero` or an 80 MB file would grow until the allocator aborts.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// The text of a TOML file of at most [`MAX_FILE_BYTES`], its stem (the default name); `what`
/// ("scenario", "spec") goes into the size error.
pub fn read_bounded(path: &Path, what: &str) -> Result<(String, String), SpecError> {
    use std::io::Read as _;
    let shown = path.display().to_string();
    let fail = |reason: String| SpecError::File {
        path: shown.clone(),
        reason,
    };
    // Opening a FIFO waits for a writer that may never come: refused before the open, as a
    // socket is (a device such as /dev/zero is read within the bound below).
    if let Ok(m) = std::fs::metadata(path) {
        use std::os::unix::fs::FileTypeExt as _;
        let t = m.file_type();
        if t.is_fifo() || t.is_socket() {
            return Err(fail(format!(
                "a FIFO or socket, not a {what} file (give the file itself)"
            )));
        }
    }
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_FILE_BYTES + 1).read_to_end(&mut bytes))
        .map_err(|e| fail(e.to_string()))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(fail(format!(
            "larger than {} KiB; a {what} file is a few kB",
            MAX_FILE_BYTES >> 10
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
    Ok((text, stem))
}

/// Reads and validates a spec file (at most [`MAX_FILE_BYTES`]); every error is one line
/// naming the file, then the line or field.
pub fn load(path: &Path) -> Result<Arc<EstimatorSpec>, SpecError> {
    let (text, stem) = read_bounded(path, "spec")?;
    parse(&text, &path.display().to_string(), &stem).map(Arc::new)
}

/// Parses and validates spec TOML; `origin` names the source in errors.
pub fn parse(text: &str, origin: &str, default_name: &str) -> Result<EstimatorSpec, SpecError> {
    let file: SpecFile = toml::from_str(text).map_err(|e| SpecError::File {
        path: origin.to_owned(),
        reason: one_line(text, &e),
    })?;
    build(file, default_name).map_err(|e| match e {
        e @ SpecError::File { .. } => e,
        e => SpecError::File {
            path: origin.to_owned(),
            reason: e.to_string(),
        },
    })
}
