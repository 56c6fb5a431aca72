//! The assembler's window: the pending instants `base ..= base + WINDOW − 1` in a ring
//! allocated once, which of every node's slots is known for each, and the front instant
//! handed on. What a missing slot counts as is the [`Assembler`](super::Assembler)'s
//! business; the window only knows which slots are there.

use estpipe_wire::{Observation, FLAG_IPC_LOST, MAX_NODES};

use super::WINDOW;

/// One pending instant.
#[derive(Clone, Copy, Debug)]
struct Pending {
    /// Bit m: node m's slot is known.
    known: u16,
    /// When the instant's first slot became known (its deadline runs from here).
    first_ns: u64,
    obs: [Observation; MAX_NODES],
}

/// [`WINDOW`] pending instants from `base` on; nothing allocated after [`Window::new`].
#[derive(Debug)]
pub(super) struct Window {
    nodes: usize,
    ny: [u8; MAX_NODES],
    /// The next instant to hand on.
    base: u64,
    ring: Box<[Pending]>,
    /// An instant handed on that never was in the ring ([`Window::lost_instant`]).
    spare: [Observation; MAX_NODES],
}

impl Window {
    /// For `nodes` nodes with `ny[n]` measurements each; starts at instant 1.
    pub(super) fn new(nodes: usize, ny: [u8; MAX_NODES]) -> Self {
        let none = [Observation::dropped(0, 0, 0, 0); MAX_NODES];
        let empty = Pending {
            known: 0,
            first_ns: 0,
            obs: none,
        };
        Self {
            nodes,
            ny,
            base: 1,
            ring: vec![empty; WINDOW].into_boxed_slice(),
            spare: none,
        }
    }

    /// Drops every pending instant; the window starts again at instant 1.
    pub(super) fn clear(&mut self) {
        for p in self.ring.iter_mut() {
            p.known = 0;
        }
        self.base = 1;
    }

    /// The next instant to hand on (every earlier one was).
    #[inline]
    pub(super) fn base(&self) -> u64 {
        self.base
    }

    /// The window starts at instant `first` (a stream joined mid-way); nothing is pending.
    pub(super) fn start_at(&mut self, first: u64) {
        self.base = first;
    }

    /// The last instant that fits.
    #[inline]
    pub(super) fn top(&self) -> u64 {
        self.base + WINDOW as u64 - 1
    }

    #[inline]
    fn at(&self, j: u64) -> &Pending {
        &self.ring[(j as usize) % WINDOW]
    }

    /// Whether node `m`'s slot of pending instant `j` is known.
    #[inline]
    pub(super) fn is_known(&self, j: u64, m: usize) -> bool {
        self.at(j).known & (1 << m) != 0
    }

    /// Node `m`'s slot of instant `k` (which fits) is `o`, known at `recv_ns`.
    #[inline]
    pub(super) fn set(&mut self, k: u64, m: usize, o: Observation, recv_ns: u64) {
        let p = &mut self.ring[(k as usize) % WINDOW];
        if p.known == 0 {
            p.first_ns = recv_ns;
        }
        p.known |= 1 << m;
        p.obs[m] = o;
    }

    /// Bit n: node n's slot of the front instant (`base`) is known.
    #[inline]
    pub(super) fn front_known(&self) -> u16 {
        self.at(self.base).known
    }

    /// When the front instant's first slot became known, if any is.
    #[inline]
    pub(super) fn front_first_ns(&self) -> Option<u64> {
        let p = self.at(self.base);
        (p.known != 0).then_some(p.first_ns)
    }

    /// Hands on the front instant: every node's slot not known becomes lost (no
    /// measurement, `FLAG_IPC_LOST`); the window moves on by one.
    #[inline]
    pub(super) fn hand_on(&mut self) -> (u32, &[Observation]) {
        let j = self.base;
        self.base = j + 1;
        let ny = self.ny;
        let p = &mut self.ring[(j as usize) % WINDOW];
        for (n, o) in p.obs[..self.nodes].iter_mut().enumerate() {
            if p.known & (1 << n) == 0 {
                *o = Observation::dropped(j as u32, n as u8, ny[n], FLAG_IPC_LOST);
            }
        }
        p.known = 0;
        (j as u32, &p.obs[..self.nodes])
    }

    /// Instant `j` outside the window (before the first slot of a stream joined mid-way),
    /// every node's slot lost.
    pub(super) fn lost_instant(&mut self, j: u64) -> &[Observation] {
        for (n, o) in self.spare[..self.nodes].iter_mut().enumerate() {
            *o = Observation::dropped(j as u32, n as u8, self.ny[n], FLAG_IPC_LOST);
        }
        &self.spare[..self.nodes]
    }
}
