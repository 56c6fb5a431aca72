//! The seed 001 estimators for occlusion dropouts: `cce` (the paper's cross-coupled estimator,
//! Algorithms 1-2), `kf-io` (the paper's linear MMSE baseline, built as `docs/design.md`
//! "Seed 001" states) and `adf` (the product's exact-likelihood assumed-density filter). The
//! paper's third curve, `ikf`, is the generic [`super::ikf`] family (prediction only on a
//! dropout).
//!
//! Applies to composed scenarios with one sensor node, a linear plant and an occlusion stage
//! ([`OcclusionSpec`] with 1 to 4 intervals), for `n_x ≤ 4` and `n_y ≤ 2`. `cce` uses the
//! KL-optimal 15-component Gaussian sum (`gsum`, σ = 0.0617 r). Diagnostics: `trace_p`.

use std::sync::Arc;

use channel_sim::channel::occlusion::OcclusionSpec;
use channel_sim::plant::{LinearDescription, Plant};
use channel_sim::scenario::ComposedScenario;
use channel_sim::{Observation, Scenario};
use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearSystem;
use estimator_core::protocol::occlusion::Occlusion;
use estimator_core::Error;
use nalgebra::{DMatrix, SMatrix, SVector};

use super::EvalOptions;
use crate::Estimator;

/// Gaussian components per region used by `cce` (the paper's N = 15).
pub const CCE_COMPONENTS: usize = 15;

/// Builds `cce`, `kf-io` and `adf` for an occlusion scenario (empty list otherwise).
pub fn build(
    scenario: &dyn Scenario,
    _options: &EvalOptions,
    _seed: u64,
    _run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Some(composed) = scenario.as_any().downcast_ref::<ComposedScenario>() else {
        return Ok(Vec::new());
    };
    if composed.plant().linear().is_none() || scenario.nodes() != 1 {
        return Ok(Vec::new());
    }
    macro_rules! by_s {
        ($s:literal) => {
            if let Some(spec) = composed.stage::<OcclusionSpec<$s>>() {
                return by_dims::<$s>(composed, spec);
            }
        };
    }
    by_s!(1);
    by_s!(2);
    by_s!(3);
    by_s!(4);
    Ok(Vec::new())
}

fn by_dims<const S: usize>(
    composed: &ComposedScenario,
    spec: &OcclusionSpec<S>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let (nx, ny) = (composed.plant().nx(), composed.plant().ny());
    macro_rules! go {
        ($nx:literal, $ny:literal) => {
            family::<$nx, $ny, S>(composed, spec)
        };
    }
    match (nx, ny) {
        (1, 1) => go!(1, 1),
        (2, 1) => go!(2, 1),
        (3, 1) => go!(3, 1),
        (4, 1) => go!(4, 1),
        (1, 2) => go!(1, 2),
        (2, 2) => go!(2, 2),
        (3, 2) => go!(3, 2),
        (4, 2) => go!(4, 2),
        _ => anyhow::bail!("occlusion estimators support n_x ≤ 4 and n_y ≤ 2, got {nx}, {ny}"),
    }
}

fn fixed<const R: usize, const C: usize>(m: &DMatrix<f64>) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|i, j| m[(i, j)])
}

fn family<const NX: usize, const NY: usize, const S: usize>(
    composed: &ComposedScenario,
    spec: &OcclusionSpec<S>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let occ: Occlusion<f64, NX, 1, S> = spec
        .occlusion::<NX>()
        .ok_or_else(|| anyhow::anyhow!("occlusion stage does not match the plant"))?;
    let init = composed.initial();
    let x0 = SVector::<f64, NX>::from_column_slice(init.estimator_mean.as_slice());
    let p0: SMatrix<f64, NX, NX> = fixed(&init.estimator_cov);
    let plant = composed.plant_arc();
    let gsum = GaussSum::<f64, 1, CCE_COMPONENTS>::uniform()?;
    let cce =
        CrossCoupledEstimator::new(x0, p0, occ, &gsum).map_err(|e| anyhow::anyhow!("cce: {e}"))?;
    let kfio = KfIo::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("kf-io: {e}"))?;
    let adf = AssumedDensityFilter::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("adf: {e}"))?;
    Ok(vec![
        Box::new(Wrapped::<NX, NY, _>::new("cce", Arc::clone(&plant), cce)),
        Box::new(Wrapped::<NX, NY, _>::new("kf-io", Arc::clone(&plant), kfio)),
        Box::new(Wrapped::<NX, NY, _>::new("adf", plant, adf)),
    ])
}

/// The plant's matrices of one step as a core [`LinearSystem`] (`A`, `BQBᵀ` of `k − 1`;
/// `C`, `DRDᵀ` of `k`).
#[derive(Clone)]
struct Snapshot<const NX: usize, const NY: usize> {
    a: SMatrix<f64, NX, NX>,
    q: SMatrix<f64, NX, NX>,
    c: SMatrix<f64, NY, NX>,
    r: SMatrix<f64, NY, NY>,
}

impl<const NX: usize, const NY: usize> LinearSystem<f64, NX, NY> for Snapshot<NX, NY> {
    fn a(&self, _k: usize) -> SMatrix<f64, NX, NX> {
        self.a
    }
    fn c(&self, _k: usize) -> SMatrix<f64, NY, NX> {
        self.c
    }
    fn process_cov(&self, _k: usize) -> SMatrix<f64, NX, NX> {
        self.q
    }
    fn measurement_cov(&self, _k: usize) -> SMatrix<f64, NY, NY> {
        self.r
    }
}

/// What the wrapper needs from a core occlusion filter.
trait OcclusionFilter<const NX: usize, const NY: usize>: Send {
    /// One step; returns the region label when the filter has one.
    fn step_core(
        &mut self,
        m: &Snapshot<NX, NY>,
        k: usize,
        y: Option<&SVector<f64, NY>>,
    ) -> Result<Option<usize>, Error>;
    fn x(&self) -> &SVector<f64, NX>;
    fn p(&self) -> &SMatrix<f64, NX, NX>;
}

/// The three core filters share the `estimate` accessor and a `step` of the same
/// shape; only `cce` and `adf` return a region label.
macro_rules! occlusion_filter {
    ($ty:ty, [$($g:tt)*], $label:expr) => {
        impl<const NX: usize, const NY: usize, $($g)*> OcclusionFilter<NX, NY> for $ty {
            fn step_core(
                &mut self,
                m: &Snapshot<NX, NY>,
                k: usize,
                y: Option<&SVector<f64, NY>>,
            ) -> Result<Option<usize>, Error> {
                self.step(m, k, y).map($label)
            }
            fn x(&self) -> &SVector<f64, NX> {
                self.estimate().state()
            }
            fn p(&self) -> &SMatrix<f64, NX, NX> {
                self.estimate().covariance()
            }
        }
    };
}
occlusion_filter!(CrossCoupledEstimator<f64, NX, 1, S, N>, [const S: usize, const N: usize], Some);
occlusion_filter!(AssumedDensityFilter<f64, NX, S>, [const S: usize], Some);
occlusion_filter!(KfIo<f64, NX, S>, [const S: usize], |()| None);

struct Wrapped<const NX: usize, const NY: usize, F> {
    name: &'static str,
    plant: Arc<dyn Plant>,
    /// The model converted once when the plant is time invariant (no allocation per step).
    cached: Option<Snapshot<NX, NY>>,
    f: F,
    label: usize,
}

impl<const NX: usize, const NY: usize, F> Wrapped<NX, NY, F> {
    fn new(name: &'static str, plant: Arc<dyn Plant>, f: F) -> Self {
        let cached = plant
            .linear()
            .filter(|m| m.time_invariant())
            .map(|m| snapshot(m, 1));
        Self {
            name,
            plant,
            cached,
            f,
            label: 0,
        }
    }
}

/// The matrices of instant `k` (`A`, `BQBᵀ` of `k − 1`; `C`, `DRDᵀ` of `k`), converted to
/// fixed size (allocates: nalgebra's dynamic matrices).
fn snapshot<const NX: usize, const NY: usize>(
    model: &dyn LinearDescription,
    k: usize,
) -> Snapshot<NX, NY> {
    let prev = k.saturating_sub(1);
    Snapshot {
        a: fixed(&model.a(prev)),
        q: fixed(&model.process_cov(prev)),
        c: fixed(&model.c(0, k)),
        r: fixed(&model.measurement_cov(0, k)),
    }
}

impl<const NX: usize, const NY: usize, F: OcclusionFilter<NX, NY>> Estimator
    for Wrapped<NX, NY, F>
{
    fn name(&self) -> &'static str {
        self.name
    }

    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        let k = k as usize;
        let snap = super::model_at(&self.cached, &*self.plant, k, |m, k| Ok(snapshot(m, k)))?;
        let y = obs
            .first()
            .and_then(|o| o.measurement())
            .map(SVector::<f64, NY>::from_column_slice);
        // A missing slot (no observation at all) counts as a dropout, as DESIGN.md says.
        let label = self.f.step_core(&snap, k, y.as_ref())?;
        self.label = label.unwrap_or(0);
        Ok(())
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..NX].copy_from_slice(self.f.x().as_slice());
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        sink("trace_p", self.f.p().trace());
    }
}
