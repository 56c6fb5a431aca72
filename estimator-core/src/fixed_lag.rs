//! Late packets are information: fixed-lag retrodiction over any [`Estimator`]
//! (docs/pipeline.md, "Late packets").
//!
//! A network delays packets as well as dropping them. When instant `j`'s packet (or one
//! node's part of it) arrives after `j` was stepped, [`FixedLag`] puts it into `j`'s
//! measurement and steps the estimator again from `j` to the newest instant `K`, from the
//! estimator as it was before `j`. An estimator whose step is a deterministic function of its
//! previous value and the instant's measurement (every filter of this crate) then holds,
//! bit for bit, what it would hold had the packet come on time.
//!
//! # Lateness and the lag
//!
//! A packet of instant `j` that arrives when `K` is the newest instant stepped is
//! `l = K − j + 1` instants late: `l = 1` when its own instant is the newest (it missed only
//! its own deadline). `FixedLag<E, M, L>` keeps, for each of the last `L` instants, the
//! estimator before it and its measurement, so it folds in a packet up to `l = L` late; an
//! older one is refused ([`Error::TooLate`]) and counted ([`LagCounts::too_old`]). `L = 0`
//! keeps nothing: every late packet is too old, and a step is the estimator's own.
//!
//! # What a late packet changes
//!
//! [`Revise`] says how a late packet enters its instant's measurement: a part that was
//! [`Packet::Lost`] (given up at the deadline) takes the late packet's value, delivered or
//! dropped by the channel; a part already known stays as it is (a duplicate changes nothing,
//! an occlusion dropout stays a dropout). [`FixedLag::revise`] takes any other rule as a
//! closure.
//!
//! # Cost and errors
//!
//! A step costs the estimator's step and one copy of the estimator and of the measurement
//! (into the ring). A fold of a packet `l` late costs `l` steps and `l − 1` copies. Nothing
//! allocates. On error the estimator, its estimate and its history are as they were: a
//! re-step that fails part-way (a late measurement the estimator refuses, say) is undone by
//! stepping the old measurements again from the untouched state before `j`, which gives the
//! old states back bit for bit for the same determinism reason.
//!
//! Tested in `tests/fixed_lag.rs` on every estimator of the crate, `f64` and `f32`.

use crate::catch_up::LostMeasurement;
use crate::estimate::Estimate;
use crate::estimator::Estimator;
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// A measurement into which a late part can be folded.
pub trait Revise {
    /// Folds `late` into this instant's measurement by the rule of the module docs: each part
    /// still lost takes `late`'s value where `late`'s is not lost. Returns how many parts
    /// changed (0: nothing new).
    fn revise(&mut self, late: &Self) -> usize;
}

impl<T: Real, const NY: usize> Revise for Packet<T, NY> {
    #[inline]
    fn revise(&mut self, late: &Self) -> usize {
        if self.is_lost() && !late.is_lost() {
            *self = *late;
            1
        } else {
            0
        }
    }
}

/// Node by node: the nodes whose part of `late` is lost are left as they are.
impl<M: Revise, const N: usize> Revise for [M; N] {
    #[inline]
    fn revise(&mut self, late: &Self) -> usize {
        self.iter_mut().zip(late).map(|(m, l)| m.revise(l)).sum()
    }
}

/// What a fold did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Revision {
    /// The late part changed instant `from`'s measurement; `from..=newest` were stepped again.
    Folded {
        /// The instant the late packet belongs to.
        from: usize,
        /// Instants stepped again (`newest − from + 1`).
        restepped: usize,
    },
    /// The late part brought nothing new (the instant's part was already known).
    Unchanged,
}

/// Running counts of late packets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LagCounts {
    /// Folded in: the estimate changed as an on-time arrival would have changed it.
    pub folded: u32,
    /// Nothing new: the instant's part was already known.
    pub unchanged: u32,
    /// More than `L` instants late, or for an instant before the first one stepped: dropped.
    pub too_old: u32,
    /// Refused by the estimator on the re-step (the estimator kept its state).
    pub refused: u32,
}

/// One instant of the history: the estimator before it, and its measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Past<E, M> {
    k: usize,
    before: E,
    y: M,
}

/// An estimator `E` (with measurements `M`) that folds in packets up to `L` instants late
/// (module docs).
#[derive(Clone, Debug)]
pub struct FixedLag<E, M, const L: usize> {
    now: E,
    /// Instant `k`'s entry at `k % L`, for the last `L` instants stepped.
    ring: [Option<Past<E, M>>; L],
    newest: Option<usize>,
    counts: LagCounts,
}

impl<E, M, const L: usize> FixedLag<E, M, L> {
    /// `estimator` with an empty history.
    pub fn new(estimator: E) -> Self {
        Self {
            now: estimator,
            ring: [const { None }; L],
            newest: None,
            counts: LagCounts::default(),
        }
    }

    /// The estimator after the newest instant.
    #[inline]
    pub fn inner(&self) -> &E {
        &self.now
    }

    /// The newest instant stepped.
    #[inline]
    pub fn newest(&self) -> Option<usize> {
        self.newest
    }

    /// The counts of late packets so far.
    #[inline]
    pub fn counts(&self) -> LagCounts {
        self.counts
    }

    /// The oldest instant a late packet may still belong to (`newest − L + 1`, or the first
    /// instant stepped), `None` before the first step or with `L = 0`.
    pub fn oldest_revisable(&self) -> Option<usize> {
        let newest = self.newest?;
        let mut oldest = None;
        for back in 0..L {
            match newest.checked_sub(back) {
                Some(k) if self.entry(k).is_some() => oldest = Some(k),
                _ => break,
            }
        }
        oldest
    }

    fn entry(&self, k: usize) -> Option<&Past<E, M>> {
        if L == 0 {
            return None;
        }
        self.ring[k % L].as_ref().filter(|p| p.k == k)
    }

    fn entry_mut(&mut self, k: usize) -> Option<&mut Past<E, M>> {
        if L == 0 {
            return None;
        }
        self.ring[k % L].as_mut().filter(|p| p.k == k)
    }
}

impl<E: Clone, M: Clone, const L: usize> FixedLag<E, M, L> {
    /// The estimator after instant `k` with every packet folded in so far: the newest, or one
    /// still in the history (`k ≥ newest − L + 1`, the instants a late packet can revise).
    pub fn after(&self, k: usize) -> Option<&E> {
        if Some(k) == self.newest {
            return Some(&self.now);
        }
        self.entry(k + 1).map(|p| &p.before)
    }

    /// Folds what arrived late into instant `j`'s measurement by `fold` (which returns how many
    /// parts it changed) and steps again from `j` to the newest instant (module docs).
    ///
    /// Errors: [`Error::OutOfOrder`] for an instant not yet stepped (step it instead),
    /// [`Error::TooLate`] for one older than the history, or the estimator's own error on the
    /// re-step. On error nothing changes.
    pub fn revise<T: Real, const NX: usize>(
        &mut self,
        j: usize,
        fold: impl FnOnce(&mut M) -> usize,
    ) -> Result<Revision>
    where
        E: Estimator<T, NX, Measurement = M>,
    {
        let newest = self.newest.ok_or(Error::OutOfOrder {
            expected: j + 1,
            got: j,
        })?;
        if j > newest {
            return Err(Error::OutOfOrder {
                expected: newest,
                got: j,
            });
        }
        let Some(entry) = self.entry(j) else {
            self.counts.too_old = self.counts.too_old.saturating_add(1);
            return Err(Error::TooLate {
                oldest: self.oldest_revisable().unwrap_or(newest + 1),
                got: j,
            });
        };
        let mut y = entry.y.clone();
        if fold(&mut y) == 0 {
            self.counts.unchanged = self.counts.unchanged.saturating_add(1);
            return Ok(Revision::Unchanged);
        }
        let mut w = entry.before.clone();
        if let Err(e) = w.step(j, &y) {
            self.counts.refused = self.counts.refused.saturating_add(1);
            return Err(e);
        }
        for i in j + 1..=newest {
            let Some(p) = self.entry_mut(i) else {
                // Unreachable: the ring holds every instant from `j` to `newest`.
                return Err(Error::Numerical {
                    what: "fixed-lag history has a hole",
                });
            };
            let before = core::mem::replace(&mut p.before, w.clone());
            if let Err(e) = w.step(i, &p.y) {
                p.before = before;
                self.restore(j, i);
                self.counts.refused = self.counts.refused.saturating_add(1);
                return Err(e);
            }
        }
        // Committed: the new measurement of `j`, the new current estimator.
        if let Some(p) = self.entry_mut(j) {
            p.y = y;
        }
        self.now = w;
        self.counts.folded = self.counts.folded.saturating_add(1);
        Ok(Revision::Folded {
            from: j,
            restepped: newest - j + 1,
        })
    }

    /// Folds `late` into instant `j`'s measurement by the [`Revise`] rule (a lost part takes
    /// the late one) and steps again from `j`: [`FixedLag::revise`].
    pub fn fold_in<T: Real, const NX: usize>(&mut self, j: usize, late: &M) -> Result<Revision>
    where
        E: Estimator<T, NX, Measurement = M>,
        M: Revise,
    {
        self.revise(j, |y| y.revise(late))
    }

    /// Puts back the states before `j + 1 .. stop` that a failed re-step overwrote, by
    /// stepping the unchanged measurements again from the untouched state before `j`. If even
    /// that fails (it cannot for a deterministic step) the history is cleared: the current
    /// estimator is untouched either way.
    fn restore<T: Real, const NX: usize>(&mut self, j: usize, stop: usize)
    where
        E: Estimator<T, NX, Measurement = M>,
    {
        let Some(entry) = self.entry(j) else { return };
        let mut w = entry.before.clone();
        let mut ok = w.step(j, &entry.y).is_ok();
        for i in j + 1..stop {
            match self.entry_mut(i) {
                Some(p) if ok => {
                    p.before = w.clone();
                    ok = w.step(i, &p.y).is_ok();
                }
                _ => ok = false,
            }
        }
        if !ok {
            self.ring = [const { None }; L];
        }
    }
}

impl<T, const NX: usize, E, M, const L: usize> Estimator<T, NX> for FixedLag<E, M, L>
where
    T: Real,
    E: Estimator<T, NX, Measurement = M> + Clone,
    M: Clone + LostMeasurement,
{
    type Measurement = M;

    /// Steps instant `k` after the newest one and keeps it in the history. Instants skipped
    /// between the newest and `k` are stepped as lost first (and kept too, so a late packet
    /// of one of them can be folded in); all of it on a copy, committed only when every step
    /// succeeds. `k` not after the newest is [`Error::OutOfOrder`] (a late packet is folded in
    /// by [`FixedLag::fold_in`]).
    fn step(&mut self, k: usize, y: &M) -> Result<()> {
        let from = match self.newest {
            Some(n) if k <= n => {
                return Err(Error::OutOfOrder {
                    expected: n + 1,
                    got: k,
                })
            }
            Some(n) => n + 1,
            None => k,
        };
        if L == 0 {
            self.now.step(k, y)?;
            self.newest = Some(k);
            return Ok(());
        }
        if from < k {
            // A gap: check the whole run on a copy first, then record the last `L` of it.
            let mut w = self.now.clone();
            let lost = M::lost();
            for i in from..k {
                w.step(i, &lost)?;
            }
            w.step(k, y)?;
            let keep = k.saturating_sub(L - 1).max(from);
            let mut v = self.now.clone();
            for i in from..k {
                if i >= keep {
                    self.ring[i % L] = Some(Past {
                        k: i,
                        before: v.clone(),
                        y: lost.clone(),
                    });
                }
                v.step(i, &lost)?;
            }
            self.ring[k % L] = Some(Past {
                k,
                before: v,
                y: y.clone(),
            });
            self.now = w;
            self.newest = Some(k);
            return Ok(());
        }
        let before = self.now.clone();
        self.now.step(k, y)?;
        self.ring[k % L] = Some(Past {
            k,
            before,
            y: y.clone(),
        });
        self.newest = Some(k);
        Ok(())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.now.estimate()
    }
}
