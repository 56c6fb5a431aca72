//! Server-side decimation of the live view (docs/view.md): the points of one frame (20 per
//! second) thinned to at most [`MAX_POINTS`] evenly spaced ones (the newest always kept), and
//! the end-to-end latency over a sliding window.

use std::collections::VecDeque;

/// Points per frame at most by default: 200 per second and series at 20 frames per second
/// (`--view-points-per-s`); a stream up to 200 Hz is shown whole.
pub const MAX_POINTS: usize = 10;

/// Indices of the points of a frame of `n` to keep: all when `n ≤ max`, else `max` evenly
/// spaced ones ending with the newest.
pub fn keep(n: usize, max: usize) -> Vec<usize> {
    if max == 0 {
        return Vec::new();
    }
    if n <= max {
        return (0..n).collect();
    }
    // The j-th kept point ends the j-th of `max` equal shares: the last share ends at n − 1.
    (1..=max).map(|j| j * n / max - 1).collect()
}

/// The latency of the newest instants (µs), at most `cap`.
#[derive(Debug)]
pub struct Window {
    values: VecDeque<f64>,
    cap: usize,
    sorted: Vec<f64>,
}

impl Window {
    /// A window of `cap` instants.
    pub fn new(cap: usize) -> Self {
        Self {
            values: VecDeque::with_capacity(cap),
            cap,
            sorted: Vec::with_capacity(cap),
        }
    }

    /// Adds one instant's latency.
    pub fn push(&mut self, us: f64) {
        if !us.is_finite() || self.cap == 0 {
            return;
        }
        if self.values.len() == self.cap {
            self.values.pop_front();
        }
        self.values.push_back(us);
    }

    /// (p50, p99, instants in the window); NaN when empty. Nearest-rank quantiles.
    pub fn quantiles(&mut self) -> (f64, f64, usize) {
        let n = self.values.len();
        if n == 0 {
            return (f64::NAN, f64::NAN, 0);
        }
        self.sorted.clear();
        self.sorted.extend(self.values.iter().copied());
        self.sorted.sort_by(f64::total_cmp);
        let at = |q: f64| self.sorted[((q * n as f64).ceil() as usize).clamp(1, n) - 1];
        (at(0.50), at(0.99), n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_all_up_to_max_then_evenly_with_the_newest() {
        assert_eq!(keep(3, 10), [0, 1, 2]);
        assert_eq!(keep(10, 10), (0..10).collect::<Vec<_>>());
        let k = keep(50, 10);
        assert_eq!(k.len(), 10);
        assert_eq!(*k.last().unwrap(), 49);
        assert_eq!(k[0], 4);
        assert!(k.windows(2).all(|w| w[1] - w[0] == 5));
        assert!(keep(5, 0).is_empty());
        let k = keep(13, 10);
        assert_eq!((k.len(), *k.last().unwrap()), (10, 12));
        assert!(k.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn window_quantiles_forget_the_oldest() {
        let mut w = Window::new(100);
        assert!(w.quantiles().0.is_nan());
        for i in 1..=100 {
            w.push(f64::from(i));
        }
        assert_eq!(w.quantiles(), (50.0, 99.0, 100));
        for _ in 0..100 {
            w.push(1000.0);
        }
        w.push(f64::NAN);
        assert_eq!(w.quantiles(), (1000.0, 1000.0, 100));
    }
}
