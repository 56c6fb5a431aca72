//! Refusing a model whose numbers are finite but whose products are not: from each prior the
//! mean and covariance of x_k, `E‖x_k‖²`, and every node's `C x_k` and `C Σ_k Cᵀ + D R Dᵀ`
//! must stay within [`MOMENT_LIMIT`] for k = 0..[`OVERFLOW_CHECK_STEPS`]; otherwise every run
//! would end in NaN ("diverged") or a later error. The field named is the input with the
//! largest entry among those the failing product used (1e308 in `model.a` names `model.a`).

use nalgebra::{DMatrix, DVector};

use crate::error::SpecError;
use crate::file::{ControlConfig, ModelConfig, Rows, ScheduleConfig, SensorConfig};
use crate::linear::LinearModel;

/// Instants over which the overflow check follows the model's moments.
pub const OVERFLOW_CHECK_STEPS: usize = 20;

/// The largest magnitude a moment may reach in the overflow check: f64's range less a margin
/// of 10⁸ for the estimators' own sums and products of those moments (an MSE sums squared
/// errors over runs; a Joseph update adds congruences).
pub const MOMENT_LIMIT: f64 = 1e300;

/// The model's fields as written, for naming the one to blame.
#[derive(Clone, Copy, Debug)]
pub struct Written<'a> {
    /// `[model]`.
    pub model: &'a ModelConfig,
    /// `[control]`.
    pub control: Option<&'a ControlConfig>,
    /// `[[sensors]]`.
    pub sensors: &'a [SensorConfig],
}

/// One prior to follow: its mean and covariance, their field names, and the covariance as
/// written.
#[derive(Clone, Copy, Debug)]
pub struct FromPrior<'a> {
    /// The mean.
    pub mean: &'a DVector<f64>,
    /// The covariance.
    pub cov: &'a DMatrix<f64>,
    /// The mean's field (`initial.mean`, `prior.mean`).
    pub mean_field: &'a str,
    /// The covariance's field.
    pub cov_field: &'a str,
    /// The covariance as written.
    pub cov_rows: &'a Rows,
}

/// The check of the module documentation, from every prior in `priors`.
pub fn check(
    model: &LinearModel,
    written: Written<'_>,
    priors: &[FromPrior<'_>],
) -> Result<(), SpecError> {
    let model_fields = model_fields(written);
    let mut input = vec![0.0; model.nx()];
    for p in priors {
        let Err((k, what)) = follow(model, p, &mut input) else {
            continue;
        };
        let mut blame = model_fields.clone();
        blame.push((p.mean_field.into(), vmax(p.mean.as_slice())));
        blame.push((p.cov_field.into(), amax(p.cov_rows)));
        let (field, v) = blame
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .cloned()
            .unwrap_or_default();
        return Err(SpecError::invalid(
            field,
            format!(
                "entries up to {v:e} make {what} overflow f64 by k = {k} (beyond \
                 {MOMENT_LIMIT:e}); scale the model down"
            ),
        ));
    }
    Ok(())
}

/// The largest magnitude in `rows`.
fn amax(rows: &[Vec<f64>]) -> f64 {
    rows.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The largest magnitude in `v`.
fn vmax(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// Every model field as written with its largest magnitude (the input `u`: its largest over
/// the schedule), the candidates to blame.
fn model_fields(written: Written<'_>) -> Vec<(String, f64)> {
    let mut model_fields: Vec<(String, f64)> = vec![
        ("model.a".into(), amax(&written.model.a)),
        ("model.q".into(), amax(&written.model.q)),
    ];
    if let Some(b) = &written.model.b {
        model_fields.push(("model.b".into(), amax(b)));
    }
    if let Some(c) = written.control {
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
    for (m, s) in written.sensors.iter().enumerate() {
        model_fields.push((format!("sensors[{m}].c"), amax(&s.c)));
        model_fields.push((format!("sensors[{m}].r"), amax(&s.r)));
        if let Some(d) = &s.d {
            model_fields.push((format!("sensors[{m}].d"), amax(d)));
        }
    }
    model_fields
}

/// Follows the moments from prior `p` for k = 0..[`OVERFLOW_CHECK_STEPS`]; the first instant
/// and product that leave the limit. `input` is scratch for the known input.
fn follow(
    model: &LinearModel,
    p: &FromPrior<'_>,
    input: &mut [f64],
) -> Result<(), (usize, &'static str)> {
    let ok = |m: &[f64]| m.iter().all(|v| v.is_finite() && v.abs() <= MOMENT_LIMIT);
    let (mut m, mut s) = (p.mean.clone(), p.cov.clone());
    for k in 0..=OVERFLOW_CHECK_STEPS {
        let second = s.trace() + m.norm_squared();
        if !(ok(m.as_slice()) && ok(s.as_slice()) && second.is_finite() && second <= MOMENT_LIMIT) {
            return Err((k, "the state's mean or covariance"));
        }
        for node in 0..model.nodes() {
            let c = model.c(node);
            let sy = c * &s * c.transpose() + model.measurement_cov(node);
            if !(ok((c * &m).as_slice()) && ok(sy.as_slice())) {
                return Err((k, "the measurement's mean or covariance"));
            }
        }
        let (a, q) = (model.a(), model.process_cov());
        if !ok(q.as_slice()) {
            return Err((k, "B Q Bᵀ"));
        }
        m = a * m;
        if model.input_into(k, input) {
            m += DVector::from_column_slice(input);
        }
        s = a * s * a.transpose() + q;
    }
    Ok(())
}
