//! [`ComposedScenario`], the one [`Scenario`] implementation: a plant, its channel stages and
//! the initial distribution under a name. The paper presets and TOML files only differ in the
//! parts they compose.
//!
//! The data path of one instant reads top to bottom in [`ComposedSimulation::next_instant`]:
//! plant → raw observations → stages. A plant that measures at k = 0 (seed 003) sends its
//! y₀ down the same path when the run starts ([`Simulation::initial_observations`]).

use std::any::Any;
use std::fmt;
use std::sync::Arc;

use estpipe_spec::{ChannelKnowledge, EstimatorSpec, Prior};

use super::initial::InitialDistribution;
use crate::channel::{Stage, StageSpec};
use crate::error::ScenarioError;
use crate::plant::{Plant, PlantRun};
use crate::rng::{run_rng, SimRng, Stream};
use crate::sim::{Instant, Observation, Scenario, Simulation, MAX_NX, MAX_NY};

/// A plant, its channel stages (applied in order) and the initial distribution, under a name.
#[derive(Debug)]
pub struct ComposedScenario {
    name: String,
    plant: Arc<dyn Plant>,
    stages: Vec<Arc<dyn StageSpec>>,
    initial: InitialDistribution,
    /// What the estimators know of it, formed once.
    spec: Arc<EstimatorSpec>,
}

impl ComposedScenario {
    /// Composes a scenario; checks that the parts agree on the dimensions.
    pub fn new(
        name: impl Into<String>,
        plant: Arc<dyn Plant>,
        initial: InitialDistribution,
        stages: Vec<Arc<dyn StageSpec>>,
    ) -> Result<Self, ScenarioError> {
        if initial.mean.len() != plant.nx() {
            return Err(ScenarioError::invalid(
                "initial.mean",
                format!(
                    "must have nx = {} entries, got {}",
                    plant.nx(),
                    initial.mean.len()
                ),
            ));
        }
        if plant.nx() > MAX_NX || plant.ny() > MAX_NY {
            return Err(ScenarioError::invalid(
                "model",
                "dimensions exceed MAX_NX/MAX_NY",
            ));
        }
        let name = name.into();
        let model = plant.model().ok_or_else(|| {
            ScenarioError::invalid("model", "the plant has no model an estimator can use")
        })?;
        let mut channel = ChannelKnowledge::default();
        for s in &stages {
            s.knowledge(&mut channel);
        }
        let prior = Prior {
            mean: initial.estimator_mean.clone(),
            cov: initial.estimator_cov.clone(),
        };
        let spec = Arc::new(EstimatorSpec::new(name.clone(), model, prior, channel)?);
        Ok(Self {
            name,
            plant,
            stages,
            initial,
            spec,
        })
    }

    /// The plant.
    pub fn plant(&self) -> &dyn Plant {
        &*self.plant
    }

    /// The plant, shared (estimators keep it to read the model at every step).
    pub fn plant_arc(&self) -> Arc<dyn Plant> {
        Arc::clone(&self.plant)
    }

    /// The channel stage specs in application order.
    pub fn stages(&self) -> &[Arc<dyn StageSpec>] {
        &self.stages
    }

    /// Every stage's [`StageSpec::warnings`], prefixed with the stage name.
    pub fn warnings(&self) -> Vec<String> {
        self.stages
            .iter()
            .flat_map(|s| {
                s.warnings()
                    .into_iter()
                    .map(|w| format!("{}: {w}", s.name()))
            })
            .collect()
    }

    /// The first stage spec of concrete type `T`, if any.
    pub fn stage<T: 'static>(&self) -> Option<&T> {
        self.stages.iter().find_map(|s| s.as_any().downcast_ref())
    }

    /// The initial distribution and the estimators' prior.
    pub fn initial(&self) -> &InitialDistribution {
        &self.initial
    }

    /// The same scenario without any channel stage (every packet delivered, plant streams
    /// unchanged).
    pub fn without_channel(&self) -> Self {
        Self::new(
            format!("{}-no-channel", self.name),
            Arc::clone(&self.plant),
            self.initial.clone(),
            Vec::new(),
        )
        .expect("the parts of a built scenario are valid")
    }

    /// Starts a run with the concrete simulation type.
    pub fn simulate(&self, seed: u64, run: u64) -> ComposedSimulation {
        let mut plant_rng = run_rng(seed, run, Stream::Plant);
        let x0 = self.initial.sample(&mut plant_rng);
        let mut truth0 = [0.0; MAX_NX];
        truth0[..x0.len()].copy_from_slice(x0.as_slice());
        let nodes = self.plant.nodes();
        let mut sim = ComposedSimulation {
            plant: self.plant.start(x0.as_slice()),
            stages: self.stages.iter().map(|s| s.build(nodes)).collect(),
            plant_rng,
            channel_rng: run_rng(seed, run, Stream::Channel),
            truth0,
            raw: Vec::with_capacity(nodes),
            z: vec![[0.0; MAX_NY]; nodes],
            ny: core::array::from_fn(|m| {
                if m < nodes {
                    self.plant.node_ny(m) as u8
                } else {
                    0
                }
            }),
            k: 0,
            obs0: None,
        };
        // Instant 0, for a plant that measures then (seed 003): the sensors' y₀ through every
        // channel stage, as any other instant. Other plants draw nothing here.
        if sim
            .plant
            .initial_measurement(&mut sim.plant_rng, &mut sim.z)
        {
            sim.obs0 = Some(sim.observe(0));
        }
        sim
    }
}

impl Scenario for ComposedScenario {
    fn name(&self) -> &str {
        &self.name
    }
    fn nx(&self) -> usize {
        self.plant.nx()
    }
    fn ny(&self) -> usize {
        self.plant.ny()
    }
    fn node_ny(&self, node: usize) -> usize {
        self.plant.node_ny(node)
    }
    fn nodes(&self) -> usize {
        self.plant.nodes()
    }
    fn estimator_spec(&self) -> Arc<EstimatorSpec> {
        Arc::clone(&self.spec)
    }
    fn start(&self, seed: u64, run: u64) -> Box<dyn Simulation> {
        Box::new(self.simulate(seed, run))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// One run of a [`ComposedScenario`].
pub struct ComposedSimulation {
    plant: Box<dyn PlantRun>,
    stages: Vec<Box<dyn Stage>>,
    plant_rng: SimRng,
    channel_rng: SimRng,
    truth0: [f64; MAX_NX],
    raw: Vec<Observation>,
    z: Vec<[f64; MAX_NY]>,
    /// Every node's measurement dimension.
    ny: [u8; crate::sim::MAX_NODES],
    k: u32,
    /// The observations of instant 0 (plants that measure at k = 0 only).
    obs0: Option<heapless::Vec<Observation, { crate::sim::MAX_NODES }>>,
}

impl ComposedSimulation {
    /// The sensors' raw observations of instant `k` from `z` (kept in `raw`), then the
    /// channel, stage by stage.
    fn observe(&mut self, k: u32) -> heapless::Vec<Observation, { crate::sim::MAX_NODES }> {
        let x = self.plant.state();
        // What the sensors hand to the channel: everything delivered, unflagged.
        self.raw.clear();
        for (m, z) in self.z.iter().enumerate() {
            let ny = self.ny[m];
            let mut y = [0.0; MAX_NY];
            y[..ny as usize].copy_from_slice(&z[..ny as usize]);
            self.raw.push(Observation {
                k,
                node: m as u8,
                delivered: true,
                ny,
                y,
                flags: 0,
                tokens: None,
            });
        }
        // The channel, stage by stage.
        let mut obs: heapless::Vec<Observation, { crate::sim::MAX_NODES }> =
            self.raw.iter().copied().collect();
        for stage in &mut self.stages {
            stage.apply(k, x, &mut obs, &mut self.channel_rng);
        }
        obs
    }
}

impl fmt::Debug for ComposedSimulation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ComposedSimulation")
            .field("k", &self.k)
            .field("stages", &self.stages.len())
            .finish_non_exhaustive()
    }
}

impl Simulation for ComposedSimulation {
    fn initial_truth(&self) -> [f64; MAX_NX] {
        self.truth0
    }

    fn next_instant(&mut self) -> Instant {
        self.k += 1;
        let k = self.k;
        // Plant and sensors: x_k and every node's z_{m,k}.
        self.plant.advance(k, &mut self.plant_rng, &mut self.z);
        let x = self.plant.state();
        let mut truth = [0.0; MAX_NX];
        truth[..x.len()].copy_from_slice(x);
        let obs = self.observe(k);
        Instant { k, truth, obs }
    }

    fn raw_observations(&self) -> Option<&[Observation]> {
        Some(&self.raw)
    }

    fn initial_observations(&self) -> Option<&[Observation]> {
        self.obs0.as_deref()
    }
}
