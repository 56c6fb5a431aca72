//! [`Observation`]: what the channel delivered for one sampling instant and one sensor node,
//! the runner's instant as the estimators read it, and its [`Slot`] form on the wire.

use crate::{Slot, WireError, MAX_NY, SLOT_DATA};

/// What the channel delivers for one sampling instant and one sensor node.
///
/// A dropped packet still produces an observation (with `delivered == false`): in the
/// occlusion model the drop itself is information, so the estimator must see the instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Sampling instant k. The stream's slots are k ≥ 1; an observation of k = 0 exists only
    /// for a scenario whose sensors measure at k = 0 (seed 003), and only through
    /// the simulator's initial observations (channel-sim's `Simulation::initial_observations`).
    pub k: u32,
    /// Sensor node index, 0-based.
    pub node: u8,
    /// Whether a measurement reached the estimator at this instant.
    pub delivered: bool,
    /// Number of valid entries in `y`.
    pub ny: u8,
    /// The measurement as received (after censoring, etc.); meaningful iff `delivered`.
    /// Entries at index ≥ `ny` are 0.
    pub y: [f64; MAX_NY],
    /// Channel-side flags of this instant, see the `FLAG_*` constants.
    pub flags: u32,
    /// The shared token bucket's level ξ_{t−1} this node's grant used, when the packet
    /// reports it (a delivered packet behind seed 004's shared bucket; the slot's `tokens`
    /// with [`FLAG_TOKENS`](crate::FLAG_TOKENS)).
    pub tokens: Option<u32>,
}

impl Observation {
    /// A dropped packet at instant `k` from `node` with measurement dimension `ny`.
    pub fn dropped(k: u32, node: u8, ny: u8, flags: u32) -> Self {
        Self {
            k,
            node,
            delivered: false,
            ny,
            y: [0.0; MAX_NY],
            flags,
            tokens: None,
        }
    }

    /// The valid part of the measurement (`None` when nothing was delivered).
    pub fn measurement(&self) -> Option<&[f64]> {
        self.delivered.then(|| &self.y[..self.ny as usize])
    }
}

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
        flags: match obs.tokens {
            Some(_) if obs.delivered => obs.flags | crate::FLAG_TOKENS,
            _ => obs.flags & !crate::FLAG_TOKENS,
        },
        tokens: obs.tokens.filter(|_| obs.delivered).unwrap_or(0),
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
        // The level a delivered packet reports; a dropped one has no grant to report.
        tokens: (slot.flags & crate::FLAG_TOKENS != 0 && slot.delivered == 1)
            .then_some(slot.tokens),
    })
}
