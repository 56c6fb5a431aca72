//! The bridge's command line, and the zenoh configuration it makes from it.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Which end of the link this bridge is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// Beside the publisher (channel-sim or a foreign sensor process): slots and truth leave
    /// shared memory for the network, estimates come back into it.
    Sensor,
    /// Beside the runner: slots and truth come from the network, are checked, and are
    /// written into shared memory; the runner's estimates go back.
    Estimator,
}

impl Side {
    /// The side's name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Side::Sensor => "sensor",
            Side::Estimator => "estimator",
        }
    }
}

/// Default zenoh endpoint: the sensor side listens, the estimator side connects (loopback).
pub const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// Largest `--max-gap`: the lost slots of one gap are written one by one, each waiting up to
/// a second for a full runner queue, so a gap is bounded in work and time.
pub const MAX_GAP_LIMIT: u64 = 1_000_000;

/// Largest `--queue` (messages).
pub const MAX_QUEUE: usize = 1 << 20;

/// Longest `--connect-timeout` (s), as every seconds-valued flag of the product.
pub const MAX_CONNECT_TIMEOUT: f64 = 1e9;

/// `ipc-runner bridge`.
#[derive(Clone, Debug, clap::Args)]
pub struct BridgeArgs {
    /// Which end this is: `sensor` (beside the publisher) or `estimator` (beside the runner).
    #[arg(long, value_enum)]
    pub side: Side,
    /// iceoryx2 service prefix on this host.
    #[arg(long, default_value = estpipe_wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// zenoh key prefix both bridges use (`<key>/slots`, which carries the truth too,
    /// `<key>/estimates`, `<key>/acks`); default `estpipe/<prefix>` of the sensor side, so give
    /// it when the prefixes differ.
    #[arg(long)]
    pub key: Option<String>,
    /// zenoh configuration (zenoh's own JSON5: mode, endpoints, TLS, access control), passed
    /// through; --listen/--connect are applied on top of it.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// zenoh endpoint to listen on (repeatable). Without a config and without --listen or
    /// --connect: the sensor side listens on tcp/127.0.0.1:7447.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// zenoh endpoint to connect to (repeatable). Without a config and without --listen or
    /// --connect: the estimator side connects to tcp/127.0.0.1:7447.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Exit once the stream's END or ABORT has been forwarded and the estimates have gone
    /// quiet (what `demo --via zenoh` uses); otherwise run until SIGINT/SIGTERM.
    #[arg(long)]
    pub once: bool,
    /// Give up after this many seconds without the far side (or, on the estimator side,
    /// without a runner); 0 waits forever.
    #[arg(long, default_value_t = 0.0, value_name = "S")]
    pub connect_timeout: f64,
    /// Messages the zenoh subscriber queues before the network pushes back.
    #[arg(long, default_value_t = 4096, value_name = "N")]
    pub queue: usize,
    /// A sequence gap longer than this many slots (at most 1 000 000) is not filled with
    /// lost slots (counted as `gap_too_large`; the runner then sees the gap itself).
    #[arg(long, default_value_t = 100_000, value_name = "SLOTS")]
    pub max_gap: u64,
    /// Write the report (counts by reason, latency) as JSON to FILE on exit.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// Stop (as on SIGTERM) once the process PID is no longer this bridge's parent, e.g.
    /// because it died (`ipc-runner demo --via zenoh` passes its own pid).
    #[arg(long, value_name = "PID")]
    pub parent_pid: Option<u32>,
    /// Test hook (sensor side): break the version byte of every Nth slot message after this
    /// side's own check, so the far side must refuse it.
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true, value_name = "N")]
    pub debug_corrupt_every: Option<u64>,
    /// No progress or summary lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

impl BridgeArgs {
    /// `--debug-corrupt-every N` (feature `test-hooks`).
    #[cfg(feature = "test-hooks")]
    pub(crate) fn corrupt_every(&self) -> Option<u64> {
        self.debug_corrupt_every
    }

    /// A shipped build parses no test hook.
    #[cfg(not(feature = "test-hooks"))]
    pub(crate) fn corrupt_every(&self) -> Option<u64> {
        None
    }

    /// Says `what` this side of the prefix is doing on stderr, unless `--quiet`.
    pub(crate) fn progress(&self, what: &str) {
        if !self.quiet {
            estpipe_process::errln!(
                "bridge: {} side of {}: {what}",
                self.side.name(),
                self.prefix
            );
        }
    }

    /// The flags' own ranges and the files they name (exit 2 on a violation, as every bad
    /// flag), before anything starts: also the `--zenoh-config` file, read and applied.
    pub fn check(&self) -> Result<()> {
        if !(self.connect_timeout.is_finite()
            && (0.0..=MAX_CONNECT_TIMEOUT).contains(&self.connect_timeout))
        {
            bail!(
                "--connect-timeout must be a finite number of seconds in [0, {MAX_CONNECT_TIMEOUT:e}], \
                 got {}",
                self.connect_timeout
            );
        }
        if self.queue == 0 || self.queue > MAX_QUEUE {
            bail!("--queue must be in 1..={MAX_QUEUE}, got {}", self.queue);
        }
        if self.max_gap > MAX_GAP_LIMIT {
            bail!(
                "--max-gap must be in 0..={MAX_GAP_LIMIT} slots, got {}",
                self.max_gap
            );
        }
        if let Some(p) = &self.report {
            check_writable(p)?;
        }
        let key = self.key();
        // A key is printed in every progress line and in the report.
        if key.chars().any(char::is_control) {
            bail!("--key {key:?} must not contain control characters");
        }
        zenoh::key_expr::KeyExpr::try_from(format!("{key}/slots"))
            .map_err(|e| anyhow::anyhow!("--key {key:?} is not a zenoh key expression: {e}"))?;
        if key.contains(['*', '$', '#', '?']) {
            bail!("--key {key:?} must name one key, without wildcards");
        }
        for (flag, endpoints) in [("--listen", &self.listen), ("--connect", &self.connect)] {
            for e in endpoints {
                check_endpoint(e).map_err(|why| anyhow::anyhow!("{flag} {e:?}: {why}"))?;
            }
        }
        self.zenoh_config()?;
        Ok(())
    }

    /// The zenoh key prefix.
    pub fn key(&self) -> String {
        self.key
            .clone()
            .unwrap_or_else(|| format!("estpipe/{}", self.prefix))
    }

    /// The zenoh configuration: the file if given, else zenoh's defaults with multicast
    /// scouting off (two bridges on one LAN must not find each other by accident), then
    /// --listen/--connect, then the loopback default for a side that was given neither.
    pub fn zenoh_config(&self) -> Result<zenoh::Config> {
        let mut c = match &self.zenoh_config {
            Some(p) => zenoh::Config::from_file(p)
                .map_err(|e| anyhow::anyhow!("--zenoh-config {}: {e}", p.display()))?,
            None => {
                let mut c = zenoh::Config::default();
                set(&mut c, "scouting/multicast/enabled", "false")?;
                c
            }
        };
        let (mut listen, mut connect) = (self.listen.clone(), self.connect.clone());
        if self.zenoh_config.is_none() && listen.is_empty() && connect.is_empty() {
            match self.side {
                Side::Sensor => listen.push(DEFAULT_ENDPOINT.into()),
                Side::Estimator => connect.push(DEFAULT_ENDPOINT.into()),
            }
        }
        if !listen.is_empty() {
            set(&mut c, "listen/endpoints", &serde_json::to_string(&listen)?)?;
        }
        if !connect.is_empty() {
            set(
                &mut c,
                "connect/endpoints",
                &serde_json::to_string(&connect)?,
            )?;
        }
        crate::security::check(&c, crate::security::Built::THIS)?;
        Ok(c)
    }
}

/// What zenoh only finds when the session opens (an error that reads like a failure of the
/// network, exit 1), checked with the flags: an IP endpoint's port is a number below 65536
/// and a dotted host is an IPv4 address. The rest of the syntax is zenoh's to check.
fn check_endpoint(endpoint: &str) -> std::result::Result<(), String> {
    let address = endpoint.split(['#', '?']).next().unwrap_or_default();
    let Some((proto, address)) = address.split_once('/') else {
        return Ok(());
    };
    if !matches!(proto, "tcp" | "udp" | "tls" | "quic" | "ws") {
        return Ok(());
    }
    let Some((host, port)) = address.rsplit_once(':') else {
        return Err(format!("a {proto} endpoint is {proto}/HOST:PORT"));
    };
    if port.parse::<u16>().is_err() {
        return Err(format!("port {port:?} is not a port number (0..=65535)"));
    }
    let dotted = !host.is_empty() && host.chars().all(|c| c.is_ascii_digit() || c == '.');
    if dotted && host.parse::<std::net::Ipv4Addr>().is_err() {
        return Err(format!("host {host:?} is not an IPv4 address"));
    }
    Ok(())
}

fn set(c: &mut zenoh::Config, key: &str, value: &str) -> Result<()> {
    c.insert_json5(key, value)
        .map_err(|e| anyhow::anyhow!("zenoh configuration {key} = {value}: {e}"))
}

/// Fails now, not after the run, when `p` cannot be written.
fn check_writable(p: &std::path::Path) -> Result<()> {
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    let meta = std::fs::metadata(dir)
        .with_context(|| format!("--report {}: directory {}", p.display(), dir.display()))?;
    if !meta.is_dir() || meta.permissions().readonly() {
        bail!(
            "--report {}: {} is not a writable directory",
            p.display(),
            dir.display()
        );
    }
    Ok(())
}
