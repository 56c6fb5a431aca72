//! Latency histograms of the real-time loop (hdrhistogram, ns resolution, 3 significant
//! digits, 1 ns … 60 s). Recording never allocates: the buckets exist from construction.
//!
//! - **transport**: slot written by channel-sim (`send_ns`, just before `send()`) → slot
//!   received by the runner, per slot;
//! - **step**: one estimator's `step()` + `estimate()`, per estimator and instant;
//! - **end to end**: the send time of the slot that completed instant k → all estimates of k
//!   published.
//!
//! All times are `CLOCK_MONOTONIC`, which is one clock for every process of the machine.

use hdrhistogram::Histogram;
use serde::Serialize;

/// The three histograms of a run.
#[derive(Debug)]
pub struct Latency {
    /// Send → receive per slot.
    pub transport: Histogram<u64>,
    /// Estimator step per estimator and instant.
    pub step: Histogram<u64>,
    /// Send → estimates published per instant.
    pub end_to_end: Histogram<u64>,
}

/// Percentiles of one histogram, in µs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Percentiles {
    /// Number of recorded values.
    pub count: u64,
    /// Median.
    pub p50_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Maximum.
    pub max_us: f64,
}

impl Percentiles {
    /// Summarises `h` (values in ns).
    pub fn of(h: &Histogram<u64>) -> Self {
        if h.is_empty() {
            return Self::default();
        }
        let us = |v: u64| v as f64 / 1000.0;
        Self {
            count: h.len(),
            p50_us: us(h.value_at_quantile(0.50)),
            p90_us: us(h.value_at_quantile(0.90)),
            p99_us: us(h.value_at_quantile(0.99)),
            p999_us: us(h.value_at_quantile(0.999)),
            max_us: us(h.max()),
        }
    }
}

fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("valid static bounds")
}

impl Default for Latency {
    fn default() -> Self {
        Self::new()
    }
}

impl Latency {
    /// Empty histograms.
    pub fn new() -> Self {
        Self {
            transport: histogram(),
            step: histogram(),
            end_to_end: histogram(),
        }
    }

    /// Records `to − from` (ns) into `h`, saturating at the histogram's range; a negative
    /// difference (impossible with one monotonic clock) is recorded as 1 ns.
    pub fn record(h: &mut Histogram<u64>, from: u64, to: u64) {
        h.saturating_record(to.saturating_sub(from).max(1));
    }

    /// The three summaries.
    pub fn summary(&self) -> LatencySummary {
        LatencySummary {
            transport: Percentiles::of(&self.transport),
            step: Percentiles::of(&self.step),
            end_to_end: Percentiles::of(&self.end_to_end),
        }
    }

    /// Clears all histograms (e.g. after warm-up).
    pub fn reset(&mut self) {
        self.transport.reset();
        self.step.reset();
        self.end_to_end.reset();
    }
}

/// Percentiles of the three histograms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LatencySummary {
    /// Send → receive.
    pub transport: Percentiles,
    /// Estimator step.
    pub step: Percentiles,
    /// Send → estimates published.
    pub end_to_end: Percentiles,
}

impl LatencySummary {
    /// A fixed-width table (µs).
    pub fn table(&self) -> String {
        let mut s = String::from(
            "latency (µs)        count      p50      p90      p99    p99.9      max\n",
        );
        for (name, p) in [
            ("transport", &self.transport),
            ("estimator step", &self.step),
            ("end to end", &self.end_to_end),
        ] {
            s.push_str(&format!(
                "{name:<16}{:>9} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}\n",
                p.count, p.p50_us, p.p90_us, p.p99_us, p.p999_us, p.max_us
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_a_known_distribution() {
        let mut l = Latency::new();
        // 1..=1000 µs, one each: p50 ≈ 500 µs, p99 ≈ 990 µs, max = 1000 µs (±0.1 %: 3 digits).
        for i in 1..=1000u64 {
            Latency::record(&mut l.transport, 0, i * 1000);
        }
        let p = Percentiles::of(&l.transport);
        assert_eq!(p.count, 1000);
        assert!((p.p50_us - 500.0).abs() <= 0.5, "{}", p.p50_us);
        assert!((p.p99_us - 990.0).abs() <= 1.0, "{}", p.p99_us);
        assert!((p.max_us - 1000.0).abs() <= 1.0, "{}", p.max_us);
        assert!(p.p50_us <= p.p90_us && p.p90_us <= p.p99_us && p.p99_us <= p.p999_us);
    }

    #[test]
    fn backwards_and_huge_differences_do_not_panic() {
        let mut l = Latency::new();
        Latency::record(&mut l.step, 10, 5);
        Latency::record(&mut l.step, 0, u64::MAX);
        assert_eq!(l.step.len(), 2);
        assert!(l.summary().table().contains("estimator step"));
    }
}
