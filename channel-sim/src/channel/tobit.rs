//! Tobit censoring at each sensor (seed 004 eq. 2) as a channel stage: a measurement
//! component below its threshold τ_m arrives as τ_m, flagged [`FLAG_CENSORED`].
//!
//! The stage runs estimator-core's sensor-side [`censor`], so the simulation and a sensor node
//! execute the same code. It draws no random numbers.

use std::any::Any;

use estimator_core::protocol::tobit::censor;
use nalgebra::SVector;

use super::{Stage, StageSpec};
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_CENSORED, MAX_NY};
pub use estpipe_spec::channel::TobitCensoring;

impl StageSpec for TobitCensoring {
    fn knowledge(&self, k: &mut estpipe_spec::channel::ChannelKnowledge) {
        k.tobit = Some(self.clone());
    }
    fn name(&self) -> &'static str {
        "tobit-censoring"
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
            let m = (o.node as usize).min(self.nodes() - 1);
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
