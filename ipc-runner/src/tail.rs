//! What a latency tail is made of, read from the per-instant trace (`latency.csv`).
//!
//! A p99 says how slow the slowest 1 % were, not why. Two causes look alike in a histogram
//! and apart in time: a slow instant on its own (an interrupt, a cache miss, a page fault in
//! one send) and an **episode** of consecutive slow instants, which needs something that lasts
//! longer than a slot period: a process stopped by the scheduler or the hypervisor, both
//! processes on one core, a periodic housekeeping task. Counting the tail instants that sit
//! in episodes of at least [`EPISODE_MIN`] tells a reader which one to chase.

use serde::Serialize;

/// Consecutive tail instants from which a run of them counts as an episode.
pub const EPISODE_MIN: usize = 3;

/// The tail of one trace, split into isolated instants and episodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TailBreakdown {
    /// Instants in the trace.
    pub instants: usize,
    /// The tail's threshold: the smallest of the slowest ⌈(1 − q)·n⌉ instants, µs.
    pub threshold_us: f64,
    /// Instants at or above the threshold.
    pub tail: usize,
    /// Maximal runs of consecutive tail instants.
    pub runs: usize,
    /// Tail instants in runs of at least [`EPISODE_MIN`].
    pub in_episodes: usize,
    /// Length of the longest run, instants.
    pub longest: usize,
    /// Index of the longest run's first instant.
    pub longest_at: usize,
}

impl TailBreakdown {
    /// Splits the slowest ⌈(1 − q)·n⌉ instants of `latency_us` (in order; ties with the
    /// threshold included) into runs.
    pub fn of(latency_us: &[f64], q: f64) -> Self {
        let n = latency_us.len();
        if n == 0 {
            return Self::default();
        }
        let mut sorted = latency_us.to_vec();
        sorted.sort_by(f64::total_cmp);
        // The slowest ⌈(1 − q)·n⌉ instants (the epsilon keeps 0.01·1000 at 10, not 11).
        let m = (((1.0 - q) * n as f64 - 1e-9).ceil() as usize).clamp(1, n);
        let threshold_us = sorted[n - m];
        let mut b = Self {
            instants: n,
            threshold_us,
            ..Self::default()
        };
        let mut run = 0usize;
        let close = |b: &mut Self, run: usize, end: usize| {
            if run == 0 {
                return;
            }
            b.runs += 1;
            if run >= EPISODE_MIN {
                b.in_episodes += run;
            }
            if run > b.longest {
                b.longest = run;
                b.longest_at = end - run;
            }
        };
        for (i, &v) in latency_us.iter().enumerate() {
            if v >= threshold_us {
                b.tail += 1;
                run += 1;
            } else {
                close(&mut b, run, i);
                run = 0;
            }
        }
        close(&mut b, run, n);
        b
    }

    /// Share of the tail instants that sit in episodes, 0–1.
    pub fn episode_share(&self) -> f64 {
        if self.tail == 0 {
            0.0
        } else {
            self.in_episodes as f64 / self.tail as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isolated_instants_and_episodes_are_told_apart() {
        // 1000 instants at 1 µs; isolated 10 µs spikes at 100, 300, 500; a 5-instant
        // episode at 700..705 and a 2-instant run at 900..902 (too short for an episode).
        let mut v = vec![1.0; 1000];
        for i in [100, 300, 500, 900, 901] {
            v[i] = 10.0;
        }
        for x in &mut v[700..705] {
            *x = 20.0;
        }
        let b = TailBreakdown::of(&v, 0.99);
        // The 10 slow instants are exactly the slowest 1 %.
        assert_eq!(b.threshold_us, 10.0);
        assert_eq!(b.tail, 10);
        assert_eq!(b.runs, 5);
        assert_eq!(b.in_episodes, 5);
        assert_eq!((b.longest, b.longest_at), (5, 700));
        assert!((b.episode_share() - 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_run_at_the_end_and_degenerate_input() {
        let mut v = vec![1.0; 100];
        for x in &mut v[96..] {
            *x = 5.0;
        }
        let b = TailBreakdown::of(&v, 0.96);
        assert_eq!((b.tail, b.runs, b.in_episodes), (4, 1, 4));
        assert_eq!((b.longest, b.longest_at), (4, 96));
        assert_eq!(TailBreakdown::of(&[], 0.99), TailBreakdown::default());
        assert_eq!(TailBreakdown::default().episode_share(), 0.0);
    }
}
