//! The simulator's side of the wire contract (`estpipe_wire`, `docs/wire.md`): an
//! [`Observation`] as a [`Slot`] and back, and the [`StreamHeader`] a scenario's stream
//! announces. The payloads, services and QoS themselves live in `estpipe-wire`, which a
//! foreign client depends on without this crate.

use crate::sim::{Observation, Scenario, MAX_NY};
use estpipe_wire::{Slot, StreamHeader, WireError, SLOT_DATA};

/// The slot carrying `obs` in stream `stream_id` of a scenario with `nodes` nodes.
pub fn slot_of(
    obs: &Observation,
    nodes: u8,
    stream_id: u64,
    send_ns: u64,
    period_ns: u64,
    stream_start_ns: u64,
) -> Slot {
    Slot {
        ny: obs.ny,
        delivered: u8::from(obs.delivered),
        flags: obs.flags,
        send_ns,
        period_ns,
        stream_start_ns,
        y: obs.y,
        ..Slot::data(obs.k, obs.node, nodes, stream_id)
    }
}

/// The observation a data slot carries (validated against the slot's own `nodes` and `ny`;
/// wire version 3 refuses a non-finite measurement entry as a malformed slot, which the
/// runner counts and hands on as lost).
pub fn observation_of(slot: &Slot) -> Result<Observation, WireError> {
    slot.validate()?;
    if slot.kind != SLOT_DATA {
        return Err(WireError::Invalid("not a data slot"));
    }
    let mut y = [0.0; MAX_NY];
    if let Some(m) = slot.measurement() {
        y[..m.len()].copy_from_slice(m);
    }
    Ok(Observation {
        k: slot.k,
        node: slot.node,
        delivered: slot.delivered == 1,
        ny: slot.ny,
        y,
        flags: slot.flags,
    })
}

/// The header every slot of a stream of `scenario` carries: its name, nodes, nx, ny per node
/// and [`Scenario::fingerprint`].
pub fn stream_header(scenario: &dyn Scenario) -> StreamHeader {
    let ny: Vec<usize> = (0..scenario.nodes()).map(|m| scenario.node_ny(m)).collect();
    StreamHeader::new(
        scenario.name(),
        scenario.nodes(),
        scenario.nx(),
        &ny,
        scenario.fingerprint(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{preset, preset_names};
    use crate::sim::FLAG_OCCLUDED;

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
