//! `tobit-1` … `tobit-l` and `fused`: the federated Tobit Kalman fusion filter of seed 004
//! (estimator-core's [`TobitFusion`]: local Tobit filters (21)-(23), (30), (37), fusion (50),
//! reset (51), Algorithm 1).
//!
//! **Definition.** One fusion filter per run; `fused` reports x̂^g_{k|k}, and `tobit-m`
//! reports node m's local estimate x̂_{m,k|k} *before* the reset (51), as in the paper's
//! Figs. 5-10. The views share one filter (it steps once per instant, whichever view asks
//! first), so they are always consistent with each other.
//!
//! Beside them, `tobit-1-predict` … `tobit-l-predict` and `fused-predict` are the same views
//! of a second fusion filter whose local filters only predict at an instant without a
//! measurement ([`Silence::Predict`], the product's option; docs/tobit-fusion.md, "Predict
//! on silence"), where the paper updates with the held measurement.
//!
//! Beside those, two fusion filters read the trigger's silence (docs/tobit-fusion.md,
//! "Silence that speaks"): their local filters update a silence that the receiver's mirror of
//! the shared bucket calls held (the node had a token, so its trigger did not fire) with the
//! silence set intersected with the censoring region, and predict on any other silence —
//! `tobit-1-silence` … `tobit-l-silence`, `fused-silence` with the moment-matched truncated
//! Gaussian ([`Silence::TruncatedGaussian`]), `tobit-1-sl` … `tobit-l-sl`, `fused-sl` with the
//! Sijs–Lazar pseudo-measurement ([`Silence::PseudoMeasurement`]). Their diagnostics add the
//! cumulative counts `silence_held`, `silence_blocked` (over all nodes) and the mirror's
//! `mirror_unknown`, `mirror_mismatches`, `mirror_resyncs`, `mirror_refused`. They are not
//! built when the spec declares a loss rate: a channel that may lose a transmission after
//! the trigger makes a silence ambiguous in a way the mirror cannot see.
//!
//! Applies to a spec with a linear model, Tobit censoring thresholds τ_m
//! ([`TobitCensoring`]) and event triggers sharing a token bucket ([`TriggeredTokenBucket`]:
//! σ_m, χ_m, λ_m, η_{m,0} enter Ξ). A node whose packet was not
//! delivered has θ = 1 (the filter holds its last received measurement, eq. 19). The filter's
//! own scalars are the example's (ε₁…ε₅ = 0.05, ε₆…ε₁₃ = 0.7, ε₁₄ = 1, d = 1.5, e = 2),
//! C(Υ∘Ω₁)Cᵀ as written, α_m = 1/l (`docs/design.md` "Seed 004").
//!
//! Diagnostics: `trace_p` — tr P^g for `fused`, tr P̄_{m,k|k} for `tobit-m`; `fused` also
//! reports `p11`, `p12`, `p22` (the entries of P^g). Against the truth (evaluation only):
//! `nees` = eᵀP⁻¹e with the view's own P (P^g or P̄_m) and `inside_95` = 1 when
//! `nees ≤ χ²_{n_x}(0.95)`, so its mean over runs is the fraction of runs whose error lies
//! inside the 95 % ellipse of the bound (Theorem 5 claims E{eeᵀ} ≤ P^g).

use std::sync::{Arc, Mutex};

use estimator_core::catch_up::LostMeasurement;
use estimator_core::filter::tobit::{BoundScalars, Silence, TobitFilterConfig};
use estimator_core::filter::{Gated, GatedStep, InnovationGate, MirroredFusion, TobitFusion};
use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;
use estimator_core::{Error, Estimator as CoreEstimator, OnModel, Revise};
use estpipe_spec::channel::{TobitCensoring, TriggeredTokenBucket};
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::{Observation, MAX_NODES};
use nalgebra::SVector;

use super::adapter::{name, write_row_major, Name};
use super::fed::{linear, on_model, Fed};
use super::lagged::Lagged;
use super::slots::FromSlots;
use super::snapshot::{fixed, Snapshot};
use super::{BuildOptions, RunStart};
use crate::{CovarianceKind, Estimator, LateFold};

/// The names of the local views, node 1 first.
pub const LOCAL_NAMES: [&str; 8] = [
    "tobit-1", "tobit-2", "tobit-3", "tobit-4", "tobit-5", "tobit-6", "tobit-7", "tobit-8",
];
/// The name of the fused view.
pub const FUSED_NAME: &str = "fused";
/// The local views of the filter with [`Silence::Predict`], node 1 first.
pub const LOCAL_PREDICT_NAMES: [&str; 8] = [
    "tobit-1-predict",
    "tobit-2-predict",
    "tobit-3-predict",
    "tobit-4-predict",
    "tobit-5-predict",
    "tobit-6-predict",
    "tobit-7-predict",
    "tobit-8-predict",
];
/// The fused view of the filter with [`Silence::Predict`].
pub const FUSED_PREDICT_NAME: &str = "fused-predict";
/// The local views of the filter with [`Silence::TruncatedGaussian`], node 1 first.
pub const LOCAL_SILENCE_NAMES: [&str; 8] = [
    "tobit-1-silence",
    "tobit-2-silence",
    "tobit-3-silence",
    "tobit-4-silence",
    "tobit-5-silence",
    "tobit-6-silence",
    "tobit-7-silence",
    "tobit-8-silence",
];
/// The fused view of the filter with [`Silence::TruncatedGaussian`].
pub const FUSED_SILENCE_NAME: &str = "fused-silence";
/// The local views of the filter with [`Silence::PseudoMeasurement`], node 1 first.
pub const LOCAL_SL_NAMES: [&str; 8] = [
    "tobit-1-sl",
    "tobit-2-sl",
    "tobit-3-sl",
    "tobit-4-sl",
    "tobit-5-sl",
    "tobit-6-sl",
    "tobit-7-sl",
    "tobit-8-sl",
];
/// The fused view of the filter with [`Silence::PseudoMeasurement`].
pub const FUSED_SL_NAME: &str = "fused-sl";
/// The views' names with their gated names, in the order of the name constants above.
const LOCAL: [Name; 8] = [
    name!("tobit-1"),
    name!("tobit-2"),
    name!("tobit-3"),
    name!("tobit-4"),
    name!("tobit-5"),
    name!("tobit-6"),
    name!("tobit-7"),
    name!("tobit-8"),
];
const FUSED: Name = name!("fused");
const LOCAL_PREDICT: [Name; 8] = [
    name!("tobit-1-predict"),
    name!("tobit-2-predict"),
    name!("tobit-3-predict"),
    name!("tobit-4-predict"),
    name!("tobit-5-predict"),
    name!("tobit-6-predict"),
    name!("tobit-7-predict"),
    name!("tobit-8-predict"),
];
const FUSED_PREDICT: Name = name!("fused-predict");
const LOCAL_SILENCE: [Name; 8] = [
    name!("tobit-1-silence"),
    name!("tobit-2-silence"),
    name!("tobit-3-silence"),
    name!("tobit-4-silence"),
    name!("tobit-5-silence"),
    name!("tobit-6-silence"),
    name!("tobit-7-silence"),
    name!("tobit-8-silence"),
];
const FUSED_SILENCE: Name = name!("fused-silence");
const LOCAL_SL: [Name; 8] = [
    name!("tobit-1-sl"),
    name!("tobit-2-sl"),
    name!("tobit-3-sl"),
    name!("tobit-4-sl"),
    name!("tobit-5-sl"),
    name!("tobit-6-sl"),
    name!("tobit-7-sl"),
    name!("tobit-8-sl"),
];
const FUSED_SL: Name = name!("fused-sl");
/// χ²_n(0.95) for n = 1, 2, 3 degrees of freedom.
pub const CHI2_95: [f64; 3] = [
    3.841_458_820_694_124,
    5.991_464_547_107_979,
    7.814_727_903_251_178,
];
/// `d_t` of Ξ in the example.
pub const XI_D: f64 = 1.5;
/// `e_t` of Ξ in the example.
pub const XI_E: f64 = 2.0;

/// Builds the views for a spec with the seed 004 channel (empty otherwise).
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Some(parts) = Parts::of(spec) else {
        return Ok(Vec::new());
    };
    let (nx, ny, l) = (spec.nx(), spec.ny(), spec.nodes());
    if let Some(m) = (0..l).find(|&m| spec.node_ny(m) != ny) {
        anyhow::bail!(
            "tobit: the Tobit fusion filters need the same n_y at every node, but node {m} \
             measures {} and another {ny} components",
            spec.node_ny(m)
        );
    }
    macro_rules! by_l {
        ($n:literal) => {
            match l {
                1 => views::<$n, $n, 1>(&parts, options),
                2 => views::<$n, $n, 2>(&parts, options),
                3 => views::<$n, $n, 3>(&parts, options),
                4 => views::<$n, $n, 4>(&parts, options),
                _ => anyhow::bail!("tobit: {l} nodes not supported (1..=4 are compiled in)"),
            }
        };
    }
    match (nx, ny) {
        (1, 1) => by_l!(1),
        (2, 2) => by_l!(2),
        (3, 3) => by_l!(3),
        _ => anyhow::bail!(
            "tobit: n_x = {nx}, n_y = {ny} not supported (C(Υ∘Ω₁)Cᵀ as written needs \
             n_x = n_y; 1..=3 are compiled in)"
        ),
    }
}

/// What the factory reads from the spec.
#[derive(Debug)]
pub struct Parts {
    spec: Arc<EstimatorSpec>,
    censoring: TobitCensoring,
    trigger: TriggeredTokenBucket,
}

impl Parts {
    /// The seed 004 parts of `spec`, if it has them.
    pub fn of(spec: &Arc<EstimatorSpec>) -> Option<Self> {
        spec.linear()?;
        Some(Self {
            censoring: spec.channel.tobit.clone()?,
            trigger: spec.channel.event_trigger.clone()?,
            spec: Arc::clone(spec),
        })
    }

    /// The λχ warnings of the spec's triggers (printed by the evaluation).
    pub fn warnings(&self) -> Vec<String> {
        self.trigger.warnings()
    }
}

/// A fresh fusion filter for the spec whose local filters do `silence` at an instant
/// without a measurement.
pub fn fusion_for<const NX: usize, const NY: usize, const L: usize>(
    parts: &Parts,
    silence: Silence,
) -> anyhow::Result<TobitFusion<f64, NX, NY, L>> {
    anyhow::ensure!(
        parts.censoring.nodes() == L && parts.trigger.nodes() == L,
        "tobit: the censoring and trigger stages must have one entry per node ({L})"
    );
    let mut cfgs = Vec::with_capacity(L);
    for m in 0..L {
        let tau = parts.censoring.tau(m);
        anyhow::ensure!(
            tau.len() == NY,
            "tobit: tau of node {m} must have {NY} entries"
        );
        cfgs.push(
            TobitFilterConfig::new(
                SVector::from_column_slice(tau),
                BoundScalars::paper_example(),
                *parts.trigger.trigger(m),
                XI_D,
                XI_E,
            )
            .map_err(|e| anyhow::anyhow!("tobit: node {m}: {e}"))?
            .with_silence(silence),
        );
    }
    let cfgs: [TobitFilterConfig<f64, NY>; L] = core::array::from_fn(|m| cfgs[m]);
    TobitFusion::new(
        cfgs,
        SVector::from_column_slice(parts.spec.prior.mean.as_slice()),
        fixed(&parts.spec.prior.cov),
    )
    .map_err(|e| anyhow::anyhow!("tobit: initial prior: {e}"))
}

/// The fusion filter on every node's model.
type OnNodes<const NX: usize, const NY: usize, const L: usize> =
    OnModel<[Snapshot<NX, NY>; L], TobitFusion<f64, NX, NY, L>, NY>;
/// The fusion filter behind the bucket mirror on every node's model.
type OnMirrored<const NX: usize, const NY: usize, const L: usize> =
    OnModel<[Snapshot<NX, NY>; L], MirroredFusion<f64, NX, NY, L>, NY>;

/// What the views read of a fusion filter, with or without the mirror.
trait FusionFilter<const NX: usize, const NY: usize, const L: usize>:
    GatedStep<f64, NX> + Clone + Send + 'static
where
    Self::Measurement: FromSlots + LostMeasurement + Revise + Clone + Send,
{
    /// The fusion filter.
    fn fusion(&self) -> &TobitFusion<f64, NX, NY, L>;
    /// The node models, to bring a controlled model's input term to an instant.
    fn models_mut(&mut self) -> &mut [Snapshot<NX, NY>; L];
    /// The silence-reading filter's counts (none for the others).
    fn silence(&self, _sink: &mut dyn FnMut(&'static str, f64)) {}
}

impl<const NX: usize, const NY: usize, const L: usize> FusionFilter<NX, NY, L>
    for OnNodes<NX, NY, L>
{
    fn fusion(&self) -> &TobitFusion<f64, NX, NY, L> {
        &self.filter
    }
    fn models_mut(&mut self) -> &mut [Snapshot<NX, NY>; L] {
        &mut self.model
    }
}

impl<const NX: usize, const NY: usize, const L: usize> FusionFilter<NX, NY, L>
    for OnMirrored<NX, NY, L>
{
    fn fusion(&self) -> &TobitFusion<f64, NX, NY, L> {
        self.filter.fusion()
    }
    fn models_mut(&mut self) -> &mut [Snapshot<NX, NY>; L] {
        &mut self.model
    }
    fn silence(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        let c = self.filter.counts();
        sink("silence_held", f64::from(c.held));
        sink("silence_blocked", f64::from(c.blocked));
        let m = self.filter.mirror().counts();
        sink("mirror_unknown", f64::from(m.unknown));
        sink("mirror_mismatches", f64::from(m.mismatches));
        sink("mirror_resyncs", f64::from(m.resyncs));
        sink("mirror_refused", f64::from(m.refused));
    }
}

/// A fresh fusion filter on the spec's model, converted for instant 1 (its input term brought
/// to every instant by [`Fed`] when the model has one).
fn fed_fusion<const NX: usize, const NY: usize, const L: usize>(
    parts: &Parts,
    silence: Silence,
) -> anyhow::Result<Fed<OnNodes<NX, NY, L>>> {
    let model = Snapshot::nodes(linear(&parts.spec)?, L, 1);
    let on = OnModel::new(model, fusion_for::<NX, NY, L>(parts, silence)?);
    Ok(on_model(on, &parts.spec, set_inputs))
}

/// A fresh silence-reading fusion filter behind the mirror of the spec's bucket.
fn fed_mirrored<const NX: usize, const NY: usize, const L: usize>(
    parts: &Parts,
    silence: Silence,
) -> anyhow::Result<Fed<OnMirrored<NX, NY, L>>> {
    let model = Snapshot::nodes(linear(&parts.spec)?, L, 1);
    let (initial, rate, capacity) = parts.trigger.bucket();
    let costs: [u32; L] = core::array::from_fn(|m| parts.trigger.costs()[m]);
    let bucket = SharedTokenBucket::<L>::new(initial, rate, capacity, costs)
        .map_err(|e| anyhow::anyhow!("tobit: bucket: {e}"))?;
    let filter = MirroredFusion::new(fusion_for::<NX, NY, L>(parts, silence)?, bucket);
    Ok(on_model(
        OnModel::new(model, filter),
        &parts.spec,
        set_inputs,
    ))
}

/// The input term of instant `k` in every node's model.
fn set_inputs<const NX: usize, const NY: usize, const L: usize, E: FusionFilter<NX, NY, L>>(
    on: &mut E,
    model: &LinearModel,
    k: usize,
) where
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone + Send,
{
    for m in on.models_mut() {
        m.set_input(model, k);
    }
}

/// The views' one filter: stepped by whichever view asks first at an instant, its result
/// kept for the others.
struct Shared<E, M> {
    /// The filter, behind the core's gate with `--gate` (its counts are all nodes'), with the
    /// history of `--lag`.
    fed: Lagged<Gated<f64, Fed<E>>, M>,
    gated: bool,
    done_k: u32,
    last: Result<(), Error>,
    /// The last late fold: its instant, its observations and what it did (every view asks).
    folded: Option<(u32, [Observation; MAX_NODES], LateFold)>,
}

struct View<E, M, const NX: usize, const NY: usize, const L: usize> {
    name: &'static str,
    node: Option<usize>,
    shared: Arc<Mutex<Shared<E, M>>>,
}

/// The views of one fusion filter: `locals[0..L]`, then `fused`.
fn push_views<const NX: usize, const NY: usize, const L: usize, E>(
    out: &mut Vec<Box<dyn Estimator>>,
    fed: Fed<E>,
    gate: InnovationGate<f64>,
    gated: bool,
    locals: &[Name; 8],
    fused: Name,
) where
    E: FusionFilter<NX, NY, L>,
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone + Send,
{
    // Gated views are named `<name>+gate` (docs/gate.md).
    let named = |n: Name| if gated { n.gated } else { n.plain };
    let shared = Arc::new(Mutex::new(Shared {
        fed: Lagged::Off(Gated::new(fed, gate)),
        gated,
        done_k: 0,
        last: Ok(()),
        folded: None,
    }));
    for m in 0..L {
        out.push(Box::new(View::<E, E::Measurement, NX, NY, L> {
            name: named(locals[m]),
            node: Some(m),
            shared: Arc::clone(&shared),
        }));
    }
    out.push(Box::new(View::<E, E::Measurement, NX, NY, L> {
        name: named(fused),
        node: None,
        shared,
    }));
}

/// The fusion filters, each with its local views and its fused view: the paper's
/// (`tobit-1` … `tobit-l`, `fused`), [`Silence::Predict`] (`…-predict`), and — unless the spec
/// declares a loss rate — the two silence-reading ones (`…-silence`, `…-sl`).
fn views<const NX: usize, const NY: usize, const L: usize>(
    parts: &Parts,
    options: &BuildOptions,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    // Without `--gate` the views take the plain step (the gate held is never asked).
    let (gate, gated) = match options.gate {
        Some(p) => (
            InnovationGate::chi2(p).map_err(|e| anyhow::anyhow!("tobit: {e}"))?,
            true,
        ),
        None => (InnovationGate::off(), false),
    };
    let mut out: Vec<Box<dyn Estimator>> = Vec::with_capacity(4 * (L + 1));
    for (silence, locals, fused) in [
        (Silence::HeldMeasurement, &LOCAL, FUSED),
        (Silence::Predict, &LOCAL_PREDICT, FUSED_PREDICT),
    ] {
        let fed = fed_fusion::<NX, NY, L>(parts, silence)?;
        push_views::<NX, NY, L, _>(&mut out, fed, gate, gated, locals, fused);
    }
    if options.loss_rate == 0.0 {
        for (silence, locals, fused) in [
            (Silence::TruncatedGaussian, &LOCAL_SILENCE, FUSED_SILENCE),
            (Silence::PseudoMeasurement, &LOCAL_SL, FUSED_SL),
        ] {
            let fed = fed_mirrored::<NX, NY, L>(parts, silence)?;
            push_views::<NX, NY, L, _>(&mut out, fed, gate, gated, locals, fused);
        }
    }
    Ok(out)
}

impl<E, M> Shared<E, M> {
    /// The filter behind its gate.
    fn gated(&self) -> &Gated<f64, Fed<E>> {
        self.fed.inner()
    }

    /// The core estimator.
    fn filter(&self) -> &E {
        &self.gated().estimator.estimator
    }
}

impl<const NX: usize, const NY: usize, const L: usize, E> Estimator
    for View<E, E::Measurement, NX, NY, L>
where
    E: FusionFilter<NX, NY, L>,
    E::Measurement: FromSlots + LostMeasurement + Revise + Clone + Send,
{
    fn name(&self) -> &'static str {
        self.name
    }

    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        let mut s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        if s.done_k != k {
            let y = FromSlots::from_slots(obs);
            let gated = s.gated;
            s.last = match &mut s.fed {
                // Without `--gate` and `--lag`, the plain step (the gate held is never asked);
                // with a lag, the off gate's step, which admits without computing anything.
                Lagged::Off(g) if !gated => CoreEstimator::step(&mut g.estimator, k as usize, &y),
                fed => fed.step(k as usize, &y),
            };
            s.done_k = k;
        }
        s.last
    }

    fn set_lag(&mut self, lag: u32) -> bool {
        let mut s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        // Every view asks; the history is set once, before the first step.
        if matches!(s.fed, Lagged::Off(_)) && s.done_k == 0 {
            s.fed.set_lag(lag);
        }
        lag > 0
    }

    fn fold_late(&mut self, k: u32, obs: &[Observation]) -> LateFold {
        let mut s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((fk, fobs, done)) = &s.folded {
            if *fk == k && fobs.get(..obs.len()) == Some(obs) {
                return *done;
            }
        }
        let done = s.fed.fold(k as usize, &FromSlots::from_slots(obs));
        let mut all = [Observation::dropped(0, 0, 0, 0); MAX_NODES];
        all[..obs.len().min(MAX_NODES)].copy_from_slice(&obs[..obs.len().min(MAX_NODES)]);
        s.folded = Some((k, all, done));
        done
    }

    fn estimate(&self, out: &mut [f64]) {
        let s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        let x = match self.node {
            Some(m) => s.filter().fusion().local_estimate(m).map(|e| *e.state()),
            None => Some(*CoreEstimator::estimate(s.filter()).state()),
        };
        match x {
            Some(x) => out[..NX].copy_from_slice(x.as_slice()),
            None => out[..NX].fill(f64::NAN),
        }
    }

    /// The bound the Tobit filters propagate (seed 004), local or fused.
    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        let s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        let p = match self.node {
            Some(m) => s
                .filter()
                .fusion()
                .local_estimate(m)
                .map(|e| *e.covariance()),
            None => Some(*CoreEstimator::estimate(s.filter()).covariance()),
        };
        match p {
            Some(p) => {
                write_row_major(&p, out);
                CovarianceKind::Bound
            }
            None => {
                out[..NX * NX].fill(f64::NAN);
                CovarianceKind::None
            }
        }
    }

    fn diagnostics_vs_truth(&self, truth: &[f64], sink: &mut dyn FnMut(&'static str, f64)) {
        let s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        let (x, p) = match self.node {
            Some(m) => match s.filter().fusion().local_estimate(m) {
                Some(e) => e.into_parts(),
                None => return,
            },
            None => CoreEstimator::estimate(s.filter()).into_parts(),
        };
        let e = SVector::<f64, NX>::from_column_slice(&truth[..NX]) - x;
        if let Ok(pe) = estimator_core::linalg::solve_spd(&p, &e, "bound") {
            let nees = e.dot(&pe);
            sink("nees", nees);
            sink("inside_95", f64::from(u8::from(nees <= CHI2_95[NX - 1])));
        }
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        let s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        // The views share one filter: every view reports its counts over all nodes.
        if s.gated {
            let g = s.gated().state();
            sink("gate_tested", f64::from(g.counts.tested));
            sink("gate_rejected", f64::from(g.counts.rejected));
            sink("gate_forced", f64::from(g.forced));
        }
        match self.node {
            Some(m) => {
                if let Some(p) = s
                    .filter()
                    .fusion()
                    .local_estimate(m)
                    .map(|e| e.covariance())
                {
                    sink("trace_p", p.trace());
                }
            }
            None => {
                let p = CoreEstimator::estimate(s.filter()).covariance();
                sink("trace_p", p.trace());
                if NX == 2 {
                    sink("p11", p[(0, 0)]);
                    sink("p12", p[(0, 1)]);
                    sink("p22", p[(1, 1)]);
                }
            }
        }
        s.filter().silence(sink);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_views_for_the_preset_and_none_for_others() {
        let s = crate::presets::preset_spec("tobit-fusion");
        let v = build(&s, &BuildOptions::default(), &RunStart::default()).unwrap();
        let names: Vec<_> = v.iter().map(|e| e.name()).collect();
        assert_eq!(
            names,
            [
                "tobit-1",
                "tobit-2",
                "tobit-3",
                "fused",
                "tobit-1-predict",
                "tobit-2-predict",
                "tobit-3-predict",
                "fused-predict",
                "tobit-1-silence",
                "tobit-2-silence",
                "tobit-3-silence",
                "fused-silence",
                "tobit-1-sl",
                "tobit-2-sl",
                "tobit-3-sl",
                "fused-sl"
            ]
        );
        // A declared loss rate makes a silence ambiguous: no silence-reading views.
        let lossy = BuildOptions {
            loss_rate: 0.1,
            ..BuildOptions::default()
        };
        assert_eq!(build(&s, &lossy, &RunStart::default()).unwrap().len(), 8);
        let lin = crate::presets::preset_spec("linear");
        assert!(build(&lin, &BuildOptions::default(), &RunStart::default())
            .unwrap()
            .is_empty());
    }

    #[test]
    fn views_step_one_shared_filter_once_per_instant() {
        let (s, mut sim) = crate::presets::preset_run("tobit-fusion", 3, 0);
        let parts = Parts::of(&s).unwrap();
        let mut v = build(&s, &BuildOptions::default(), &RunStart::default()).unwrap();
        let mut alone = fusion_for::<2, 2, 3>(&parts, Silence::HeldMeasurement).unwrap();
        let mut predict = fusion_for::<2, 2, 3>(&parts, Silence::Predict).unwrap();
        for k in 1..=50u32 {
            let inst = sim.next_instant();
            for e in v.iter_mut() {
                e.step(k, &inst.obs).unwrap();
            }
            let models: [Snapshot<2, 2>; 3] =
                Snapshot::nodes(parts.spec.linear().unwrap(), 3, k as usize);
            let y: Vec<_> = inst
                .obs
                .iter()
                .map(|o| o.measurement().map(SVector::<f64, 2>::from_column_slice))
                .collect();
            let received = || core::array::from_fn(|m| y[m].as_ref());
            alone.step_models(&models, k as usize, received()).unwrap();
            predict
                .step_models(&models, k as usize, received())
                .unwrap();
            let mut out = [0.0; 2];
            v[3].estimate(&mut out);
            assert_eq!(
                out,
                [alone.estimate().state()[0], alone.estimate().state()[1]]
            );
            v[1].estimate(&mut out);
            let l1 = alone.local_estimate(1).unwrap().state();
            assert_eq!(out, [l1[0], l1[1]]);
            v[7].estimate(&mut out);
            let g = predict.estimate().state();
            assert_eq!(out, [g[0], g[1]]);
            v[5].estimate(&mut out);
            let l1 = predict.local_estimate(1).unwrap().state();
            assert_eq!(out, [l1[0], l1[1]]);
        }
    }
}
