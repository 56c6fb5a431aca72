//! What the loop records per instant, preallocated (recording stops when full): keys, truth,
//! estimates, timing and the received slots; written at the end as CSV files.

use anyhow::{Context, Result};
use estpipe_wire::Observation;
use estpipe_wire::MAX_NX;

/// Recorded instants a late slot's instant is looked for in ([`Trajectories::mark_late`]):
/// a late slot is at most `--lag` ≤ [`crate::estimators::MAX_LAG`] instants old.
const LATE_SEARCH: usize = crate::estimators::MAX_LAG as usize + 1;

/// Recorded trajectories (preallocated; recording stops when full).
#[derive(Debug, Default)]
pub struct Trajectories {
    /// Session, k per recorded instant.
    pub keys: Vec<(u32, u32)>,
    /// Truth per instant (`nx` values, NaN when missing).
    pub truth: Vec<f64>,
    /// Estimates per instant and estimator (`n_est · nx` values).
    pub estimates: Vec<f64>,
    /// Per instant and estimator, the variance of each component (`n_est · nx` values: the
    /// diagonal of the covariance or bound the estimator publishes, NaN when it publishes
    /// none): the ±2σ bands of the demo's plot, as the live view draws them (docs/view.md).
    pub var: Vec<f64>,
    /// Per instant and node, what became of its slot (`nodes` values, the live view's
    /// [`crate::view::tap`] codes: delivered, dropped, lost, late): the plot's node strip.
    pub status: Vec<u8>,
    /// Per instant: the completing slot's send time, its receive time and the time the
    /// instant's estimates were all published (`CLOCK_MONOTONIC` ns).
    pub timing: Vec<[u64; 3]>,
    /// Received slots (for `replay`), if requested.
    pub slots: Vec<Observation>,
    /// The slots of `slots` (by index) that arrived late and were folded in (`--lag`), with
    /// the newest instant handed on when each came.
    pub late_after: Vec<(usize, u32)>,
    /// With `--mcap`: every node's observation of each recorded instant (`nodes` each).
    pub obs: Vec<Observation>,
    /// With `--mcap`: per recorded instant and estimator, the covariance (or bound), `nx · nx`
    /// row-major.
    pub cov: Vec<f64>,
    /// With `--mcap`: per recorded instant and estimator, the wire's `cov_kind`.
    pub cov_kind: Vec<u32>,
    /// Whether `obs`, `cov` and `cov_kind` are recorded (`--mcap`).
    pub full: bool,
    /// Sensor nodes (observations per instant in `obs`).
    pub nodes: usize,
    /// State dimension.
    pub nx: usize,
    /// Estimator names.
    pub names: Vec<String>,
}

impl Trajectories {
    /// Room for `instants` instants of `nx` states and the estimators `names`, and for the
    /// slots of `slots` instants of `nodes` nodes.
    pub(super) fn with_capacity(
        instants: usize,
        nx: usize,
        names: Vec<String>,
        slots: usize,
        nodes: usize,
        full: bool,
    ) -> Self {
        let full_cap = if full { instants } else { 0 };
        Self {
            obs: Vec::with_capacity(full_cap * nodes),
            cov: Vec::with_capacity(full_cap * names.len() * nx * nx),
            cov_kind: Vec::with_capacity(full_cap * names.len()),
            full,
            nodes,
            keys: Vec::with_capacity(instants),
            truth: Vec::with_capacity(instants * nx),
            estimates: Vec::with_capacity(instants * nx * names.len()),
            var: Vec::with_capacity(instants * nx * names.len()),
            status: Vec::with_capacity(instants * nodes),
            timing: Vec::with_capacity(instants),
            slots: Vec::with_capacity(slots * nodes),
            late_after: Vec::new(),
            nx,
            names,
        }
    }

    /// Records instant `k` of `session`: its `timing`, `truth` (NaN when missing), every
    /// estimator's estimate and variances (first `nx` values of each pair in `estimates`) and
    /// every node's slot (`obs`, in node order; a node missing from it was lost).
    pub(super) fn record<'a>(
        &mut self,
        (session, k): (u32, u32),
        timing: [u64; 3],
        truth: Option<&[f64; MAX_NX]>,
        estimates: impl Iterator<Item = (&'a [f64; MAX_NX], &'a [f64; MAX_NX])>,
        obs: &[Observation],
    ) {
        let nx = self.nx;
        self.keys.push((session, k));
        self.timing.push(timing);
        for j in 0..nx {
            self.truth.push(truth.map_or(f64::NAN, |x| x[j]));
        }
        for (x, v) in estimates {
            self.estimates.extend_from_slice(&x[..nx]);
            self.var.extend_from_slice(&v[..nx]);
        }
        for n in 0..self.nodes {
            self.status.push(
                obs.get(n)
                    .map_or(crate::view::tap::LOST, crate::view::tap::slot_status),
            );
        }
    }

    /// Marks node `node`'s slot of instant `k` of `session` late (it came after the instant
    /// was handed on, `--lag`); only the newest recorded instants are looked at.
    pub(super) fn mark_late(&mut self, (session, k): (u32, u32), node: u8) {
        let node = usize::from(node);
        if node >= self.nodes {
            return;
        }
        let found = self
            .keys
            .iter()
            .rev()
            .take(LATE_SEARCH)
            .position(|&key| key == (session, k));
        if let Some(back) = found {
            let i = self.keys.len() - 1 - back;
            self.status[i * self.nodes + node] = crate::view::tap::LATE;
        }
    }

    /// Writes `session,k,truth_0..,<est>_0..` rows.
    pub fn write_estimates_csv(&self, path: &std::path::Path) -> Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
        );
        let mut head = String::from("session,k");
        for j in 0..self.nx {
            head.push_str(&format!(",truth_{j}"));
        }
        for n in &self.names {
            for j in 0..self.nx {
                head.push_str(&format!(",{n}_{j}"));
            }
        }
        writeln!(w, "{head}").with_context(|| format!("cannot write {path:?}"))?;
        let ne = self.names.len();
        for (i, (session, k)) in self.keys.iter().enumerate() {
            write!(w, "{session},{k}").with_context(|| format!("cannot write {path:?}"))?;
            for v in &self.truth[i * self.nx..(i + 1) * self.nx] {
                write!(w, ",{v:e}").with_context(|| format!("cannot write {path:?}"))?;
            }
            for v in &self.estimates[i * self.nx * ne..(i + 1) * self.nx * ne] {
                write!(w, ",{v:e}").with_context(|| format!("cannot write {path:?}"))?;
            }
            writeln!(w).with_context(|| format!("cannot write {path:?}"))?;
        }
        // Dropping a BufWriter loses its last error: a full disk must fail the write.
        w.flush()
            .with_context(|| format!("cannot write {path:?}"))?;
        Ok(())
    }

    /// Writes `session,k,t_s,transport_us,end_to_end_us` rows, one per instant: `t_s` is the
    /// send time of the slot that completed the instant, in seconds since the first recorded
    /// one; the latencies are that slot sent → received and sent → all estimates published.
    /// The end-to-end column is the end-to-end histogram's samples in order; the transport
    /// histogram also holds the other nodes' slots.
    pub fn write_latency_csv(&self, path: &std::path::Path) -> Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
        );
        writeln!(w, "session,k,t_s,transport_us,end_to_end_us")
            .with_context(|| format!("cannot write {path:?}"))?;
        for ((session, k), tr) in self.keys.iter().zip(&self.timing) {
            let (t_s, transport, e2e) = self.latency_point(tr);
            writeln!(w, "{session},{k},{t_s:.6},{transport:.3},{e2e:.3}")
                .with_context(|| format!("cannot write {path:?}"))?;
        }
        w.flush()
            .with_context(|| format!("cannot write {path:?}"))?;
        Ok(())
    }

    /// `(seconds since the first recorded send, transport µs, end to end µs)` of one
    /// recorded instant.
    pub fn latency_point(&self, tr: &[u64; 3]) -> (f64, f64, f64) {
        let t0 = self.timing.first().map_or(0, |t| t[0]);
        (
            tr[0].saturating_sub(t0) as f64 * 1e-9,
            tr[1].saturating_sub(tr[0]) as f64 * 1e-3,
            tr[2].saturating_sub(tr[0]) as f64 * 1e-3,
        )
    }

    /// Writes the recorded instants as an MCAP file ([`crate::mcap_file`]; needs `full`).
    pub fn write_mcap(&self, path: &std::path::Path, scenario: &str) -> Result<()> {
        let (nx, ne) = (self.nx, self.names.len());
        let nodes = self.nodes;
        let mut w = crate::mcap_file::McapWriter::create(path, scenario, nx, &self.names)?;
        for (i, ((session, k), tr)) in self.keys.iter().zip(&self.timing).enumerate() {
            let truth = &self.truth[i * nx..(i + 1) * nx];
            w.instant(&crate::mcap_file::InstantRecord {
                session: *session,
                k: *k,
                times: crate::mcap_file::Times {
                    sent: tr[0],
                    received: tr[1],
                    published: tr[2],
                },
                truth: truth.iter().all(|v| !v.is_nan()).then_some(truth),
                obs: self.obs.get(i * nodes..(i + 1) * nodes).unwrap_or(&[]),
                xhat: &self.estimates[i * nx * ne..(i + 1) * nx * ne],
                cov: self
                    .cov
                    .get(i * nx * nx * ne..(i + 1) * nx * nx * ne)
                    .unwrap_or(&[]),
                cov_kind: self.cov_kind.get(i * ne..(i + 1) * ne).unwrap_or(&[]),
            })?;
        }
        w.finish()?;
        Ok(())
    }

    /// Writes the received slots as a slot log ([`crate::slot_log`], what `replay` reads).
    pub fn write_slots_csv(&self, path: &std::path::Path, ny: usize) -> Result<()> {
        crate::slot_log::write_slots(path, &self.slots, ny, &self.late_after)
    }
}
