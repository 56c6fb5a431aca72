//! The occlusion channel stage (seed 001, eqs. (2)-(3)): the packets of instant `k` are lost
//! iff `u_k = E x_k + n_k`, `n_k ~ N(0, Ψ)`, lies in one of the occlusion regions.
//!
//! The region test is estimator-core's [`OcclusionRegions::label`], the same code a sensor
//! node would run. One `n_k` is drawn per instant (it moves the regions, eq. 2, so it is common
//! to every node) and it is drawn whether or not an upstream stage already dropped the
//! packets, so the channel stream stays aligned across channel settings. Dropped packets get
//! [`FLAG_OCCLUDED`]. `n_e = 1` (intervals), as in the paper's example.

use std::any::Any;

use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use nalgebra::{SMatrix, SVector};
use rand_distr::{Distribution, StandardNormal};

use super::{drop_packet, Stage, StageSpec};
use crate::error::ScenarioError;
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_OCCLUDED};

/// Configuration of the occlusion stage with `S` interval regions on `u = e·x + n`.
#[derive(Clone, Debug, PartialEq)]
pub struct OcclusionSpec<const S: usize> {
    /// The row `E` (length n_x).
    pub e: Vec<f64>,
    /// Variance `Ψ` of `n_k`.
    pub psi: f64,
    /// The regions (validated by estimator-core: finite, positive radii, disjoint).
    pub regions: OcclusionRegions<f64, 1, S>,
}

impl<const S: usize> OcclusionSpec<S> {
    /// Validates `E` (finite, length `nx`), `Ψ` and the regions as the estimators' spec does
    /// ([`estpipe_spec::channel::Occlusion::new`]: the same fields named in errors).
    pub fn new(
        e: Vec<f64>,
        psi: f64,
        centres: [f64; S],
        radii: [f64; S],
        nx: usize,
    ) -> Result<Self, ScenarioError> {
        let known = estpipe_spec::channel::Occlusion::new(
            e.clone(),
            psi,
            centres.to_vec(),
            radii.to_vec(),
            nx,
        )?;
        let regions = known
            .regions::<S>()
            .map_err(|e| ScenarioError::invalid("occlusion.regions", e.to_string()))?;
        Ok(Self { e, psi, regions })
    }

    /// The mechanism as estimator-core's [`Occlusion`] for an `NX`-state filter (`None` when
    /// `NX` differs from the length of `E`).
    pub fn occlusion<const NX: usize>(&self) -> Option<Occlusion<f64, NX, 1, S>> {
        (self.e.len() == NX).then_some(())?;
        Occlusion::new(
            SMatrix::<f64, 1, NX>::from_fn(|_, j| self.e[j]),
            SMatrix::<f64, 1, 1>::new(self.psi),
            self.regions,
        )
        .ok()
    }

    /// The occlusion model as the estimators know it (this stage's parameters, validated
    /// here already).
    pub fn knowledge(&self) -> estpipe_spec::channel::Occlusion {
        estpipe_spec::channel::Occlusion::new(
            self.e.clone(),
            self.psi,
            (0..S).map(|i| self.regions.centre(i)[0]).collect(),
            (0..S).map(|i| self.regions.radius(i)).collect(),
            self.e.len(),
        )
        .expect("an OcclusionSpec holds validated parameters")
    }

    /// `E x`.
    pub fn ex(&self, x: &[f64]) -> f64 {
        self.e.iter().zip(x).map(|(a, b)| a * b).sum()
    }
}

impl<const S: usize> StageSpec for OcclusionSpec<S> {
    fn knowledge(&self, k: &mut estpipe_spec::channel::ChannelKnowledge) {
        k.occlusion = Some(self.knowledge());
    }
    fn name(&self) -> &'static str {
        "occlusion"
    }
    fn build(&self, _nodes: usize) -> Box<dyn Stage> {
        Box::new(self.clone())
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl<const S: usize> Stage for OcclusionSpec<S> {
    fn apply(&mut self, _k: u32, truth: &[f64], obs: &mut [Observation], rng: &mut SimRng) {
        let n: f64 = StandardNormal.sample(rng);
        let u = self.ex(truth) + self.psi.sqrt() * n;
        if self.regions.drops(&SVector::from([u])) {
            for o in obs {
                if o.delivered {
                    drop_packet(o, FLAG_OCCLUDED);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::SeedableRng;

    #[test]
    fn drops_inside_regions_only() {
        let spec = OcclusionSpec::new(vec![1.0, 0.0], 1e-12, [20.0, 40.0], [5.0, 5.0], 2).unwrap();
        let mut stage = spec.build(1);
        let mut rng = SimRng::seed_from_u64(1);
        for (x1, dropped) in [(10.0, false), (16.0, true), (30.0, false), (44.9, true)] {
            let mut obs = [Observation {
                k: 1,
                node: 0,
                delivered: true,
                ny: 1,
                y: [1.0, 0.0, 0.0, 0.0],
                flags: 0,
                tokens: None,
            }];
            stage.apply(1, &[x1, 0.0], &mut obs, &mut rng);
            assert_eq!(!obs[0].delivered, dropped, "x1 = {x1}");
            assert_eq!(obs[0].flags & FLAG_OCCLUDED != 0, dropped);
        }
        assert!(OcclusionSpec::new(vec![1.0], 0.1, [0.0, 5.0], [5.0, 5.0], 1).is_err());
        assert!(OcclusionSpec::new(vec![1.0], -0.1, [0.0], [5.0], 1).is_err());
        assert!(OcclusionSpec::new(vec![1.0, 0.0], 0.1, [0.0], [5.0], 1).is_err());
        assert!(spec.occlusion::<2>().is_some() && spec.occlusion::<3>().is_none());
    }
}
