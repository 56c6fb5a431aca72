//! The target-independent half of the firmware: the embedded measurement stream, the model it
//! was simulated from, and one driver per estimator that runs the core in `f32` over the stream
//! and digests every estimate.
//!
//! The same file is compiled into the firmware (Cortex-M4F) and into the host check
//! (`tests/firmware_qemu.rs`, through `#[path]`), so the two sides run the same source over the
//! same bytes; the check is that their results agree bit for bit.
//!
//! No `unsafe`, no allocation, no panics on the stream's content: a malformed stream is a
//! [`StreamError`], an estimator error is counted in [`Summary::errors`].
#![forbid(unsafe_code)]

use core::fmt;

use estimator_core::filter::adf::AssumedDensityFilter;
use estimator_core::filter::cce::CrossCoupledEstimator;
use estimator_core::filter::kf_io::KfIo;
use estimator_core::filter::nn_bound::NnBoundConfig;
use estimator_core::filter::nn_system::{Seed003Example, Tanh};
use estimator_core::filter::nn_tbcp::{NnTbcpEstimator, Seed003Nn};
use estimator_core::filter::{IntermittentKalmanFilter, KalmanFilter};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearModel;
use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use nalgebra::{Matrix2x3, Matrix3, SMatrix, SVector, Vector2, Vector3};

/// An embedded vector file and the FNV-1a 64 it must have: a regenerated or corrupted file
/// fails both the firmware's boot check and the host test until the constant is updated on
/// purpose. Both files are written by `cargo run -p channel-sim --example firmware_vectors`
/// (see the firmware README).
#[derive(Clone, Copy, Debug)]
pub struct Vectors {
    /// The file's bytes.
    pub bytes: &'static [u8],
    /// Its expected FNV-1a 64.
    pub fnv1a64: u64,
}

impl Vectors {
    /// Parses the file after checking its hash.
    pub fn stream(&self) -> Result<Stream<'static>, StreamError> {
        Stream::parse_checked(self.bytes, self.fnv1a64)
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

/// File magic and format version of the vector file.
pub const MAGIC: [u8; 4] = *b"EFV1";
/// Format version written after the magic.
pub const FORMAT_VERSION: u32 = 1;
/// Header bytes: magic, version u32, seed u64, steps u32, nx u32, ny u32, record size u32.
pub const HEADER_LEN: usize = 32;
/// Bytes per instant: k u32, delivered u8, label u8, 2 reserved, channel flags u32,
/// y f32×2, truth f32×3 (all little-endian).
pub const RECORD_LEN: usize = 32;
/// State and measurement dimensions of the stream.
pub const NX: usize = 3;
/// Measurement dimension.
pub const NY: usize = 2;

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
    pub fn estimate(&mut self, x: &SVector<f32, NX>, p: &SMatrix<f32, NX, NX>) {
        for i in 0..NX {
            self.f32(x[i]);
        }
        for i in 0..NX {
            for j in i..NX {
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

/// One sampling instant of the stream.
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

/// A parsed vector file (borrowed, nothing copied).
#[derive(Clone, Copy, Debug)]
pub struct Stream<'a> {
    bytes: &'a [u8],
    /// Simulation seed the stream was generated with.
    pub seed: u64,
    /// Number of instants (k = 1..=steps).
    pub steps: u32,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(w)
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_bits(u32_at(b, at))
}

impl<'a> Stream<'a> {
    /// Validates header, shape and length (not the hash: see [`Stream::parse_checked`]).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, StreamError> {
        if bytes.len() < HEADER_LEN {
            return Err(StreamError::Truncated);
        }
        if bytes[..4] != MAGIC || u32_at(bytes, 4) != FORMAT_VERSION {
            return Err(StreamError::BadFormat);
        }
        let seed = u64::from(u32_at(bytes, 8)) | (u64::from(u32_at(bytes, 12)) << 32);
        let steps = u32_at(bytes, 16);
        if u32_at(bytes, 20) as usize != NX
            || u32_at(bytes, 24) as usize != NY
            || u32_at(bytes, 28) as usize != RECORD_LEN
        {
            return Err(StreamError::BadShape);
        }
        let need = (steps as usize)
            .checked_mul(RECORD_LEN)
            .and_then(|n| n.checked_add(HEADER_LEN))
            .ok_or(StreamError::Truncated)?;
        if bytes.len() != need {
            return Err(StreamError::Truncated);
        }
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
}

/// Seed 001 Section IV in `f32`: A, C as printed, B = I₃, D = I₂ (DESIGN.md), Q = 0.3 I₃,
/// R = 0.2 I₂.
pub fn model() -> Result<Model, estimator_core::Error> {
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

/// What one estimator did over the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Summary {
    /// Estimator name (`kf`, `ikf`, …).
    pub name: &'static str,
    /// Instants processed.
    pub steps: u32,
    /// Instants whose measurement was used.
    pub arrivals: u32,
    /// Instants without a measurement.
    pub dropouts: u32,
    /// Steps that returned an error (the estimator kept its previous state).
    pub errors: u32,
    /// Instant k of the first error (0 if none).
    pub first_error: u32,
    /// FNV-1a 64 over the bits of every estimate (x̂_k and P_k's upper triangle, k = 1..).
    pub digest: u64,
    /// Bit patterns of the final x̂.
    pub x_bits: [u32; NX],
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
            x_bits: [0; NX],
        }
    }

    fn error(&mut self, k: u32) {
        if self.errors == 0 {
            self.first_error = k;
        }
        self.errors += 1;
    }

    /// The final estimate as numbers.
    pub fn x(&self) -> [f32; NX] {
        self.x_bits.map(f32::from_bits)
    }
}

/// The result line; the host check compares it character for character.
impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} steps={} arrivals={} dropouts={} errors={} first_error={} digest={:016x} x=[{:08x} {:08x} {:08x}]",
            self.name,
            self.steps,
            self.arrivals,
            self.dropouts,
            self.errors,
            self.first_error,
            self.digest,
            self.x_bits[0],
            self.x_bits[1],
            self.x_bits[2]
        )
    }
}

/// The model type of the occlusion stream.
pub type Model = LinearModel<f32, NX, NX, NY, NY>;

/// An estimator of the occlusion stream as the driver sees it: one instant `k` with the
/// measurement or `None` on a dropout; returns the region-label estimate (0 for estimators
/// that have none). On error the estimator must keep its state (the core's contract).
pub trait OcclusionEstimator {
    /// One instant.
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error>;
    /// Current x̂_k.
    fn state(&self) -> &Vector3<f32>;
    /// Current P_k.
    fn covariance(&self) -> &Matrix3<f32>;
}

impl OcclusionEstimator for KalmanFilter<f32, NX> {
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error> {
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
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error> {
        IntermittentKalmanFilter::step(self, m, k, y).map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        IntermittentKalmanFilter::state(self)
    }
    fn covariance(&self) -> &Matrix3<f32> {
        IntermittentKalmanFilter::covariance(self)
    }
}

/// Whether the estimator sees the channel's dropouts or every sensor measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Every instant's sensor measurement (the lossless reference).
    Lossless,
    /// Only what the channel delivered.
    Channel,
}

/// Runs the estimator `build` makes over the first `steps` instants of the stream (all of
/// them if `steps` exceeds it) and digests every estimate: the label byte, then x̂_k and P_k.
pub fn drive<E: OcclusionEstimator>(
    name: &'static str,
    stream: &Stream<'_>,
    steps: usize,
    link: Link,
    build: fn() -> Result<(Model, E), estimator_core::Error>,
) -> Summary {
    let mut s = Summary::new(name);
    let mut h = Fnv1a64::default();
    let Ok((m, mut est)) = build() else {
        s.errors = 1;
        return finish(s, h, &prior().0);
    };
    for r in stream.records().take(steps) {
        s.steps += 1;
        let y = Vector2::from(r.y);
        let y = if r.delivered || link == Link::Lossless {
            s.arrivals += 1;
            Some(&y)
        } else {
            s.dropouts += 1;
            None
        };
        let label = est.step(&m, r.k as usize, y).unwrap_or_else(|_| {
            s.error(r.k);
            usize::MAX
        });
        h.bytes(&[label.min(255) as u8]);
        h.estimate(est.state(), est.covariance());
    }
    finish(s, h, est.state())
}

fn finish(mut s: Summary, h: Fnv1a64, x: &Vector3<f32>) -> Summary {
    s.digest = h.0;
    s.x_bits = [x[0].to_bits(), x[1].to_bits(), x[2].to_bits()];
    s
}

/// The Kalman filter on a lossless link: every instant's sensor measurement is used,
/// dropped or not (the reference the other estimators are compared with).
pub fn run_kf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf", stream, steps, Link::Lossless, build_kf)
}

fn build_kf() -> Result<(Model, KalmanFilter<f32, NX>), estimator_core::Error> {
    let (x0, p0) = prior();
    Ok((model()?, KalmanFilter::new(x0, p0)?))
}

/// The intermittent Kalman filter: updates on delivered instants, predicts through dropouts.
pub fn run_ikf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("ikf", stream, steps, Link::Channel, build_ikf)
}

fn build_ikf() -> Result<(Model, IntermittentKalmanFilter<f32, NX>), estimator_core::Error> {
    let (x0, p0) = prior();
    Ok((model()?, IntermittentKalmanFilter::new(x0, p0)?))
}

/// Seed 001's dropout mechanism in `f32`: E = [1 0 0], Ψ = 0.1, regions [20i − 5, 20i + 5].
pub fn occlusion() -> Result<Occlusion<f32, NX, 1, 4>, estimator_core::Error> {
    use nalgebra::{Matrix1, Matrix1x3, Vector1};
    let c = |z: f32| Vector1::new(z);
    let regions = OcclusionRegions::new([c(20.0), c(40.0), c(60.0), c(80.0)], [5.0; 4])?;
    Occlusion::new(Matrix1x3::new(1.0, 0.0, 0.0), Matrix1::new(0.1), regions)
}

/// The CCE as configured for the stream: N = 15 Gaussians per region, KL-optimal σ̂.
pub type Cce = CrossCoupledEstimator<f32, NX, 1, 4, 15>;

impl OcclusionEstimator for Cce {
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error> {
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
    drive("cce", stream, steps, Link::Channel, || {
        let (x0, p0) = prior();
        let g = GaussSum::<f32, 1, 15>::uniform()?;
        Ok((model()?, Cce::new(x0, p0, occlusion()?, &g)?))
    })
}

/// The assumed-density filter with exact interval likelihoods (the product's improvement).
pub type Adf = AssumedDensityFilter<f32, NX, 4>;

impl OcclusionEstimator for Adf {
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error> {
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
    drive("adf", stream, steps, Link::Channel, || {
        let (x0, p0) = prior();
        Ok((model()?, Adf::new(x0, p0, occlusion()?)?))
    })
}

/// The linear MMSE filter with Bernoulli arrivals (KF-IO, DESIGN.md's construction).
pub type KfIoF32 = KfIo<f32, NX, 4>;

impl OcclusionEstimator for KfIoF32 {
    fn step(
        &mut self,
        m: &Model,
        k: usize,
        y: Option<&Vector2<f32>>,
    ) -> Result<usize, estimator_core::Error> {
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
    drive("kf-io", stream, steps, Link::Channel, || {
        let (x0, p0) = prior();
        Ok((model()?, KfIoF32::new(x0, p0, occlusion()?)?))
    })
}

/// The seed 003 NN estimator in `f32` with the paper's configuration (Section IV), on the
/// token-bucket stream.
pub type Nn = Seed003Nn<f32>;

fn build_nn() -> Result<Nn, estimator_core::Error> {
    NnTbcpEstimator::new(
        NnBoundConfig::seed003_example(),
        Tanh,
        Seed003Example::xhat0(),
        Seed003Example::h0(),
        Seed003Example::p0(),
        Seed003Example::p0(),
    )
}

/// The NN estimator over the token-bucket stream: step `i` takes instant `k = i + 1`'s
/// observation (`None` when the bucket withheld it) and yields x̂_k; the digest covers x̂_k
/// and the bound P̄_k.
pub fn run_nn(stream: &Stream<'_>, steps: usize) -> Summary {
    let mut s = Summary::new("nn");
    let mut h = Fnv1a64::default();
    let Ok(mut nn) = build_nn() else {
        s.errors = 1;
        return finish(s, h, &Seed003Example::xhat0());
    };
    for r in stream.records().take(steps) {
        s.steps += 1;
        let y = Vector2::from(r.y);
        let y = if r.delivered {
            s.arrivals += 1;
            Some(&y)
        } else {
            s.dropouts += 1;
            None
        };
        if nn.step(&Seed003Example, y).is_err() {
            s.error(r.k);
        }
        h.bytes(&[0]);
        h.estimate(nn.state(), nn.bound_p());
    }
    finish(s, h, nn.state())
}
