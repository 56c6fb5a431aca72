//! A slot of an instant already handed on, within `--lag` ([`Pushed::Late`](super::Pushed::Late)): what the
//! estimators' fixed-lag history gets of it (docs/pipeline.md, "Late packets").

use estpipe_wire::{Observation, Slot, FLAG_IPC_LOST, MAX_NODES, MAX_NY};

use super::Assembler;

impl Assembler {
    /// The slot's measurement, zero-padded (zero when it has none).
    pub(super) fn measurement(&self, slot: &Slot) -> [f64; MAX_NY] {
        let mut y = [0.0; MAX_NY];
        if let Some(v) = slot.measurement() {
            y[..v.len()].copy_from_slice(v);
        }
        y
    }

    /// The slot of the last [`Pushed::Late`](super::Pushed::Late), as its instant's observations: every other node
    /// lost (`FLAG_IPC_LOST`), what the estimators' `fold_late` takes. `None` after the first
    /// call.
    pub fn take_late(&mut self, out: &mut [Observation; MAX_NODES]) -> Option<(u32, usize)> {
        let o = self.late.take()?;
        let nodes = usize::from(self.nodes);
        for (n, d) in out.iter_mut().enumerate().take(nodes) {
            *d = Observation::dropped(o.k, n as u8, self.ny[n], FLAG_IPC_LOST);
        }
        out[usize::from(o.node)] = o;
        Some((o.k, nodes))
    }
}
