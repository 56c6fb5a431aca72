//! The embedded vector files: which files and the hashes they must have, their byte layout
//! (version 1: one record per instant, the occlusion and token-bucket streams; version 2: one
//! slot per instant and node, the three-node Tobit stream), and the two parsers, which yield
//! the [`Instant`]s an estimator sees.

use core::fmt;

use nalgebra::Vector2;

use super::digest::fnv1a64;
use super::drive::Instant;

/// An embedded vector file and the FNV-1a 64 it must have: a regenerated or corrupted file
/// fails both the firmware's boot check and the host test until the constant is updated on
/// purpose. All files are written by `cargo run -p channel-sim --example firmware_vectors`
/// (see the firmware README).
#[derive(Clone, Copy, Debug)]
pub struct Vectors {
    /// The file's bytes.
    pub bytes: &'static [u8],
    /// Its expected FNV-1a 64.
    pub fnv1a64: u64,
}

impl Vectors {
    /// Parses a version-1 file (one record per instant) after checking its hash.
    pub fn stream(&self) -> Result<Stream<'static>, StreamError> {
        Stream::parse_checked(self.bytes, self.fnv1a64)
    }

    /// Parses a version-2 file (one slot per instant and node) after checking its hash.
    pub fn node_stream(&self) -> Result<NodeStream<'static>, StreamError> {
        NodeStream::parse_checked(self.bytes, self.fnv1a64)
    }
}

/// The occlusion stream (seed 001, Section IV).
pub const OCCLUSION: Vectors = Vectors {
    bytes: include_bytes!("../../vectors/occlusion.bin"),
    fnv1a64: 0x3def_2fa7_871d_31a1,
};

/// The token-bucket stream (seed 003, Section IV).
pub const NN: Vectors = Vectors {
    bytes: include_bytes!("../../vectors/nn.bin"),
    fnv1a64: 0xb40d_7d3d_c0d6_dc1e,
};

/// The three-node Tobit stream (seed 004, section 4), format version 2.
pub const TOBIT: Vectors = Vectors {
    bytes: include_bytes!("../../vectors/tobit.bin"),
    fnv1a64: 0x8275_0f1a_ed82_b55a,
};

/// File magic of every vector file (the version that follows selects the layout).
pub const MAGIC: [u8; 4] = *b"EFV1";
/// Format version of the one-record-per-instant layout.
pub const FORMAT_VERSION: u32 = 1;
/// Header bytes: magic, version u32, seed u64, steps u32, nx u32, ny u32, record size u32.
pub const HEADER_LEN: usize = 32;
/// Bytes per instant: k u32, delivered u8, label u8, 2 reserved, channel flags u32,
/// y f32×2, truth f32×3 (all little-endian).
pub const RECORD_LEN: usize = 32;
/// State dimension of the version-1 streams.
pub const NX: usize = 3;
/// Measurement dimension (of every stream).
pub const NY: usize = 2;
/// Format version of the one-slot-per-node layout.
pub const NODE_FORMAT_VERSION: u32 = 2;
/// Version-2 header: the version-1 fields, then nodes u32 and 4 reserved bytes.
pub const NODE_HEADER_LEN: usize = 40;
/// Sensor nodes of the Tobit stream.
pub const NODES: usize = 3;
/// State dimension of the Tobit stream.
pub const TOBIT_NX: usize = 2;
/// Bytes per node slot: delivered u8, 3 reserved, channel flags u32, y f32×2.
pub const SLOT_LEN: usize = 8 + 4 * NY;
/// Bytes per instant of the Tobit stream: k u32, truth f32×2, then one slot per node.
pub const NODE_RECORD_LEN: usize = 4 + 4 * TOBIT_NX + NODES * SLOT_LEN;

/// Why a vector file was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamError {
    /// Shorter than its header says.
    Truncated,
    /// Wrong magic or format version.
    BadFormat,
    /// Dimensions or record size differ from what this firmware was built for.
    BadShape,
    /// The FNV-1a 64 of the file is not the expected one.
    BadHash,
}

impl fmt::Display for StreamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            StreamError::Truncated => "vector file truncated",
            StreamError::BadFormat => "vector file: bad magic or version",
            StreamError::BadShape => "vector file: unexpected dimensions or record size",
            StreamError::BadHash => "vector file: FNV-1a 64 mismatch",
        })
    }
}

/// What the firmware's `main` needs from a stream type: open it from the embedded file.
pub trait Source: Sized {
    /// Checks the hash and the layout.
    fn open(v: &Vectors) -> Result<Self, StreamError>;
}

impl Source for Stream<'static> {
    fn open(v: &Vectors) -> Result<Self, StreamError> {
        v.stream()
    }
}

impl Source for NodeStream<'static> {
    fn open(v: &Vectors) -> Result<Self, StreamError> {
        v.node_stream()
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(w)
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_bits(u32_at(b, at))
}

/// The header fields common to both layouts; checks magic, version, shape and total length.
/// Returns (seed, steps).
fn parse_header(
    bytes: &[u8],
    version: u32,
    header_len: usize,
    shape: &[usize],
    record_len: usize,
) -> Result<(u64, u32), StreamError> {
    if bytes.len() < header_len {
        return Err(StreamError::Truncated);
    }
    if bytes[..4] != MAGIC || u32_at(bytes, 4) != version {
        return Err(StreamError::BadFormat);
    }
    let seed = u64::from(u32_at(bytes, 8)) | (u64::from(u32_at(bytes, 12)) << 32);
    let steps = u32_at(bytes, 16);
    // nx, ny, record size, then (version 2) nodes and a reserved zero word.
    if shape
        .iter()
        .enumerate()
        .any(|(i, &want)| u32_at(bytes, 20 + 4 * i) as usize != want)
    {
        return Err(StreamError::BadShape);
    }
    let need = (steps as usize)
        .checked_mul(record_len)
        .and_then(|n| n.checked_add(header_len))
        .ok_or(StreamError::Truncated)?;
    if bytes.len() != need {
        return Err(StreamError::Truncated);
    }
    Ok((seed, steps))
}

/// One sampling instant of a version-1 stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Sampling instant k ≥ 1.
    pub k: u32,
    /// Whether the channel delivered the measurement.
    pub delivered: bool,
    /// True region label h_k (0 outside every region), for evaluation only.
    pub label: u8,
    /// Channel flags (channel-sim's `FLAG_*` bits).
    pub flags: u32,
    /// The sensor's measurement z_k (present even when the channel dropped it: the lossless
    /// Kalman filter reference uses it).
    pub y: [f32; NY],
    /// True state x_k, for evaluation only.
    pub truth: [f32; NX],
}

/// A parsed version-1 vector file (borrowed, nothing copied).
#[derive(Clone, Copy, Debug)]
pub struct Stream<'a> {
    bytes: &'a [u8],
    /// Simulation seed the stream was generated with.
    pub seed: u64,
    /// Number of instants (k = 1..=steps).
    pub steps: u32,
}

impl<'a> Stream<'a> {
    /// Validates header, shape and length (not the hash: see [`Stream::parse_checked`]).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, StreamError> {
        let (seed, steps) = parse_header(
            bytes,
            FORMAT_VERSION,
            HEADER_LEN,
            &[NX, NY, RECORD_LEN],
            RECORD_LEN,
        )?;
        Ok(Self { bytes, seed, steps })
    }

    /// [`Stream::parse`] after checking the file's FNV-1a 64 against `expected`.
    pub fn parse_checked(bytes: &'a [u8], expected: u64) -> Result<Self, StreamError> {
        if fnv1a64(bytes) != expected {
            return Err(StreamError::BadHash);
        }
        Self::parse(bytes)
    }

    /// Instant `i` (0-based; instant k = i + 1). `None` past the end.
    pub fn record(&self, i: usize) -> Option<Record> {
        if i >= self.steps as usize {
            return None;
        }
        let r = &self.bytes[HEADER_LEN + i * RECORD_LEN..HEADER_LEN + (i + 1) * RECORD_LEN];
        Some(Record {
            k: u32_at(r, 0),
            delivered: r[4] != 0,
            label: r[5],
            flags: u32_at(r, 8),
            y: [f32_at(r, 12), f32_at(r, 16)],
            truth: [f32_at(r, 20), f32_at(r, 24), f32_at(r, 28)],
        })
    }

    /// All instants in order.
    pub fn records(&self) -> impl Iterator<Item = Record> + '_ {
        (0..self.steps as usize).filter_map(move |i| self.record(i))
    }

    /// The instants as a single-node estimator sees them: the measurement if the channel
    /// delivered it (or always, on the lossless link).
    pub fn instants(&self, link: Link) -> impl Iterator<Item = Instant<1>> + '_ {
        self.records().map(move |r| Instant {
            k: r.k,
            y: [(r.delivered || link == Link::Lossless).then(|| Vector2::from(r.y))],
        })
    }
}

/// What one node's channel slot held at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slot {
    /// Whether the node transmitted (triggered and granted a token, α β = 1).
    pub delivered: bool,
    /// Channel flags (channel-sim's `FLAG_*` bits: triggered, token-blocked, censored).
    pub flags: u32,
    /// The measurement as delivered (censored components equal τ); 0 when nothing was sent.
    pub y: [f32; NY],
}

/// One sampling instant of a version-2 stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeRecord {
    /// Sampling instant t ≥ 1.
    pub k: u32,
    /// True state x_t, for evaluation only.
    pub truth: [f32; TOBIT_NX],
    /// Node m's slot, m = 0..NODES.
    pub nodes: [Slot; NODES],
}

/// A parsed version-2 vector file: one slot per instant and node (borrowed, nothing copied).
#[derive(Clone, Copy, Debug)]
pub struct NodeStream<'a> {
    bytes: &'a [u8],
    /// Simulation seed the stream was generated with.
    pub seed: u64,
    /// Number of instants (t = 1..=steps).
    pub steps: u32,
}

impl<'a> NodeStream<'a> {
    /// Validates header, shape (n_x = 2, n_y = 2, 3 nodes) and length (not the hash).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, StreamError> {
        let (seed, steps) = parse_header(
            bytes,
            NODE_FORMAT_VERSION,
            NODE_HEADER_LEN,
            &[TOBIT_NX, NY, NODE_RECORD_LEN, NODES, 0],
            NODE_RECORD_LEN,
        )?;
        Ok(Self { bytes, seed, steps })
    }

    /// [`NodeStream::parse`] after checking the file's FNV-1a 64 against `expected`.
    pub fn parse_checked(bytes: &'a [u8], expected: u64) -> Result<Self, StreamError> {
        if fnv1a64(bytes) != expected {
            return Err(StreamError::BadHash);
        }
        Self::parse(bytes)
    }

    /// Instant `i` (0-based; instant t = i + 1). `None` past the end.
    pub fn record(&self, i: usize) -> Option<NodeRecord> {
        if i >= self.steps as usize {
            return None;
        }
        let at = NODE_HEADER_LEN + i * NODE_RECORD_LEN;
        let r = &self.bytes[at..at + NODE_RECORD_LEN];
        Some(NodeRecord {
            k: u32_at(r, 0),
            truth: [f32_at(r, 4), f32_at(r, 8)],
            nodes: core::array::from_fn(|m| {
                let s = &r[12 + m * SLOT_LEN..12 + (m + 1) * SLOT_LEN];
                Slot {
                    delivered: s[0] != 0,
                    flags: u32_at(s, 4),
                    y: [f32_at(s, 8), f32_at(s, 12)],
                }
            }),
        })
    }

    /// All instants in order.
    pub fn records(&self) -> impl Iterator<Item = NodeRecord> + '_ {
        (0..self.steps as usize).filter_map(move |i| self.record(i))
    }

    /// The instants as the fusion filter sees them: per node, the measurement it delivered.
    pub fn instants(&self) -> impl Iterator<Item = Instant<NODES>> + '_ {
        self.records().map(|r| Instant {
            k: r.k,
            y: r.nodes.map(|s| s.delivered.then(|| Vector2::from(s.y))),
        })
    }
}

/// Whether a single-node estimator sees the channel's dropouts or every sensor measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Every instant's sensor measurement (the lossless reference).
    Lossless,
    /// Only what the channel delivered.
    Channel,
}
