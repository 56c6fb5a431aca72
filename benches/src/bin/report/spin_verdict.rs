//! How the spin target is decided: from triples measured back to back, on the median one.

use crate::pct::Pct;

/// How many (raw, queue, blackboard) triples the spin verdict is the median of.
pub const TRIPLES: usize = 5;

/// The spin target: pipeline p99 ≤ this × raw iceoryx2's.
pub const SPIN_TARGET: f64 = 1.5;

/// One back-to-back triple of the spin comparison: p99s measured within the same minute.
#[derive(Clone, Copy, Debug)]
pub struct Triple {
    /// Raw iceoryx2, paced at the pipeline's rate (one-way).
    pub raw: Pct,
    /// The pipeline end to end, estimates on the queue (the default, the verdict).
    pub queue: Pct,
    /// The queue run's own iceoryx2 hop (slot sent → received).
    pub hop: Pct,
    /// The pipeline end to end, estimates on the blackboard.
    pub board: Pct,
}

impl Triple {
    pub fn ratio(&self) -> f64 {
        self.queue.p99 / self.raw.p99
    }
    pub fn board_ratio(&self) -> f64 {
        self.board.p99 / self.raw.p99
    }
    pub fn own_hop(&self) -> f64 {
        self.queue.p99 / self.hop.p99
    }
}

/// The triple the verdict is read from: the median by the queue's ratio (the upper one of an
/// even count).
pub fn median_triple(t: &[Triple]) -> usize {
    let mut order: Vec<usize> = (0..t.len()).collect();
    order.sort_by(|&a, &b| t[a].ratio().total_cmp(&t[b].ratio()));
    order[order.len() / 2]
}

/// Range, median and count within a target of some ratios.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    pub lo: f64,
    pub median: f64,
    pub hi: f64,
    pub within: usize,
    pub n: usize,
}

impl Spread {
    pub fn of(ratios: impl Iterator<Item = f64>, target: f64) -> Self {
        let mut r: Vec<f64> = ratios.collect();
        r.sort_by(f64::total_cmp);
        Self {
            lo: r[0],
            median: r[r.len() / 2],
            hi: r[r.len() - 1],
            within: r.iter().filter(|&&x| x <= target).count(),
            n: r.len(),
        }
    }
    /// Every ratio on the same side of the target.
    pub fn unanimous(&self) -> bool {
        self.within == 0 || self.within == self.n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pct(p99: f64) -> Pct {
        Pct {
            count: 1,
            p99,
            ..Pct::default()
        }
    }

    #[test]
    fn the_verdict_is_read_from_the_median_triple_by_the_queue_ratio() {
        // Queue ratios 2.0, 1.2, 3.0, 1.6, 1.4 → sorted 1.2 1.4 1.6 2.0 3.0: median is the 4th.
        let t: Vec<Triple> = [(1.0, 2.0), (1.0, 1.2), (0.5, 1.5), (1.0, 1.6), (1.0, 1.4)]
            .iter()
            .map(|&(raw, queue)| Triple {
                raw: pct(raw),
                queue: pct(queue),
                hop: pct(raw),
                // The blackboard ratio must not decide which triple is the median.
                board: pct(10.0 / queue),
            })
            .collect();
        assert_eq!(median_triple(&t), 3);
        assert_eq!(
            median_triple(&t[..4]),
            0,
            "upper median of 1.2 1.6 2.0 3.0: 2.0"
        );
        assert_eq!(median_triple(&t[..1]), 0);
    }

    #[test]
    fn spread_counts_the_ratios_within_the_target() {
        let s = Spread::of([2.13, 1.6, 1.94, 2.26, 2.89].into_iter(), SPIN_TARGET);
        assert_eq!(
            s,
            Spread {
                lo: 1.6,
                median: 2.13,
                hi: 2.89,
                within: 0,
                n: 5
            }
        );
        assert!(s.unanimous());
        let mixed = Spread::of([1.43, 1.57, 7.03, 1.55, 1.9].into_iter(), SPIN_TARGET);
        assert_eq!((mixed.within, mixed.median), (1, 1.57));
        assert!(!mixed.unanimous());
        // The target itself counts as met.
        assert_eq!(Spread::of([1.5].into_iter(), SPIN_TARGET).within, 1);
    }
}
