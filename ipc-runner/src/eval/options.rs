//! What one `eval` is: the experiment (runs, horizon, seed), the estimators it builds
//! ([`BuildOptions`]'s fields, flat, as the command line gives them) and the transport stage
//! between the channel and the estimators that only an evaluation simulates.

use crate::estimators::BuildOptions;

/// Options of an evaluation.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Number of Monte-Carlo runs.
    pub runs: u64,
    /// Horizon T: instants k = 1..=T are simulated.
    pub horizon: u32,
    /// Experiment seed.
    pub seed: u64,
    /// [`BuildOptions::particles`].
    pub particles: usize,
    /// [`BuildOptions::estimators`].
    pub estimators: Vec<String>,
    /// [`BuildOptions::loss_rate`].
    pub loss_rate: f64,
    /// [`BuildOptions::gate`].
    pub gate: Option<f64>,
    /// [`BuildOptions::lag`].
    pub lag: u32,
    /// Probability that a slot is lost in transport after the channel (`--transport-loss`),
    /// independently of everything else (its own random stream, so the channel's randomness
    /// is unchanged). 0: no transport stage.
    pub transport_loss: f64,
    /// The transport losses look like channel dropouts (`--transport-loss-unmarked`: the
    /// receiver sees only "no packet") instead of being marked lost.
    pub transport_loss_unmarked: bool,
    /// The transport delays slots by whole instants (`--transport-delay`); `None`: every slot
    /// on time.
    pub transport_delay: Option<super::delay::Delay>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        let build = BuildOptions::default();
        Self {
            runs: 500,
            horizon: 100,
            seed: 0,
            particles: build.particles,
            estimators: build.estimators,
            loss_rate: build.loss_rate,
            gate: build.gate,
            lag: build.lag,
            transport_loss: 0.0,
            transport_loss_unmarked: false,
            transport_delay: None,
        }
    }
}

impl From<&EvalOptions> for BuildOptions {
    fn from(o: &EvalOptions) -> Self {
        Self {
            particles: o.particles,
            estimators: o.estimators.clone(),
            loss_rate: o.loss_rate,
            gate: o.gate,
            lag: o.lag,
        }
    }
}
