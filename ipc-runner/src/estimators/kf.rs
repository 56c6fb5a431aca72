//! `kf`: the full-information Kalman filter, an oracle lower bound.
//!
//! **Definition.** `kf` is estimator-core's [`KalmanFilter`] on the plant's linear description
//! fed with *every* sensor measurement, as if the channel were perfect: it reads the
//! observations before the channel ([`Estimator::full_information`]), so it exists only in
//! offline evaluation. Under a lossy channel it is therefore not a competitor but the bound
//! that no channel-aware estimator can beat (for a linear-Gaussian plant it is the MMSE
//! estimator given all measurements, and its MSE converges to the trace of the Riccati
//! covariance). The meaningful channel-aware baseline is [`super::ikf`]. A "KF" that treats
//! a dropped packet as y = 0 is deliberately not offered: it is neither optimal nor a bound.
//!
//! Applies to every scenario whose plant offers a [`LinearDescription`]. Multi-node scenarios
//! update node by node (sequential updates are exact because nodes' noises are independent).
//! Diagnostics: `trace_p`, the trace of the filter's covariance P_k.

use std::sync::Arc;

use channel_sim::plant::{LinearDescription, Plant};
use channel_sim::scenario::ComposedScenario;
use channel_sim::sim::MAX_NODES;
use channel_sim::{Observation, Scenario};
use estimator_core::filter::KalmanFilter;
use estimator_core::Error;
use nalgebra::{DMatrix, SMatrix, SVector};

use super::EvalOptions;
use crate::Estimator;

/// Builds `kf` for a composed scenario with a linear description.
pub fn build(
    scenario: &dyn Scenario,
    _options: &EvalOptions,
    _seed: u64,
    _run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(linear_kf(scenario, "kf", true)?.into_iter().collect())
}

/// A Kalman filter on `scenario`'s linear description named `name`, or `None` when the
/// scenario has none. `full_information` selects the oracle (`kf`) or the channel-fed filter.
pub fn linear_kf(
    scenario: &dyn Scenario,
    name: &'static str,
    full_information: bool,
) -> anyhow::Result<Option<Box<dyn Estimator>>> {
    let Some(composed) = scenario.as_any().downcast_ref::<ComposedScenario>() else {
        return Ok(None);
    };
    let plant = composed.plant_arc();
    if plant.linear().is_none() {
        return Ok(None);
    }
    let init = composed.initial();
    let spec = Spec {
        name,
        full_information,
        plant,
        x0: init.estimator_mean.as_slice(),
        p0: &init.estimator_cov,
    };
    let (nx, ny) = (scenario.nx(), scenario.ny());
    macro_rules! by_ny {
        ($nx:literal) => {
            match ny {
                1 => LinearKf::<$nx, 1>::boxed(spec),
                2 => LinearKf::<$nx, 2>::boxed(spec),
                3 => LinearKf::<$nx, 3>::boxed(spec),
                4 => LinearKf::<$nx, 4>::boxed(spec),
                _ => anyhow::bail!("{name}: measurement dimension {ny} not supported"),
            }
        };
    }
    let kf = match nx {
        1 => by_ny!(1),
        2 => by_ny!(2),
        3 => by_ny!(3),
        4 => by_ny!(4),
        5 => by_ny!(5),
        6 => by_ny!(6),
        7 => by_ny!(7),
        8 => by_ny!(8),
        _ => anyhow::bail!("{name}: state dimension {nx} not supported"),
    }?;
    Ok(Some(kf))
}

struct Spec<'a> {
    name: &'static str,
    full_information: bool,
    plant: Arc<dyn Plant>,
    x0: &'a [f64],
    p0: &'a DMatrix<f64>,
}

/// Kalman filter over the plant's linear description; updates with every delivered
/// observation of an instant, node by node.
struct LinearKf<const NX: usize, const NY: usize> {
    name: &'static str,
    full_information: bool,
    plant: Arc<dyn Plant>,
    kf: KalmanFilter<f64, NX>,
    /// Fixed-size copies of a time-invariant model, so that a step allocates nothing.
    cache: Option<Box<Cached<NX, NY>>>,
}

/// A, B Q Bᵀ and, per node, C and D R Dᵀ converted once.
struct Cached<const NX: usize, const NY: usize> {
    a: SMatrix<f64, NX, NX>,
    q: SMatrix<f64, NX, NX>,
    c: [SMatrix<f64, NY, NX>; MAX_NODES],
    r: [SMatrix<f64, NY, NY>; MAX_NODES],
}

impl<const NX: usize, const NY: usize> Cached<NX, NY> {
    fn of(model: &dyn LinearDescription, nodes: usize) -> Box<Self> {
        let mut c = [SMatrix::zeros(); MAX_NODES];
        let mut r = [SMatrix::identity(); MAX_NODES];
        for m in 0..nodes.min(MAX_NODES) {
            c[m] = fixed(&model.c(m, 0));
            r[m] = fixed(&model.measurement_cov(m, 0));
        }
        Box::new(Self {
            a: fixed(&model.a(0)),
            q: fixed(&model.process_cov(0)),
            c,
            r,
        })
    }
}

fn fixed<const R: usize, const C: usize>(m: &DMatrix<f64>) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|i, j| m[(i, j)])
}

impl<const NX: usize, const NY: usize> LinearKf<NX, NY> {
    fn boxed(spec: Spec<'_>) -> anyhow::Result<Box<dyn Estimator>> {
        let kf = KalmanFilter::new(SVector::from_column_slice(spec.x0), fixed(spec.p0))
            .map_err(|e| anyhow::anyhow!("{}: initial.estimator_cov: {e}", spec.name))?;
        let cache = spec
            .plant
            .linear()
            .filter(|m| m.time_invariant())
            .map(|m| Cached::of(m, spec.plant.nodes()));
        Ok(Box::new(Self {
            name: spec.name,
            full_information: spec.full_information,
            plant: spec.plant,
            kf,
            cache,
        }))
    }

    fn model(&self) -> Result<&dyn LinearDescription, Error> {
        super::linear_of(&*self.plant)
    }
}

impl<const NX: usize, const NY: usize> Estimator for LinearKf<NX, NY> {
    fn name(&self) -> &'static str {
        self.name
    }

    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), Error> {
        if let Some(m) = &self.cache {
            let mut kf = self.kf;
            kf.predict_with(&m.a, &m.q)?;
            for o in obs {
                if let Some(y) = o.measurement() {
                    let node = o.node as usize;
                    if node >= self.plant.nodes() {
                        return Err(Error::InvalidConfig {
                            field: "node",
                            reason: "observation from a node the model does not have",
                        });
                    }
                    kf.update_with::<NY>(&m.c[node], &m.r[node], &SVector::from_column_slice(y))?;
                }
            }
            self.kf = kf;
            return Ok(());
        }
        let model = self.model()?;
        let (k, prev) = (k as usize, k.saturating_sub(1) as usize);
        // Work on a copy and commit at the end: an error leaves the filter untouched.
        let mut kf = self.kf;
        kf.predict_with(&fixed(&model.a(prev)), &fixed(&model.process_cov(prev)))?;
        for o in obs {
            if let Some(y) = o.measurement() {
                let node = o.node as usize;
                kf.update_with::<NY>(
                    &fixed(&model.c(node, k)),
                    &fixed(&model.measurement_cov(node, k)),
                    &SVector::from_column_slice(y),
                )?;
            }
        }
        self.kf = kf;
        Ok(())
    }

    fn estimate(&self, out: &mut [f64]) {
        out[..NX].copy_from_slice(self.kf.estimate().state().as_slice());
    }

    fn diagnostics(&self, sink: &mut dyn FnMut(&'static str, f64)) {
        sink("trace_p", self.kf.estimate().covariance().trace());
    }

    fn full_information(&self) -> bool {
        self.full_information
    }
}
