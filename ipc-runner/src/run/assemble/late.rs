//! A slot of an instant already handed on, within `--lag` ([`Pushed::Late`](super::Pushed::Late)):
//! the observation kept of it, and what the estimators' fixed-lag history gets of it
//! (docs/pipeline.md, "Late packets").

use estpipe_wire::{Observation, Slot, FLAG_IPC_LOST, MAX_NODES, MAX_NY};

/// The slot's measurement, zero-padded (zero when it has none).
pub(super) fn measurement(slot: &Slot) -> [f64; MAX_NY] {
    let mut y = [0.0; MAX_NY];
    if let Some(v) = slot.measurement() {
        y[..v.len()].copy_from_slice(v);
    }
    y
}

/// The late slot `o` as its instant's observations in `out`: every other of the `ny.len()`
/// nodes lost (`FLAG_IPC_LOST`), what the estimators' `fold_late` takes. Returns the instant
/// and the node count.
pub(super) fn as_instant(
    o: Observation,
    ny: &[u8],
    out: &mut [Observation; MAX_NODES],
) -> (u32, usize) {
    for (n, d) in out.iter_mut().enumerate().take(ny.len()) {
        *d = Observation::dropped(o.k, n as u8, ny[n], FLAG_IPC_LOST);
    }
    out[usize::from(o.node)] = o;
    (o.k, ny.len())
}
