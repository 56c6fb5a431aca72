//! Scenarios: a plant, its channel stages and the initial distribution, under a name.
//!
//! [`ComposedScenario`] is the one [`Scenario`] implementation: the paper presets and TOML
//! files only differ in the parts they compose. The data path of one instant reads
//! top to bottom in [`ComposedSimulation::next_instant`]: plant → raw observations → stages.
//!
//! Presets are looked up by name with [`preset`]; adding one is a line in [`PRESETS`] and a
//! file `scenario/<name>.rs` with a `pub fn preset() -> Result<Box<dyn Scenario>, ScenarioError>`.

pub mod config;
pub mod linear;
pub mod nn_token_bucket;
pub mod occlusion;
pub mod tobit_fusion;

use std::any::Any;
use std::fmt;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use crate::plant::{check_pd, check_psd, run_rng, Plant, PlantRun, SimRng, Stream};
use crate::sim::{Instant, Observation, Scenario, Simulation, MAX_NX, MAX_NY};
use crate::stage::{Stage, StageSpec};

/// A constructor of a preset scenario.
pub type PresetFn = fn() -> Result<Box<dyn Scenario>, ScenarioError>;

/// The preset registry: name → constructor. Paper presets add one line each.
pub const PRESETS: &[(&str, PresetFn)] = &[
    ("linear", linear::preset),
    ("occlusion", occlusion::preset),
    ("nn-token-bucket", nn_token_bucket::preset),
    ("tobit-fusion", tobit_fusion::preset),
];

/// The preset named `name`.
pub fn preset(name: &str) -> Result<Box<dyn Scenario>, ScenarioError> {
    match PRESETS.iter().find(|(n, _)| *n == name) {
        Some((_, make)) => make(),
        None => Err(ScenarioError::UnknownScenario {
            name: name.to_owned(),
            known: preset_names().join(", "),
        }),
    }
}

/// Names of all presets, in registry order.
pub fn preset_names() -> Vec<&'static str> {
    PRESETS.iter().map(|(n, _)| *n).collect()
}

/// Why a scenario could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum ScenarioError {
    /// No preset has this name.
    UnknownScenario {
        /// The requested name.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// A parameter is invalid.
    Invalid {
        /// Dotted path of the field (`model.q`, `stages[1].p_loss`).
        field: String,
        /// Why.
        reason: String,
    },
    /// A scenario file could not be read or parsed.
    File {
        /// The file.
        path: String,
        /// What went wrong (one line).
        reason: String,
    },
}

impl ScenarioError {
    /// An [`ScenarioError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        ScenarioError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ScenarioError::UnknownScenario { name, known } => {
                write!(f, "unknown scenario '{name}' (known: {known})")
            }
            ScenarioError::Invalid { field, reason } => write!(f, "invalid `{field}`: {reason}"),
            ScenarioError::File { path, reason } => write!(f, "{path}: {reason}"),
        }
    }
}

impl std::error::Error for ScenarioError {}

/// The initial distribution: the true x_0 ~ N(mean, cov) (cov may be zero: a known start) and
/// the prior the estimators start from (x̂_0, P_0), which the papers sometimes choose
/// differently from the truth's distribution (seed 003).
#[derive(Clone, Debug)]
pub struct InitialDistribution {
    /// Mean of x_0.
    pub mean: DVector<f64>,
    /// Covariance of x_0 (positive semi-definite).
    pub cov: DMatrix<f64>,
    /// x̂_0.
    pub estimator_mean: DVector<f64>,
    /// P_0 (positive definite).
    pub estimator_cov: DMatrix<f64>,
    factor: DMatrix<f64>,
}

impl InitialDistribution {
    /// Validates dimensions and definiteness; field names are under `initial.`.
    pub fn new(
        mean: DVector<f64>,
        cov: DMatrix<f64>,
        estimator_mean: DVector<f64>,
        estimator_cov: DMatrix<f64>,
    ) -> Result<Self, ScenarioError> {
        let n = mean.len();
        if mean.iter().any(|v| !v.is_finite()) {
            return Err(ScenarioError::invalid("initial.mean", "contains NaN or ±∞"));
        }
        if estimator_mean.iter().any(|v| !v.is_finite()) {
            return Err(ScenarioError::invalid(
                "initial.estimator_mean",
                "contains NaN or ±∞",
            ));
        }
        if estimator_mean.len() != n {
            return Err(ScenarioError::invalid(
                "initial.estimator_mean",
                format!("must have {n} entries, got {}", estimator_mean.len()),
            ));
        }
        crate::plant::check_shape(cov.shape(), (n, n), "initial.cov")?;
        crate::plant::check_shape(estimator_cov.shape(), (n, n), "initial.estimator_cov")?;
        let factor = check_psd(&cov, "initial.cov")?;
        check_pd(&estimator_cov, "initial.estimator_cov")?;
        Ok(Self {
            mean,
            cov,
            estimator_mean,
            estimator_cov,
            factor,
        })
    }

    /// The common case: the estimator's prior is the truth's distribution.
    pub fn gaussian(mean: DVector<f64>, cov: DMatrix<f64>) -> Result<Self, ScenarioError> {
        Self::new(mean.clone(), cov.clone(), mean, cov)
    }

    /// Draws x_0.
    pub fn sample(&self, rng: &mut SimRng) -> DVector<f64> {
        &self.mean + &self.factor * crate::plant::standard_normal(self.mean.len(), rng)
    }
}

/// A plant, its channel stages (applied in order) and the initial distribution, under a name.
#[derive(Debug)]
pub struct ComposedScenario {
    name: String,
    plant: Arc<dyn Plant>,
    stages: Vec<Arc<dyn StageSpec>>,
    initial: InitialDistribution,
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
        Ok(Self {
            name: name.into(),
            plant,
            stages,
            initial,
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
        Self {
            name: format!("{}-no-channel", self.name),
            plant: Arc::clone(&self.plant),
            stages: Vec::new(),
            initial: self.initial.clone(),
        }
    }

    /// Starts a run with the concrete simulation type.
    pub fn simulate(&self, seed: u64, run: u64) -> ComposedSimulation {
        let mut plant_rng = run_rng(seed, run, Stream::Plant);
        let x0 = self.initial.sample(&mut plant_rng);
        let mut truth0 = [0.0; MAX_NX];
        truth0[..x0.len()].copy_from_slice(x0.as_slice());
        let nodes = self.plant.nodes();
        ComposedSimulation {
            plant: self.plant.start(x0.as_slice()),
            stages: self.stages.iter().map(|s| s.build(nodes)).collect(),
            plant_rng,
            channel_rng: run_rng(seed, run, Stream::Channel),
            truth0,
            raw: Vec::with_capacity(nodes),
            z: vec![[0.0; MAX_NY]; nodes],
            ny: self.plant.ny() as u8,
            k: 0,
        }
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
    fn nodes(&self) -> usize {
        self.plant.nodes()
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
    ny: u8,
    k: u32,
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
        // What the sensors hand to the channel: everything delivered, unflagged.
        self.raw.clear();
        for (m, z) in self.z.iter().enumerate() {
            let mut y = [0.0; MAX_NY];
            y[..self.ny as usize].copy_from_slice(&z[..self.ny as usize]);
            self.raw.push(Observation {
                k,
                node: m as u8,
                delivered: true,
                ny: self.ny,
                y,
                flags: 0,
            });
        }
        // The channel, stage by stage.
        let mut obs: heapless::Vec<Observation, { crate::sim::MAX_NODES }> =
            self.raw.iter().copied().collect();
        for stage in &mut self.stages {
            stage.apply(k, x, &mut obs, &mut self.channel_rng);
        }
        Instant { k, truth, obs }
    }

    fn raw_observations(&self) -> Option<&[Observation]> {
        Some(&self.raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_preset_lists_known_names() {
        let e = preset("nope").unwrap_err().to_string();
        assert!(e.starts_with("unknown scenario 'nope' (known: "), "{e}");
        assert!(e.contains("linear"));
    }

    #[test]
    fn same_seed_same_instants_and_channel_does_not_change_plant() {
        let s = preset("linear").unwrap();
        let c = s.as_any().downcast_ref::<ComposedScenario>().unwrap();
        let bare = c.without_channel();
        let (mut a, mut b, mut n) = (c.simulate(5, 9), c.simulate(5, 9), bare.simulate(5, 9));
        assert_eq!(a.initial_truth(), n.initial_truth());
        let mut dropped = 0;
        for _ in 0..200 {
            let (ia, ib, inn) = (a.next_instant(), b.next_instant(), n.next_instant());
            assert_eq!(ia, ib);
            assert_eq!(ia.truth, inn.truth);
            assert_eq!(a.raw_observations().unwrap(), &inn.obs[..]);
            assert!(inn.obs.iter().all(|o| o.delivered && o.flags == 0));
            for (o, r) in ia.obs.iter().zip(a.raw_observations().unwrap()) {
                if o.delivered {
                    assert_eq!(o, r);
                } else {
                    dropped += 1;
                }
            }
        }
        assert!(dropped > 0);
        let mut other = c.simulate(5, 10);
        assert_ne!(
            other.next_instant().truth,
            c.simulate(5, 9).next_instant().truth
        );
    }
}
