//! Latency percentiles as the runner writes them, and their table rows.

use anyhow::{Context, Result};
use serde_json::Value;

/// The head of every latency table: one [`Pct::row`] per path follows.
pub const PCT_HEAD: &str =
    "| path | samples | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs |\n|---|---:|---:|---:|---:|---:|---:|\n";

#[derive(Clone, Copy, Debug, Default)]
pub struct Pct {
    pub count: u64,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

impl Pct {
    /// Reads `ipc_runner::latency::Percentiles` as serialised (`report.json`). A missing or non-numeric field is an error, not a NaN in a table.
    pub fn from_json(v: &Value) -> Result<Self> {
        let f = |k: &str| {
            v[k].as_f64()
                .with_context(|| format!("latency percentiles without a numeric {k:?}: {v}"))
        };
        Ok(Self {
            count: v["count"]
                .as_u64()
                .with_context(|| format!("latency percentiles without \"count\": {v}"))?,
            p50: f("p50_us")?,
            p90: f("p90_us")?,
            p99: f("p99_us")?,
            p999: f("p999_us")?,
            max: f("max_us")?,
        })
    }

    /// This path's row of a table under [`PCT_HEAD`].
    pub fn row(&self, name: &str) -> String {
        format!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} |",
            self.count, self.p50, self.p90, self.p99, self.p999, self.max
        )
    }

    /// Back to the runner's type (what the test compares with).
    #[cfg(test)]
    pub fn percentiles(&self) -> ipc_runner::latency::Percentiles {
        ipc_runner::latency::Percentiles {
            count: self.count,
            p50_us: self.p50,
            p90_us: self.p90,
            p99_us: self.p99,
            p999_us: self.p999,
            max_us: self.max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_runner::latency::Percentiles;

    #[test]
    fn reads_what_the_runner_writes() {
        let p = Percentiles {
            count: 30_000,
            p50_us: 0.5,
            p90_us: 0.56,
            p99_us: 0.91,
            p999_us: 9.8,
            max_us: 1500.25,
        };
        let back = Pct::from_json(&serde_json::to_value(p).unwrap()).unwrap();
        assert_eq!(back.percentiles(), p);
        // A renamed or missing field fails loudly instead of printing NaN in BENCHMARKS.md.
        let mut v = serde_json::to_value(p).unwrap();
        v.as_object_mut().unwrap().remove("p99_us");
        let e = Pct::from_json(&v).unwrap_err();
        assert!(format!("{e:#}").contains("p99_us"), "{e:#}");
        assert!(Pct::from_json(&Value::Null).is_err());
    }
}
