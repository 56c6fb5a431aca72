//! `kf-silence` and `kf-sl`: the Kalman filter behind event-triggered nodes sharing a token
//! bucket, reading the silence of every held trigger (docs/tobit-fusion.md, "The linear case").
//!
//! **Definition.** estimator-core's [`SilenceKf`]: one prediction per instant, the Kalman
//! update with each delivered measurement, and for a node that sent nothing although the
//! receiver's mirror of the shared bucket says it had a token (its trigger held) the silence
//! update on its silence set `‖y − ȳ‖ < η̄/χ + σ` — the moment-matched truncated Gaussian on
//! the set's box (`kf-silence`) or the Sijs–Lazar pseudo-measurement (`kf-sl`); any other
//! silence is no information, as in `ikf`, which is the same filter ignoring every silence.
//!
//! Applies to a spec with a linear model and an event-trigger stage (`kind = "event-trigger"`)
//! but no Tobit censoring (the Tobit family's `*-silence` views handle that) and no declared
//! loss rate (a loss after the trigger would make a silence ambiguous). Diagnostics:
//! `trace_p`, and the cumulative counts `silence_held`, `silence_blocked`,
//! `silence_unusable` and the mirror's `mirror_unknown`, `mirror_mismatches`,
//! `mirror_resyncs`, `mirror_refused`.

use std::sync::Arc;

use estimator_core::filter::silence::kalman::SilenceKf;
use estimator_core::filter::silence::{SilenceCounts, SilenceForm};
use estimator_core::filter::KalmanFilter;
use estimator_core::protocol::bucket_mirror::MirrorCounts;
use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;
use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
use estimator_core::OnModel;
use estpipe_spec::{EstimatorSpec, LinearModel};
use nalgebra::SVector;

use super::adapter::{name, Adapted, Name};
use super::fed::{linear, on_model};
use super::snapshot::{fixed, Snapshot};
use super::{BuildOptions, RunStart};
use crate::Estimator;

/// The truncated-Gaussian view's name.
pub const TG_NAME: &str = "kf-silence";
/// The pseudo-measurement view's name.
pub const SL_NAME: &str = "kf-sl";

/// Builds `kf-silence` and `kf-sl` where they apply (empty otherwise).
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    if spec.linear().is_none()
        || spec.channel.event_trigger.is_none()
        || spec.channel.tobit.is_some()
        || options.loss_rate > 0.0
    {
        return Ok(Vec::new());
    }
    let (nx, ny, l) = (spec.nx(), spec.ny(), spec.nodes());
    let mut out = Vec::new();
    for (form, n) in [
        (SilenceForm::TruncatedGaussian, name!("kf-silence")),
        (SilenceForm::PseudoMeasurement, name!("kf-sl")),
    ] {
        macro_rules! by_l {
            ($nx:literal, $ny:literal) => {
                match l {
                    1 => boxed::<$nx, $ny, 1>(spec, form, n, options.gate),
                    2 => boxed::<$nx, $ny, 2>(spec, form, n, options.gate),
                    3 => boxed::<$nx, $ny, 3>(spec, form, n, options.gate),
                    _ => anyhow::bail!("{}: {l} nodes not supported (1..=3)", n.plain),
                }
            };
        }
        out.push(match (nx, ny) {
            (1, 1) => by_l!(1, 1),
            (2, 1) => by_l!(2, 1),
            (2, 2) => by_l!(2, 2),
            (3, 1) => by_l!(3, 1),
            (3, 2) => by_l!(3, 2),
            (4, 1) => by_l!(4, 1),
            (4, 2) => by_l!(4, 2),
            _ => anyhow::bail!(
                "{}: n_x = {nx}, n_y = {ny} not supported (n_x ≤ 4, n_y ≤ 2 are compiled in)",
                n.plain
            ),
        }?);
    }
    Ok(out)
}

type OnNodes<const NX: usize, const NY: usize, const L: usize> =
    OnModel<[Snapshot<NX, NY>; L], SilenceKf<f64, NX, NY, L>, NY>;

/// The input term of instant `k` in every node's model.
fn remodel<const NX: usize, const NY: usize, const L: usize>(
    on: &mut OnNodes<NX, NY, L>,
    model: &LinearModel,
    k: usize,
) {
    for m in &mut on.model {
        m.set_input(model, k);
    }
}

/// `trace_p` and the silence and mirror counts.
fn diagnostics<const NX: usize, const NY: usize, const L: usize>(
    on: &OnNodes<NX, NY, L>,
    sink: &mut dyn FnMut(&'static str, f64),
) {
    let f = &on.filter;
    sink("trace_p", f.estimate().covariance().trace());
    silence_counts(f.counts(), f.mirror().counts(), sink);
}

/// The cumulative silence and bucket-mirror counts of a silence-reading filter.
pub(super) fn silence_counts(
    c: SilenceCounts,
    m: MirrorCounts,
    sink: &mut dyn FnMut(&'static str, f64),
) {
    sink("silence_held", f64::from(c.held));
    sink("silence_blocked", f64::from(c.blocked));
    sink("silence_unusable", f64::from(c.unusable));
    sink("mirror_unknown", f64::from(m.unknown));
    sink("mirror_mismatches", f64::from(m.mismatches));
    sink("mirror_resyncs", f64::from(m.resyncs));
    sink("mirror_refused", f64::from(m.refused));
}

fn boxed<const NX: usize, const NY: usize, const L: usize>(
    spec: &Arc<EstimatorSpec>,
    form: SilenceForm,
    name: Name,
    gate: Option<f64>,
) -> anyhow::Result<Box<dyn Estimator>> {
    let what = |e: estimator_core::Error| anyhow::anyhow!("{}: {e}", name.plain);
    let trig = spec
        .channel
        .event_trigger
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("{}: no event trigger", name.plain))?;
    anyhow::ensure!(
        trig.nodes() == L,
        "{}: the event trigger must have one entry per node ({L})",
        name.plain
    );
    let mut nodes = Vec::with_capacity(L);
    for m in 0..L {
        let r = trig.reference(m);
        anyhow::ensure!(
            r.len() <= NY,
            "{}: node {m}'s reference has {} entries",
            name.plain,
            r.len()
        );
        let mut reference = SVector::<f64, NY>::zeros();
        reference.as_mut_slice()[..r.len()].copy_from_slice(r);
        nodes.push(TriggerKnowledge::new(*trig.trigger(m), reference).map_err(what)?);
    }
    let nodes: [TriggerKnowledge<f64, NY>; L] = core::array::from_fn(|m| nodes[m]);
    let (initial, rate, capacity) = trig.bucket();
    let costs: [u32; L] = core::array::from_fn(|m| trig.costs()[m]);
    let bucket = SharedTokenBucket::<L>::new(initial, rate, capacity, costs).map_err(what)?;
    let prior = &spec.prior;
    let kf = KalmanFilter::new(
        SVector::from_column_slice(prior.mean.as_slice()),
        fixed(&prior.cov),
    )
    .map_err(what)?;
    let model = Snapshot::nodes(linear(spec)?, L, 1);
    let on = OnModel::new(model, SilenceKf::new(kf, nodes, bucket, form));
    Ok(Box::new(
        Adapted::<_, NX>::new(name, on_model(on, spec, remodel::<NX, NY, L>))
            .with_diagnostics(diagnostics::<NX, NY, L>)
            .with_gate(gate)?,
    ))
}
