//! What a bridge forwarded, refused and measured.

use crate::args::Side;
use hdrhistogram::Histogram;
use serde::Serialize;
use std::collections::BTreeMap;

/// Latency percentiles of one stage, µs.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Percentiles {
    /// Samples.
    pub count: u64,
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Largest.
    pub max_us: f64,
}

/// A latency histogram in ns (1 ns … 60 s, 3 significant digits; allocated once).
#[derive(Debug)]
pub struct Stage(Histogram<u64>);

impl Default for Stage {
    fn default() -> Self {
        Self(Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("static bounds"))
    }
}

impl Stage {
    /// Records `ns` (clamped into the histogram's range).
    pub fn record(&mut self, ns: u64) {
        self.0.saturating_record(ns.max(1));
    }

    /// The percentiles so far.
    pub fn percentiles(&self) -> Percentiles {
        let us = |q: f64| self.0.value_at_quantile(q) as f64 / 1e3;
        Percentiles {
            count: self.0.len(),
            p50_us: us(0.5),
            p99_us: us(0.99),
            max_us: self.0.max() as f64 / 1e3,
        }
    }
}

/// The bridge's account of one run (printed as one line, written as JSON with `--report`).
#[derive(Debug, Default, Serialize)]
pub struct BridgeReport {
    /// Which side.
    pub side: Option<Side>,
    /// The zenoh key prefix.
    pub key: String,
    /// Data slots forwarded.
    pub slots: u64,
    /// END/ABORT markers forwarded.
    pub markers: u64,
    /// Estimator side: copies of a marker already forwarded (the sensor side repeats each
    /// marker until it is acknowledged), dropped as expected.
    pub markers_repeated: u64,
    /// Estimator side: markers echoed on `<key>/acks` (every copy that arrived).
    pub acks: u64,
    /// Sensor side: END/ABORT messages put on the network, first puts and repeats.
    pub marker_puts: u64,
    /// Sensor side: markers the estimator side acknowledged.
    pub markers_acked: u64,
    /// Sensor side: markers given up on unacknowledged (repeated for
    /// [`crate::markers::RESEND_FOR`] without an echo on `<key>/acks`, or replaced by a newer
    /// marker of the same node).
    pub markers_unacked: u64,
    /// Sensor side: well-formed messages on `<key>/acks` that acknowledged no marker being
    /// repeated (the echoes of a marker's repeats after the first, or acks naming another
    /// marker, stream or node), dropped; malformed ones are in `refused`.
    pub acks_stale: u64,
    /// Truth samples forwarded.
    pub truth: u64,
    /// Estimates forwarded.
    pub estimates: u64,
    /// Slots the network lost (sequence gaps seen on arrival), written into shared memory as
    /// lost slots (`FLAG_NET_LOST`) so the runner reads them as no information.
    pub lost_on_network: u64,
    /// Messages refused, by reason; never forwarded.
    pub refused: BTreeMap<&'static str, u64>,
    /// Estimator side: times the sensor side vanished (zenoh no longer saw it).
    pub far_side_lost: u64,
    /// Data slots the local runner did not take within the send limit (its queue stayed full).
    pub dropped_at_bridge: u64,
    /// Estimator side: the slot's `send_ns` → its arrival here (the sensor-side bridge and the
    /// network; meaningful when both hosts' `CLOCK_MONOTONIC` agree, as on one host).
    pub network_hop: Percentiles,
    /// Estimator side: arrival → written into shared memory (this bridge's own time).
    pub bridge_time: Percentiles,
    /// Why the bridge stopped.
    pub ending: String,
}

impl BridgeReport {
    /// An empty report of `side`, on `key`.
    pub(crate) fn new(side: Side, key: String) -> Self {
        Self {
            side: Some(side),
            key,
            ..Default::default()
        }
    }

    /// Counts one refused message.
    pub fn refuse(&mut self, reason: &'static str) {
        *self.refused.entry(reason).or_default() += 1;
    }

    /// Messages refused in all.
    pub fn refused_total(&self) -> u64 {
        self.refused.values().sum()
    }

    /// One line for stderr.
    pub fn summary(&self) -> String {
        let refused = if self.refused.is_empty() {
            "none".to_string()
        } else {
            self.refused
                .iter()
                .map(|(r, n)| format!("{r} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "{} side, key {}: {} slots, {} markers, {} truth, {} estimates forwarded; {} lost on \
             the network; refused: {refused}; {}",
            self.side.map_or("?", Side::name),
            self.key,
            self.slots,
            self.markers,
            self.truth,
            self.estimates,
            self.lost_on_network,
            self.ending
        )
    }
}
