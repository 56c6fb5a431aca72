//! Tobit censoring at each sensor (seed 004 eq. 2) as a channel stage: a measurement
//! component below its threshold τ_m arrives as τ_m, flagged [`FLAG_CENSORED`].
//!
//! The stage runs estimator-core's sensor-side [`censor`], so the simulation and a sensor node
//! execute the same code. It draws no random numbers.

use std::any::Any;

use estimator_core::protocol::tobit::censor;
use estpipe_wire::Fnv1a64;
use nalgebra::SVector;

use super::{Stage, StageSpec};
use crate::error::ScenarioError;
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_CENSORED, MAX_NODES, MAX_NY};

/// Padding for unused measurement components: never censors, never counts in a norm.
const NO_THRESHOLD: f64 = -f64::MAX;

/// Tobit censoring (eq. 2) with per-node thresholds τ_m.
#[derive(Clone, Debug, PartialEq)]
pub struct TobitCensoring {
    thresholds: Vec<Vec<f64>>,
}

impl TobitCensoring {
    /// `thresholds[m]` is τ_m (finite, one entry per measurement component of node m,
    /// 1 to MAX_NY; nodes may measure different numbers of components).
    pub fn new(thresholds: Vec<Vec<f64>>) -> Result<Self, ScenarioError> {
        if thresholds.is_empty() || thresholds.len() > MAX_NODES {
            return Err(ScenarioError::invalid(
                "tobit.thresholds",
                "need one threshold vector per node",
            ));
        }
        for (m, t) in thresholds.iter().enumerate() {
            if t.is_empty() || t.len() > MAX_NY {
                return Err(ScenarioError::invalid(
                    format!("tobit.thresholds[{m}]"),
                    format!("needs 1 to {MAX_NY} thresholds, got {}", t.len()),
                ));
            }
            if t.iter().any(|v| !v.is_finite()) {
                return Err(ScenarioError::invalid(
                    format!("tobit.thresholds[{m}]"),
                    "contains NaN or ±∞",
                ));
            }
        }
        Ok(Self { thresholds })
    }

    /// τ_m of node `m`.
    pub fn tau(&self, m: usize) -> &[f64] {
        &self.thresholds[m]
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.thresholds.len()
    }

    fn padded(&self, m: usize) -> SVector<f64, MAX_NY> {
        let mut t = SVector::<f64, MAX_NY>::repeat(NO_THRESHOLD);
        let tau = &self.thresholds[m];
        t.as_mut_slice()[..tau.len()].copy_from_slice(tau);
        t
    }
}

impl StageSpec for TobitCensoring {
    fn name(&self) -> &'static str {
        "tobit-censoring"
    }
    fn fingerprint(&self, h: &mut Fnv1a64) {
        h.u64(self.thresholds.len() as u64);
        for t in &self.thresholds {
            h.u64(t.len() as u64).f64s(t);
        }
    }
    fn build(&self, _nodes: usize) -> Box<dyn Stage> {
        Box::new(self.clone())
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl Stage for TobitCensoring {
    fn apply(&mut self, _k: u32, _truth: &[f64], obs: &mut [Observation], _rng: &mut SimRng) {
        for o in obs.iter_mut().filter(|o| o.delivered) {
            let m = (o.node as usize).min(self.thresholds.len() - 1);
            let z = SVector::<f64, MAX_NY>::from_column_slice(&o.y);
            // A non-finite z would be the plant's bug; leave the observation as it is.
            if let Ok((y, observed)) = censor(&z, &self.padded(m)) {
                let ny = o.ny as usize;
                o.y[..ny].copy_from_slice(&y.as_slice()[..ny]);
                if observed[..ny].iter().any(|&v| !v) {
                    o.flags |= FLAG_CENSORED;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(node: u8, y: [f64; 2]) -> Observation {
        let mut o = Observation::dropped(1, node, 2, 0);
        o.delivered = true;
        o.y[..2].copy_from_slice(&y);
        o
    }

    #[test]
    fn censoring_sets_flag_and_threshold() {
        let mut s = TobitCensoring::new(vec![vec![0.0, 0.5]; 2]).unwrap();
        let mut o = [obs(0, [1.0, 0.2]), obs(1, [1.0, 0.7])];
        let mut rng = crate::rng::run_rng(0, 0, crate::rng::Stream::Channel);
        s.apply(1, &[], &mut o, &mut rng);
        assert_eq!(&o[0].y[..2], &[1.0, 0.5]);
        assert!(o[0].flags & FLAG_CENSORED != 0);
        assert_eq!(o[1].flags, 0);
        assert!(TobitCensoring::new(vec![vec![f64::NAN]]).is_err());
    }
}
