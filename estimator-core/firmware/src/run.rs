//! The target-independent half of the firmware: the embedded measurement streams, the models
//! they were simulated from, and one generic driver ([`drive`]) that runs any estimator
//! ([`Driven`]) in `f32` over a stream and digests every estimate.
//!
//! The same file is compiled into the firmware (Cortex-M4F) and into the host check
//! (`tests/firmware_qemu.rs`, through `#[path]`), so the two sides run the same source over the
//! same bytes; the check is that their results agree bit for bit.
//!
//! No `unsafe`, no allocation, no panics on the stream's content: a malformed stream is a
//! [`StreamError`], an estimator error is counted in [`Summary::errors`]. No floating-point
//! function of `std` is called (on the host it would be the platform's libm, on the target
//! there is none): transcendental functions go through nalgebra's `ComplexField`, which
//! `estimator-core`'s `libm-force` routes to the `libm` crate on both sides.
#![forbid(unsafe_code)]

use core::fmt;

use estimator_core::filter::nn::NnBoundConfig;
use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo, NnTbcpEstimator};
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
use estimator_core::filter::{IntermittentKalmanFilter, KalmanFilter, TobitFusion};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearModel;
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use estimator_core::Error;
use nalgebra::{ComplexField, Matrix2, Matrix2x3, Matrix3, SMatrix, SVector, Vector2, Vector3};

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
    bytes: include_bytes!("../vectors/occlusion.bin"),
    fnv1a64: 0x3def_2fa7_871d_31a1,
};

/// The token-bucket stream (seed 003, Section IV).
pub const NN: Vectors = Vectors {
    bytes: include_bytes!("../vectors/nn.bin"),
    fnv1a64: 0xb40d_7d3d_c0d6_dc1e,
};

/// The three-node Tobit stream (seed 004, section 4), format version 2.
pub const TOBIT: Vectors = Vectors {
    bytes: include_bytes!("../vectors/tobit.bin"),
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
/// Largest state dimension of a result line.
pub const MAX_NX: usize = 3;

/// FNV-1a, 64 bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a64(pub u64);

impl Default for Fnv1a64 {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a64 {
    /// Feeds bytes.
    pub fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// Feeds the IEEE-754 bit pattern of `x`, little-endian.
    pub fn f32(&mut self, x: f32) {
        self.bytes(&x.to_bits().to_le_bytes());
    }

    /// Feeds an estimate: every entry of x̂, then the upper triangle of P row by row.
    pub fn estimate<const N: usize>(&mut self, x: &SVector<f32, N>, p: &SMatrix<f32, N, N>) {
        for i in 0..N {
            self.f32(x[i]);
        }
        for i in 0..N {
            for j in i..N {
                self.f32(p[(i, j)]);
            }
        }
    }
}

/// FNV-1a 64 of a byte string.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv1a64::default();
    h.bytes(bytes);
    h.0
}

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

/// One sampling instant as an estimator sees it: k and what each of the `L` nodes delivered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instant<const L: usize> {
    /// Sampling instant k ≥ 1.
    pub k: u32,
    /// Node m's measurement, `None` when nothing arrived.
    pub y: [Option<Vector2<f32>>; L],
}

/// What one estimator did over the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Summary {
    /// Estimator name (`kf`, `ikf`, …).
    pub name: &'static str,
    /// Instants processed.
    pub steps: u32,
    /// Measurements used (per node and instant).
    pub arrivals: u32,
    /// Node slots without a measurement (per node and instant).
    pub dropouts: u32,
    /// Steps that returned an error (the estimator kept its previous state).
    pub errors: u32,
    /// Instant k of the first error (0 if none).
    pub first_error: u32,
    /// FNV-1a 64 over every step's label byte and estimate (see [`Driven::digest`]).
    pub digest: u64,
    /// Entries of x̂ in `x_bits` (0 if the estimator could not be built).
    pub nx: usize,
    /// Bit patterns of the final x̂ (the first `nx`).
    pub x_bits: [u32; MAX_NX],
}

impl Summary {
    fn new(name: &'static str) -> Self {
        Self {
            name,
            steps: 0,
            arrivals: 0,
            dropouts: 0,
            errors: 0,
            first_error: 0,
            digest: Fnv1a64::default().0,
            nx: 0,
            x_bits: [0; MAX_NX],
        }
    }

    fn error(&mut self, k: u32) {
        if self.errors == 0 {
            self.first_error = k;
        }
        self.errors += 1;
    }

    /// The final estimate as numbers (entries past `nx` are 0).
    pub fn x(&self) -> [f32; MAX_NX] {
        self.x_bits.map(f32::from_bits)
    }
}

/// The result line; the host check compares it character for character.
impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} steps={} arrivals={} dropouts={} errors={} first_error={} digest={:016x} x=[",
            self.name,
            self.steps,
            self.arrivals,
            self.dropouts,
            self.errors,
            self.first_error,
            self.digest,
        )?;
        for (i, b) in self.x_bits.iter().take(self.nx).enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:08x}")?;
        }
        f.write_str("]")
    }
}

/// An estimator as the driver sees it: one instant with what each of the `L` nodes delivered.
/// On error the estimator must keep its state (the core's contract).
pub trait Driven<const L: usize> {
    /// Whether [`Driven::step`] returns a region label; if not, the digest records 0 for
    /// every step, else the label (255 for a refused step).
    const LABELS: bool;
    /// One instant; returns the region-label estimate (ignored unless [`Driven::LABELS`]).
    fn step(&mut self, k: usize, y: [Option<&Vector2<f32>>; L]) -> Result<usize, Error>;
    /// Feeds the current estimate into the digest (x̂, then P's upper triangle, …).
    fn digest(&self, h: &mut Fnv1a64);
    /// The current x̂.
    fn x(&self) -> &[f32];
}

/// Runs the estimator's constructor in a frame of its own, and [`step_all`] the steps in
/// another: the constructor's temporaries (model and region validation, Gaussian-sum tables)
/// and the steps' then share the same stack instead of being laid out side by side in one
/// frame of the driver (stack coloring does not overlap them once everything is inlined).
#[inline(never)]
fn construct<E>(build: impl FnOnce() -> Result<E, Error>) -> Result<E, Error> {
    build()
}

/// The one driver: builds the estimator, steps it over the first `steps` instants (all of them
/// if `steps` exceeds the stream), and digests after every instant the label byte and the
/// estimate. Counts arrivals and dropouts per node slot, and the refused steps.
pub fn drive<const L: usize, E: Driven<L>>(
    name: &'static str,
    instants: impl Iterator<Item = Instant<L>>,
    steps: usize,
    build: impl FnOnce() -> Result<E, Error>,
) -> Summary {
    let mut s = Summary::new(name);
    // Borrowed in place: moving the estimator out of the `Result` would be a second copy of
    // it on the stack.
    let mut built = construct(build);
    let Ok(est) = &mut built else {
        s.errors = 1;
        return s;
    };
    s.digest = step_all(&mut s, est, instants.take(steps));
    let x = est.x();
    s.nx = x.len().min(MAX_NX);
    for (b, v) in s.x_bits.iter_mut().zip(x) {
        *b = v.to_bits();
    }
    s
}

/// The loop of [`drive`], in a frame of its own (see [`construct`]). Returns the digest.
#[inline(never)]
fn step_all<const L: usize, E: Driven<L>>(
    s: &mut Summary,
    est: &mut E,
    instants: impl Iterator<Item = Instant<L>>,
) -> u64 {
    let mut h = Fnv1a64::default();
    for inst in instants {
        s.steps += 1;
        for y in &inst.y {
            if y.is_some() {
                s.arrivals += 1;
            } else {
                s.dropouts += 1;
            }
        }
        let label = match est.step(inst.k as usize, inst.y.each_ref().map(Option::as_ref)) {
            Ok(label) => label,
            Err(_) => {
                s.error(inst.k);
                usize::MAX
            }
        };
        h.bytes(&[if E::LABELS { label.min(255) as u8 } else { 0 }]);
        est.digest(&mut h);
    }
    h.0
}

/// Seed 001 Section IV in `f32`: A, C as printed, B = I₃, D = I₂ (DESIGN.md), Q = 0.3 I₃,
/// R = 0.2 I₂.
pub fn model() -> Result<Model, Error> {
    LinearModel::new(
        Matrix3::new(1.01, 0.1, 0.0, 0.0, 1.01, 0.1, 0.0, 0.0, -1.02),
        Matrix3::identity(),
        Matrix2x3::new(2.0, 3.0, 1.0, 1.0, 0.0, 0.98),
        SMatrix::<f32, NY, NY>::identity(),
        Matrix3::identity() * 0.3,
        SMatrix::<f32, NY, NY>::identity() * 0.2,
    )
}

/// Prior of seed 001: x̂₀ = μ₀ = [5 5 5]ᵀ, P₀ = Σ₀ = 4 I₃.
pub fn prior() -> (Vector3<f32>, Matrix3<f32>) {
    (Vector3::new(5.0, 5.0, 5.0), Matrix3::identity() * 4.0)
}

/// The model type of the occlusion stream.
pub type Model = LinearModel<f32, NX, NX, NY, NY>;

/// An estimator of the occlusion stream: one instant `k` with the measurement or `None` on a
/// dropout; returns the region-label estimate (0 for estimators that have none).
pub trait OcclusionEstimator {
    /// One instant.
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error>;
    /// Current x̂_k.
    fn state(&self) -> &Vector3<f32>;
    /// Current P_k.
    fn covariance(&self) -> &Matrix3<f32>;
}

/// An occlusion-stream estimator with its model, as the driver runs it; the digest covers
/// the label, x̂_k and P_k.
#[derive(Clone, Debug)]
pub struct OnModel<E> {
    /// Seed 001's model.
    pub model: Model,
    /// The estimator.
    pub est: E,
}

impl<E: OcclusionEstimator> OnModel<E> {
    /// `est` on seed 001's model.
    pub fn new(est: E) -> Result<Self, Error> {
        Ok(Self {
            model: model()?,
            est,
        })
    }
}

impl<E: OcclusionEstimator> Driven<1> for OnModel<E> {
    const LABELS: bool = true;
    // Not inlined into the driver's loop: the step's temporaries then live only while it
    // runs (measured: adf 4 152 -> 4 048 B peak stack, the others equal or lower).
    #[inline(never)]
    fn step(&mut self, k: usize, [y]: [Option<&Vector2<f32>>; 1]) -> Result<usize, Error> {
        self.est.step(&self.model, k, y)
    }
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.est.state(), self.est.covariance());
    }
    fn x(&self) -> &[f32] {
        self.est.state().as_slice()
    }
}

impl OcclusionEstimator for KalmanFilter<f32, NX> {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        match y {
            Some(y) => KalmanFilter::step(self, m, k, y),
            None => self.predict(m, k.saturating_sub(1)),
        }
        .map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        KalmanFilter::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        KalmanFilter::covariance(self)
    }
}

impl OcclusionEstimator for IntermittentKalmanFilter<f32, NX> {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        IntermittentKalmanFilter::step(self, m, k, y).map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        IntermittentKalmanFilter::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        IntermittentKalmanFilter::covariance(self)
    }
}

/// The Kalman filter on a lossless link: every instant's sensor measurement is used,
/// dropped or not (the reference the other estimators are compared with).
pub fn run_kf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf", stream.instants(Link::Lossless), steps, || {
        let (x0, p0) = prior();
        OnModel::new(KalmanFilter::new(x0, p0)?)
    })
}

/// The intermittent Kalman filter: updates on delivered instants, predicts through dropouts.
pub fn run_ikf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("ikf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(IntermittentKalmanFilter::new(x0, p0)?)
    })
}

/// Seed 001's dropout mechanism in `f32`: E = [1 0 0], Ψ = 0.1, regions [20i − 5, 20i + 5].
pub fn occlusion() -> Result<Occlusion<f32, NX, 1, 4>, Error> {
    use nalgebra::{Matrix1, Matrix1x3, Vector1};
    let c = |z: f32| Vector1::new(z);
    let regions = OcclusionRegions::new([c(20.0), c(40.0), c(60.0), c(80.0)], [5.0; 4])?;
    Occlusion::new(Matrix1x3::new(1.0, 0.0, 0.0), Matrix1::new(0.1), regions)
}

/// The CCE as configured for the stream: N = 15 Gaussians per region, KL-optimal σ̂.
pub type Cce = CrossCoupledEstimator<f32, NX, 1, 4, 15>;

impl OcclusionEstimator for Cce {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        Cce::step(self, m, k, y)
    }
    fn state(&self) -> &Vector3<f32> {
        Cce::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        Cce::covariance(self)
    }
}

/// The cross-coupled estimator (seed 001, Algorithms 1-2).
pub fn run_cce(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("cce", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        let g = GaussSum::<f32, 1, 15>::uniform()?;
        OnModel::new(Cce::new(x0, p0, occlusion()?, &g)?)
    })
}

/// The assumed-density filter with exact interval likelihoods (the product's improvement).
pub type Adf = AssumedDensityFilter<f32, NX, 4>;

impl OcclusionEstimator for Adf {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        Adf::step(self, m, k, y)
    }
    fn state(&self) -> &Vector3<f32> {
        Adf::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        Adf::covariance(self)
    }
}

/// The assumed-density filter over the stream.
pub fn run_adf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("adf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(Adf::new(x0, p0, occlusion()?)?)
    })
}

/// The linear MMSE filter with Bernoulli arrivals (KF-IO, DESIGN.md's construction).
pub type KfIoF32 = KfIo<f32, NX, 4>;

impl OcclusionEstimator for KfIoF32 {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        KfIoF32::step(self, m, k, y).map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        KfIoF32::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        KfIoF32::covariance(self)
    }
}

/// KF-IO over the stream.
pub fn run_kf_io(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf-io", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(KfIoF32::new(x0, p0, occlusion()?)?)
    })
}

/// The seed 003 NN estimator in `f32` with the paper's configuration (Section IV), on the
/// token-bucket stream.
pub type Nn = Seed003Nn<f32>;

/// Step `i` takes instant `k = i + 1`'s observation (`None` when the bucket withheld it) and
/// yields x̂_k; the digest covers x̂_k and the bound P̄_k.
impl Driven<1> for Nn {
    const LABELS: bool = false;
    fn step(&mut self, _k: usize, [y]: [Option<&Vector2<f32>>; 1]) -> Result<usize, Error> {
        NnTbcpEstimator::step(self, &Seed003Example, y).map(|()| 0)
    }
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.state(), self.bound_p());
    }
    fn x(&self) -> &[f32] {
        self.state().as_slice()
    }
}

/// The NN estimator over the token-bucket stream.
pub fn run_nn(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("nn", stream.instants(Link::Channel), steps, || {
        Nn::seed003(NnBoundConfig::seed003_example())
    })
}

/// σ_m of the example's triggers (seed 004, section 4).
pub const TOBIT_SIGMA: [f32; NODES] = [0.1, 0.2, 0.3];
/// λ_m of the example's triggers.
pub const TOBIT_LAMBDA: [f32; NODES] = [0.1, 0.2, 0.1];
/// χ_m (the example's "θ_m = 5", DESIGN.md).
pub const TOBIT_CHI: f32 = 5.0;
/// η_{m,0}.
pub const TOBIT_ETA0: f32 = 1.5;

/// Seed 004's oscillator in `f32`, per instant and node as [`TobitFusion::step`] takes it:
/// A = [cos w  sin w; −sin w  cos w] with w = 0.052π, B Q Bᵀ with B = [0.16 0.18]ᵀ, Q = 0.05,
/// C_m = I₂ and R_m = 0.5 I₂ (as variances) for every node. Time-invariant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitModel {
    /// A.
    pub a: Matrix2<f32>,
    /// B Q Bᵀ (the fusion scales it by α_m⁻¹ per node, eq. 51).
    pub bqb: Matrix2<f32>,
    /// C_m.
    pub c: [Matrix2<f32>; NODES],
    /// The variances R_m,j.
    pub r: [Vector2<f32>; NODES],
}

impl TobitModel {
    /// The example's matrices. sin and cos are evaluated in f64 (as channel-sim does) by the
    /// `libm` crate on both sides, then rounded to f32 once.
    pub fn paper_example() -> Self {
        let w = 0.052 * core::f64::consts::PI;
        let (s, c) = (ComplexField::sin(w) as f32, ComplexField::cos(w) as f32);
        let b = Vector2::new(0.16f32, 0.18);
        Self {
            a: Matrix2::new(c, s, -s, c),
            bqb: b * b.transpose() * 0.05,
            c: [Matrix2::identity(); NODES],
            r: [Vector2::repeat(0.5); NODES],
        }
    }
}

/// The federated Tobit fusion filter of the stream: 3 local Tobit filters on (n_x, n_y) = (2, 2).
pub type Fusion = TobitFusion<f32, TOBIT_NX, NY, NODES>;

/// Seed 004's estimator side as the firmware runs it: the fusion filter and its model.
#[derive(Clone, Debug)]
pub struct Tobit {
    /// The example's matrices.
    pub model: TobitModel,
    /// The three local filters and the fusion centre.
    pub fusion: Fusion,
}

impl Tobit {
    /// Node `m`'s local filter: τ_m = 0, ε as in section 4, the trigger's σ, χ, λ, η₀ (λχ ≤ 1
    /// is accepted, as the example needs), d = 1.5, e = 2.
    pub fn node_config(m: usize) -> Result<TobitFilterConfig<f32, NY>, Error> {
        let trigger = EventTriggerConfig::new_allowing_paper_violation(
            TOBIT_SIGMA[m],
            TOBIT_CHI,
            TOBIT_LAMBDA[m],
            TOBIT_ETA0,
        )?;
        TobitFilterConfig::new(
            Vector2::zeros(),
            BoundScalars::paper_example(),
            trigger,
            1.5,
            2.0,
        )
    }

    /// The example's fusion filter: α_m = 1/3, x̂₀ = [5 0]ᵀ, P₀ = I₂.
    pub fn paper_example() -> Result<Self, Error> {
        let cfgs = [
            Self::node_config(0)?,
            Self::node_config(1)?,
            Self::node_config(2)?,
        ];
        Ok(Self {
            model: TobitModel::paper_example(),
            fusion: Fusion::new(cfgs, Vector2::new(5.0, 0.0), Matrix2::identity())?,
        })
    }
}

/// One instant of Algorithm 1 on the estimator side: every local filter on what its node
/// delivered (θ = 1 holds the last received measurement), fusion (50), reset (51). The digest
/// covers x̂^g and P^g, then every node's x̂_m and P̄_m before the reset.
impl Driven<NODES> for Tobit {
    const LABELS: bool = false;
    fn step(&mut self, _k: usize, y: [Option<&Vector2<f32>>; NODES]) -> Result<usize, Error> {
        let m = &self.model;
        self.fusion.step(&m.a, &m.bqb, &m.c, &m.r, y).map(|()| 0)
    }
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.fusion.state(), self.fusion.covariance());
        for m in 0..NODES {
            if let (Some(x), Some(p)) = (self.fusion.local_state(m), self.fusion.local_bound(m)) {
                h.estimate(x, p);
            }
        }
    }
    fn x(&self) -> &[f32] {
        self.fusion.state().as_slice()
    }
}

/// The seed 004 fusion filter over the three-node Tobit stream.
pub fn run_tobit(stream: &NodeStream<'_>, steps: usize) -> Summary {
    drive("tobit", stream.instants(), steps, Tobit::paper_example)
}
