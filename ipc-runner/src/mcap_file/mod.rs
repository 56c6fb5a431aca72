//! `--mcap FILE` of `run`, `demo` and `replay`: the run as an MCAP file (docs/mcap.md), the
//! recording format robotics tools (Foxglove, the `mcap` readers) open. Channels: `/slots`
//! (every node's slot of every instant, delivered / dropped / lost), `/truth` (when the
//! publisher sent it) and one `/estimates/<name>` per estimator (x̂, the covariance or bound,
//! √P_ii); JSON messages with JSON schemas ([`schema`]). Uncompressed chunks with the summary,
//! message indexes and statistics, so a reader can seek and count without reading it all.
//!
//! The file is written after the run from what the run recorded, never from the loop.

pub mod schema;

use anyhow::{Context, Result};
use estpipe_wire::Observation;
use schema::{EstimateMsg, SlotMsg, TruthMsg};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// One recorded instant, as the MCAP writer takes it.
#[derive(Clone, Copy, Debug)]
pub struct InstantRecord<'a> {
    /// Session of the runner.
    pub session: u32,
    /// The instant.
    pub k: u32,
    /// Log and publish times of its messages, `CLOCK_MONOTONIC` ns (docs/mcap.md, "Times").
    pub times: Times,
    /// The truth (`nx` values), when the publisher sent it.
    pub truth: Option<&'a [f64]>,
    /// Every node's observation of the instant.
    pub obs: &'a [Observation],
    /// x̂ of every estimator, `nx` each.
    pub xhat: &'a [f64],
    /// The covariance (or bound) of every estimator, `nx · nx` row-major each.
    pub cov: &'a [f64],
    /// Per estimator, the wire's `cov_kind`.
    pub cov_kind: &'a [u32],
}

/// The times of an instant's messages (ns).
#[derive(Clone, Copy, Debug, Default)]
pub struct Times {
    /// When the instant's completing slot was sent (the publisher's clock): every message's
    /// publish time, and the truth's log time.
    pub sent: u64,
    /// When the runner received it: the slots' log time.
    pub received: u64,
    /// When its estimates were all published: the estimates' log time.
    pub published: u64,
}

/// Messages written per channel.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// `/slots` messages.
    pub slots: u64,
    /// `/truth` messages.
    pub truth: u64,
    /// Per estimator, its `/estimates/<name>` messages.
    pub estimates: Vec<u64>,
}

/// An MCAP file being written.
pub struct McapWriter {
    out: mcap::Writer<BufWriter<std::fs::File>>,
    path: PathBuf,
    nx: usize,
    names: Vec<String>,
    slots: u16,
    truth: u16,
    estimates: Vec<u16>,
    counts: Counts,
    buf: Vec<u8>,
    sigma: Vec<f64>,
}

impl std::fmt::Debug for McapWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapWriter")
            .field("path", &self.path)
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

fn mcap_err(path: &Path) -> impl Fn(mcap::McapError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("cannot write {path:?}: {e}")
}

impl McapWriter {
    /// Creates `path` for a run of `scenario` with `nx` states and the estimators `names`.
    pub fn create(path: &Path, scenario: &str, nx: usize, names: &[String]) -> Result<Self> {
        let file =
            std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?;
        let err = mcap_err(path);
        let mut out = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("estpipe ipc-runner ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(&err)?;
        let meta = BTreeMap::new();
        let schema = |out: &mut mcap::Writer<_>, (name, text): (&str, &str)| {
            out.add_schema(name, "jsonschema", text.as_bytes())
        };
        let s = schema(&mut out, schema::SLOT_SCHEMA).map_err(&err)?;
        let slots = out.add_channel(s, "/slots", "json", &meta).map_err(&err)?;
        let s = schema(&mut out, schema::TRUTH_SCHEMA).map_err(&err)?;
        let truth = out.add_channel(s, "/truth", "json", &meta).map_err(&err)?;
        let s = schema(&mut out, schema::ESTIMATE_SCHEMA).map_err(&err)?;
        let mut estimates = Vec::with_capacity(names.len());
        for n in names {
            let id = out
                .add_channel(s, &format!("/estimates/{n}"), "json", &meta)
                .map_err(&err)?;
            estimates.push(id);
        }
        let mut run = BTreeMap::new();
        run.insert("scenario".to_string(), scenario.to_string());
        run.insert("nx".to_string(), nx.to_string());
        run.insert("estimators".to_string(), names.join(","));
        out.write_metadata(&mcap::records::Metadata {
            name: "estpipe.run".to_string(),
            metadata: run,
        })
        .map_err(&err)?;
        Ok(Self {
            out,
            path: path.to_path_buf(),
            nx,
            names: names.to_vec(),
            slots,
            truth,
            estimates,
            counts: Counts {
                estimates: vec![0; names.len()],
                ..Counts::default()
            },
            buf: Vec::with_capacity(1024),
            sigma: Vec::with_capacity(nx),
        })
    }

    fn put(&mut self, channel: u16, seq: u64, log_time: u64, publish_time: u64) -> Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            // The sequence is 32 bits in MCAP; a longer run wraps (readers order by time).
            sequence: seq as u32,
            log_time,
            publish_time,
        };
        self.out
            .write_to_known_channel(&header, &self.buf)
            .map_err(mcap_err(&self.path))
    }

    fn encode<T: serde::Serialize>(&mut self, msg: &T) -> Result<()> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg)
            .with_context(|| format!("cannot write {:?}", self.path))
    }

    /// Writes one instant's messages: its slots, its truth, its estimates.
    pub fn instant(&mut self, r: &InstantRecord<'_>) -> Result<()> {
        let nx = self.nx;
        let t = r.times;
        for o in r.obs {
            let ny = if o.delivered {
                usize::from(o.ny).min(o.y.len())
            } else {
                0
            };
            self.encode(&SlotMsg {
                session: r.session,
                k: r.k,
                node: o.node,
                status: schema::slot_status(o),
                delivered: o.delivered,
                flags: o.flags,
                y: &o.y[..ny],
            })?;
            self.put(self.slots, self.counts.slots, t.received, t.sent)?;
            self.counts.slots += 1;
        }
        if let Some(x) = r.truth.filter(|x| x.iter().any(|v| v.is_finite())) {
            self.encode(&TruthMsg {
                session: r.session,
                k: r.k,
                x: &x[..nx.min(x.len())],
            })?;
            self.put(self.truth, self.counts.truth, t.sent, t.sent)?;
            self.counts.truth += 1;
        }
        for e in 0..self.estimates.len() {
            let (Some(x), Some(p)) = (
                r.xhat.get(e * nx..(e + 1) * nx),
                r.cov.get(e * nx * nx..(e + 1) * nx * nx),
            ) else {
                break;
            };
            let mut sigma = std::mem::take(&mut self.sigma);
            sigma.clear();
            sigma.extend((0..nx).map(|i| p[i * nx + i].sqrt()));
            let name = std::mem::take(&mut self.names[e]);
            let encoded = self.encode(&EstimateMsg {
                session: r.session,
                k: r.k,
                estimator: &name,
                x,
                cov_kind: schema::cov_kind_name(r.cov_kind.get(e).copied().unwrap_or(0)),
                sigma: &sigma,
                p,
            });
            self.names[e] = name;
            self.sigma = sigma;
            encoded?;
            self.put(
                self.estimates[e],
                self.counts.estimates[e],
                t.published,
                t.sent,
            )?;
            self.counts.estimates[e] += 1;
        }
        Ok(())
    }

    /// Writes the summary and closes the file: the messages written per channel.
    pub fn finish(mut self) -> Result<Counts> {
        self.out.finish().map_err(mcap_err(&self.path))?;
        use std::io::Write;
        let mut inner = self.out.into_inner();
        inner
            .flush()
            .with_context(|| format!("cannot write {:?}", self.path))?;
        Ok(self.counts)
    }
}

#[cfg(test)]
mod tests;
