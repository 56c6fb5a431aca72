//! `tobit-kf`, `tobit-cmm` and `tobit-cmm-held`: centralised filters of every node's
//! censored packets that carry a covariance, beside seed 004's federated filters
//! (docs/tobit-fusion.md, "At the information bound").
//!
//! **Definitions.**
//! * `tobit-kf` (baseline): estimator-core's [`TobitKf`], the Tobit Kalman filter of Allik et
//!   al. (2016) over all nodes' delivered packets, the prediction on any silence.
//! * `tobit-cmm` (product): [`MomentMatchedTobit`] without the silence: the Kalman update with
//!   every observed component and the exact moment-matched truncation with every censored one,
//!   using the full prediction covariance; a silence is no information.
//! * `tobit-cmm-held` (product): the same filter reading every silence the receiver's mirror
//!   of the shared bucket calls held, with the truncated-Gaussian update on the node's silence
//!   box intersected with the censoring region.
//!
//! `tobit-kf` applies to a spec with a linear model and Tobit censoring thresholds; the two
//! `tobit-cmm` filters also need the event-trigger stage (σ_m, χ_m, λ_m, η_{m,0}, the shared
//! bucket), and `tobit-cmm-held` is not built when the spec declares a loss rate (a loss
//! after the trigger makes a silence ambiguous in a way the mirror cannot see). Their P is
//! the error covariance (not a bound): diagnostics `trace_p`, and in evaluation `nees`,
//! `inside_95`; the `tobit-cmm` filters add the cumulative `silence_held`, `silence_blocked`,
//! `silence_unusable` and the mirror's counts.

use std::sync::Arc;

use estimator_core::filter::tobit::{MomentMatchedTobit, TobitKf};
use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;
use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
use estimator_core::{Estimate, OnModel};
use estpipe_spec::{EstimatorSpec, LinearModel};
use nalgebra::SVector;

use super::adapter::{name, Adapted};
use super::fed::{linear, on_model};
use super::snapshot::{fixed, Snapshot};
use super::{BuildOptions, RunStart};
use crate::Estimator;

/// The practitioner's Tobit Kalman filter.
pub const TOBIT_KF_NAME: &str = "tobit-kf";
/// The moment-matched filter, silences ignored.
pub const CMM_NAME: &str = "tobit-cmm";
/// The moment-matched filter reading held silences.
pub const CMM_SILENCE_NAME: &str = "tobit-cmm-held";

/// Builds the views that apply to `spec` (none without Tobit censoring).
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    if spec.linear().is_none() || spec.channel.tobit.is_none() {
        return Ok(Vec::new());
    }
    let (nx, ny, l) = (spec.nx(), spec.ny(), spec.nodes());
    if let Some(m) = (0..l).find(|&m| spec.node_ny(m) != ny) {
        anyhow::bail!(
            "tobit-kf: the centralised Tobit filters need the same n_y at every node, but \
             node {m} measures {} and another {ny} components",
            spec.node_ny(m)
        );
    }
    macro_rules! by_l {
        ($nx:literal, $ny:literal) => {
            match l {
                1 => views::<$nx, $ny, 1>(spec, options),
                2 => views::<$nx, $ny, 2>(spec, options),
                3 => views::<$nx, $ny, 3>(spec, options),
                4 => views::<$nx, $ny, 4>(spec, options),
                _ => anyhow::bail!("tobit-kf: {l} nodes not supported (1..=4 are compiled in)"),
            }
        };
    }
    match (nx, ny) {
        (1, 1) => by_l!(1, 1),
        (2, 1) => by_l!(2, 1),
        (2, 2) => by_l!(2, 2),
        (3, 1) => by_l!(3, 1),
        (3, 2) => by_l!(3, 2),
        (3, 3) => by_l!(3, 3),
        _ => anyhow::bail!(
            "tobit-kf: n_x = {nx}, n_y = {ny} not supported (n_x ≤ 3, n_y ≤ n_x are compiled in)"
        ),
    }
}

/// Every view that applies, in the order of the tables: `tobit-kf`, `tobit-cmm`,
/// `tobit-cmm-held`.
fn views<const NX: usize, const NY: usize, const L: usize>(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let tau = thresholds::<NY, L>(spec)?;
    let prior = prior::<NX>(spec)?;
    let model = Snapshot::nodes(linear(spec)?, L, 1);
    let kf = OnModel::new(
        model,
        TobitKf::new(prior, tau).map_err(named(TOBIT_KF_NAME))?,
    );
    let mut out: Vec<Box<dyn Estimator>> = vec![Box::new(
        Adapted::<_, NX>::new(name!("tobit-kf"), on_model(kf, spec, remodel))
            .with_nees()
            .with_gate(options.gate)?,
    )];
    if spec.channel.event_trigger.is_none() {
        return Ok(out);
    }
    let mut cmm = vec![(false, name!("tobit-cmm"))];
    if options.loss_rate <= 0.0 {
        cmm.push((true, name!("tobit-cmm-held")));
    }
    for (reads_silence, n) in cmm {
        let filter = moment_matched::<NX, NY, L>(spec, prior, tau, reads_silence)
            .map_err(|e| anyhow::anyhow!("{}: {e}", n.plain))?;
        let on = OnModel::new(model, filter);
        out.push(Box::new(
            Adapted::<_, NX>::new(n, on_model(on, spec, remodel))
                .with_diagnostics(diagnostics::<NX, NY, L>)
                .with_nees()
                .with_gate(options.gate)?,
        ));
    }
    Ok(out)
}

/// The error of a view's construction, named.
fn named(view: &'static str) -> impl Fn(estimator_core::Error) -> anyhow::Error {
    move |e| anyhow::anyhow!("{view}: {e}")
}

/// Every node's τ_m.
fn thresholds<const NY: usize, const L: usize>(
    spec: &EstimatorSpec,
) -> anyhow::Result<[SVector<f64, NY>; L]> {
    let censoring = spec
        .channel
        .tobit
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("tobit-kf: no censoring thresholds"))?;
    anyhow::ensure!(
        censoring.nodes() == L,
        "tobit-kf: the censoring stage must have one entry per node ({L})"
    );
    let mut tau = [SVector::<f64, NY>::zeros(); L];
    for (m, t) in tau.iter_mut().enumerate() {
        let given = censoring.tau(m);
        anyhow::ensure!(
            given.len() == NY,
            "tobit-kf: tau of node {m} must have {NY} entries"
        );
        *t = SVector::from_column_slice(given);
    }
    Ok(tau)
}

/// The spec's prior.
fn prior<const NX: usize>(spec: &EstimatorSpec) -> anyhow::Result<Estimate<f64, NX>> {
    Estimate::new(
        SVector::from_column_slice(spec.prior.mean.as_slice()),
        fixed(&spec.prior.cov),
    )
    .map_err(|e| anyhow::anyhow!("tobit-kf: initial prior: {e}"))
}

/// A fresh moment-matched filter with the receiver's knowledge of every trigger and the
/// mirror of the shared bucket.
fn moment_matched<const NX: usize, const NY: usize, const L: usize>(
    spec: &EstimatorSpec,
    prior: Estimate<f64, NX>,
    tau: [SVector<f64, NY>; L],
    reads_silence: bool,
) -> anyhow::Result<MomentMatchedTobit<f64, NX, NY, L>> {
    let trig = spec
        .channel
        .event_trigger
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("no event trigger"))?;
    anyhow::ensure!(
        trig.nodes() == L,
        "the event trigger must have one entry per node ({L})"
    );
    let mut nodes = [TriggerKnowledge::new(*trig.trigger(0), tau[0])?; L];
    for (m, node) in nodes.iter_mut().enumerate() {
        let r = trig.reference(m);
        anyhow::ensure!(
            r.len() <= NY,
            "node {m}'s reference has {} entries",
            r.len()
        );
        let mut reference = SVector::<f64, NY>::zeros();
        reference.as_mut_slice()[..r.len()].copy_from_slice(r);
        *node = TriggerKnowledge::new(*trig.trigger(m), reference)?;
    }
    let (initial, rate, capacity) = trig.bucket();
    let costs: [u32; L] = core::array::from_fn(|m| trig.costs()[m]);
    let bucket = SharedTokenBucket::<L>::new(initial, rate, capacity, costs)?;
    Ok(MomentMatchedTobit::new(
        prior,
        tau,
        nodes,
        bucket,
        reads_silence,
    )?)
}

type CmmOnNodes<const NX: usize, const NY: usize, const L: usize> =
    OnModel<[Snapshot<NX, NY>; L], MomentMatchedTobit<f64, NX, NY, L>, NY>;

/// The input term of instant `k` in every node's model (either filter on the nodes' models).
fn remodel<F, const NX: usize, const NY: usize, const L: usize>(
    on: &mut OnModel<[Snapshot<NX, NY>; L], F, NY>,
    model: &LinearModel,
    k: usize,
) {
    for m in &mut on.model {
        m.set_input(model, k);
    }
}

/// `trace_p` and the silence and mirror counts.
fn diagnostics<const NX: usize, const NY: usize, const L: usize>(
    on: &CmmOnNodes<NX, NY, L>,
    sink: &mut dyn FnMut(&'static str, f64),
) {
    let f = &on.filter;
    sink("trace_p", f.estimate().covariance().trace());
    super::silence_kf::silence_counts(f.counts(), f.mirror().counts(), sink);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_three_views_for_the_preset_and_none_without_censoring() {
        let s = crate::presets::preset_spec("tobit-fusion");
        let names = |o: &BuildOptions| -> Vec<&'static str> {
            build(&s, o, &RunStart::default())
                .unwrap()
                .iter()
                .map(|e| e.name())
                .collect()
        };
        assert_eq!(
            names(&BuildOptions::default()),
            ["tobit-kf", "tobit-cmm", "tobit-cmm-held"]
        );
        let lossy = BuildOptions {
            loss_rate: 0.1,
            ..BuildOptions::default()
        };
        assert_eq!(names(&lossy), ["tobit-kf", "tobit-cmm"]);
        let lin = crate::presets::preset_spec("linear");
        assert!(build(&lin, &BuildOptions::default(), &RunStart::default())
            .unwrap()
            .is_empty());
    }
}
