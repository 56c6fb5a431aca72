//! The simulator's side of the wire contract (`estpipe_wire`, `docs/wire.md`): an
//! [`Observation`](estpipe_wire::Observation) as a [`Slot`](estpipe_wire::Slot) and back
//! (re-exported from the contract), and the [`StreamHeader`] a scenario's stream
//! announces. The payloads, services and QoS themselves live in `estpipe-wire`, which a
//! foreign client depends on without this crate.

pub use estpipe_wire::observation::{observation_of, slot_of};

use crate::sim::Scenario;
use estpipe_wire::StreamHeader;

/// The header every slot of a stream of `scenario` carries: its name, nodes, nx, ny per node
/// and [`Scenario::fingerprint`].
pub fn stream_header(scenario: &dyn Scenario) -> StreamHeader {
    scenario.estimator_spec().stream_header()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{preset, preset_names};
    use crate::sim::FLAG_OCCLUDED;
    use crate::sim::{Observation, MAX_NY};

    fn obs(k: u32, node: u8, delivered: bool) -> Observation {
        let mut y = [0.0; MAX_NY];
        if delivered {
            y[0] = 1.5;
            y[1] = -2.25;
        }
        Observation {
            k,
            node,
            delivered,
            ny: 2,
            y,
            flags: if delivered { 0 } else { FLAG_OCCLUDED },
            tokens: None,
        }
    }

    #[test]
    fn observation_round_trips() {
        for (k, node, delivered) in [(1, 0, true), (7, 2, false), (300, 1, true)] {
            let o = obs(k, node, delivered);
            let s = slot_of(&o, 3, 42, 10, 20, 5);
            assert_eq!(s.seq, u64::from(k - 1));
            assert_eq!(observation_of(&s).unwrap(), o);
        }
    }

    #[test]
    fn non_finite_values_are_malformed_slots() {
        let mut o = obs(3, 0, true);
        o.y[1] = f64::NAN;
        let e = observation_of(&slot_of(&o, 1, 1, 0, 0, 0)).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }

    #[test]
    fn every_preset_has_its_own_fingerprint_and_a_stable_one() {
        let headers: Vec<StreamHeader> = preset_names()
            .iter()
            .map(|n| stream_header(&*preset(n).unwrap()))
            .collect();
        for (i, a) in headers.iter().enumerate() {
            assert!(a.validate().is_ok(), "{}", a.describe());
            for b in &headers[i + 1..] {
                assert_ne!(a.model, b.model, "{} {}", a.describe(), b.describe());
            }
        }
        // Building the same preset twice gives the same model.
        let again = stream_header(&*preset(preset_names()[0]).unwrap());
        assert_eq!(again, headers[0]);
    }
}
