//! The plant and its sensors: the first link of the data path.
//!
//! A [`Plant`] advances the true state x_k **and** produces every node's raw measurement z_{m,k}
//! in one call, because some papers draw both from the same noise sample (seed 003 eq. 1 uses
//! one w_k in the state and the measurement). What a linear filter may know about the plant
//! (A_k, C_{m,k} and the effective noise covariances) is a separate trait,
//! [`LinearDescription`], so a nonlinear plant can still offer its linear part to a KF.
//!
//! Randomness: every run has its own generators derived from `(seed, run)` by SplitMix64
//! ([`run_rng`]), one stream for the plant and one for the channel, so a run's numbers do not
//! depend on the thread that computes it, and changing the channel does not change the plant's
//! trajectory (common random numbers across channel settings).

use std::any::Any;
use std::borrow::Cow;
use std::fmt::Debug;

use nalgebra::{DMatrix, DVector};
use rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::scenario::ScenarioError;
use crate::sim::{MAX_NODES, MAX_NX, MAX_NY};

/// The generator used everywhere in simulation.
pub type SimRng = Xoshiro256PlusPlus;

/// The independent random streams of one run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Initial state, process and measurement noise.
    Plant = 1,
    /// Every channel stage (loss, occlusion noise, …).
    Channel = 2,
}

/// SplitMix64 finaliser: a bijective mix so that nearby inputs give unrelated seeds.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of `stream` in run `run` of the experiment seeded by `seed`.
pub fn run_rng(seed: u64, run: u64, stream: Stream) -> SimRng {
    SimRng::seed_from_u64(splitmix64(
        splitmix64(splitmix64(seed) ^ run) ^ stream as u64,
    ))
}

/// A vector of `n` independent standard normal samples.
pub fn standard_normal(n: usize, rng: &mut SimRng) -> DVector<f64> {
    DVector::from_fn(n, |_, _| StandardNormal.sample(rng))
}

/// Plant and sensors of a scenario (configuration; cheap to share between threads).
pub trait Plant: Send + Sync + Debug {
    /// State dimension.
    fn nx(&self) -> usize;
    /// Measurement dimension of every node.
    fn ny(&self) -> usize;
    /// Number of sensor nodes.
    fn nodes(&self) -> usize;
    /// Starts one run from the true initial state `x0`.
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun>;
    /// The linear-Gaussian description a Kalman-type filter may use, if the plant has one.
    fn linear(&self) -> Option<&dyn LinearDescription> {
        None
    }
    /// For downcasting to the concrete plant.
    fn as_any(&self) -> &dyn Any;
}

/// One run of a plant: owns the true state and whatever noise memory the model needs.
pub trait PlantRun: Send {
    /// The current true state x_k.
    fn state(&self) -> &[f64];
    /// Advances from x_{k−1} to x_k and writes node m's raw measurement z_{m,k} into
    /// `z[m][..ny]` for every node.
    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]);
}

/// The linear-Gaussian part of a plant as a filter sees it:
/// `x_{k+1} = A_k x_k + B_k w_k`, `z_{m,k} = C_{m,k} x_k + D_{m,k} v_{m,k}`, nodes' noises
/// independent of each other.
pub trait LinearDescription: Send + Sync + Debug {
    /// A_k.
    fn a(&self, k: usize) -> DMatrix<f64>;
    /// Effective process-noise covariance B_k Q Bₖᵀ.
    fn process_cov(&self, k: usize) -> DMatrix<f64>;
    /// C_{m,k} of node `node`.
    fn c(&self, node: usize, k: usize) -> DMatrix<f64>;
    /// Effective measurement-noise covariance D_{m,k} R_m D_{m,k}ᵀ of node `node`.
    fn measurement_cov(&self, node: usize, k: usize) -> DMatrix<f64>;
    /// `true` when no matrix depends on k, so a filter may convert them once and never
    /// allocate per step.
    fn time_invariant(&self) -> bool {
        false
    }
}

/// A matrix that is constant or a function of the time index k.
#[derive(Clone, Debug)]
pub enum TimeMatrix {
    /// The same matrix at every k.
    Constant(DMatrix<f64>),
    /// `at(k)`, which must return a `rows × cols` finite matrix for every k.
    Varying {
        /// Row count of every `at(k)`.
        rows: usize,
        /// Column count of every `at(k)`.
        cols: usize,
        /// The matrix at instant k.
        at: fn(usize) -> DMatrix<f64>,
    },
}

impl TimeMatrix {
    /// The matrix at instant `k` (borrowed when constant).
    pub fn at(&self, k: usize) -> Cow<'_, DMatrix<f64>> {
        match self {
            TimeMatrix::Constant(m) => Cow::Borrowed(m),
            TimeMatrix::Varying { at, .. } => Cow::Owned(at(k)),
        }
    }

    /// `(rows, cols)`.
    pub fn shape(&self) -> (usize, usize) {
        match self {
            TimeMatrix::Constant(m) => m.shape(),
            TimeMatrix::Varying { rows, cols, .. } => (*rows, *cols),
        }
    }
}

impl From<DMatrix<f64>> for TimeMatrix {
    fn from(m: DMatrix<f64>) -> Self {
        TimeMatrix::Constant(m)
    }
}

/// One sensor node of a [`LinearPlant`]: `z_{m,k} = C_{m,k} x_k + D_{m,k} v_{m,k}`,
/// `v_{m,k} ~ N(0, R_m)`.
#[derive(Clone, Debug)]
pub struct LinearSensor {
    /// C_{m,k} (ny × nx).
    pub c: TimeMatrix,
    /// D_{m,k} (ny × nv).
    pub d: TimeMatrix,
    /// R_m (nv × nv), symmetric positive definite.
    pub r: DMatrix<f64>,
}

/// Linear (optionally time-varying) plant with Gaussian noise:
/// `x_{k+1} = A_k x_k + B_k w_k`, `w_k ~ N(0, Q)`, and [`LinearSensor`]s.
#[derive(Clone, Debug)]
pub struct LinearPlant {
    a: TimeMatrix,
    b: TimeMatrix,
    q: DMatrix<f64>,
    sensors: Vec<LinearSensor>,
    q_factor: DMatrix<f64>,
    r_factors: Vec<DMatrix<f64>>,
}

impl LinearPlant {
    /// Builds and validates the plant; errors name the offending field (`model.a`,
    /// `sensors[1].r`, …).
    pub fn new(
        a: TimeMatrix,
        b: TimeMatrix,
        q: DMatrix<f64>,
        sensors: Vec<LinearSensor>,
    ) -> Result<Self, ScenarioError> {
        let (nx, ncols) = a.shape();
        if nx == 0 || nx != ncols || nx > MAX_NX {
            return Err(ScenarioError::invalid(
                "model.a",
                format!("must be square n×n with 1 ≤ n ≤ {MAX_NX}, got {nx}×{ncols}"),
            ));
        }
        check_time_matrix(&a, "model.a")?;
        let nw = q.nrows();
        check_time_matrix(&b, "model.b")?;
        check_shape(b.shape(), (nx, nw), "model.b")?;
        let q_factor = check_pd(&q, "model.q")?;
        if sensors.is_empty() || sensors.len() > MAX_NODES {
            return Err(ScenarioError::invalid(
                "sensors",
                format!(
                    "need between 1 and {MAX_NODES} sensors, got {}",
                    sensors.len()
                ),
            ));
        }
        let ny = sensors[0].c.shape().0;
        let mut r_factors = Vec::with_capacity(sensors.len());
        for (m, s) in sensors.iter().enumerate() {
            let field = |f: &str| format!("sensors[{m}].{f}");
            let (rows, cols) = s.c.shape();
            if rows == 0 || rows > MAX_NY || rows != ny || cols != nx {
                return Err(ScenarioError::invalid(
                    field("c"),
                    format!(
                        "must be {ny}×{nx} (every sensor has the same 1 ≤ ny ≤ {MAX_NY}, \
                         nx columns), got {rows}×{cols}"
                    ),
                ));
            }
            check_time_matrix(&s.c, &field("c"))?;
            check_time_matrix(&s.d, &field("d"))?;
            check_shape(s.d.shape(), (ny, s.r.nrows()), &field("d"))?;
            r_factors.push(check_pd(&s.r, &field("r"))?);
            let d0 = s.d.at(0);
            check_pd(&(&*d0 * &s.r * d0.transpose()), &field("d r dᵀ"))?;
        }
        Ok(Self {
            a,
            b,
            q,
            sensors,
            q_factor,
            r_factors,
        })
    }

    /// The sensors.
    pub fn sensors(&self) -> &[LinearSensor] {
        &self.sensors
    }

    /// The process-noise covariance Q.
    pub fn q(&self) -> &DMatrix<f64> {
        &self.q
    }
}

impl Plant for LinearPlant {
    fn nx(&self) -> usize {
        self.a.shape().0
    }
    fn ny(&self) -> usize {
        self.sensors[0].c.shape().0
    }
    fn nodes(&self) -> usize {
        self.sensors.len()
    }
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun> {
        Box::new(LinearRun {
            plant: self.clone(),
            x: DVector::from_column_slice(x0),
        })
    }
    fn linear(&self) -> Option<&dyn LinearDescription> {
        Some(self)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl LinearDescription for LinearPlant {
    fn a(&self, k: usize) -> DMatrix<f64> {
        self.a.at(k).into_owned()
    }
    fn process_cov(&self, k: usize) -> DMatrix<f64> {
        let b = self.b.at(k);
        symmetric(&*b * &self.q * b.transpose())
    }
    fn c(&self, node: usize, k: usize) -> DMatrix<f64> {
        self.sensors[node].c.at(k).into_owned()
    }
    fn measurement_cov(&self, node: usize, k: usize) -> DMatrix<f64> {
        let s = &self.sensors[node];
        let d = s.d.at(k);
        symmetric(&*d * &s.r * d.transpose())
    }
    fn time_invariant(&self) -> bool {
        let constant = |m: &TimeMatrix| matches!(m, TimeMatrix::Constant(_));
        constant(&self.a)
            && constant(&self.b)
            && self
                .sensors
                .iter()
                .all(|s| constant(&s.c) && constant(&s.d))
    }
}

#[derive(Debug)]
struct LinearRun {
    plant: LinearPlant,
    x: DVector<f64>,
}

impl PlantRun for LinearRun {
    fn state(&self) -> &[f64] {
        self.x.as_slice()
    }

    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]) {
        let p = &self.plant;
        let prev = k.saturating_sub(1) as usize;
        let w = &p.q_factor * standard_normal(p.q.nrows(), rng);
        self.x = &*p.a.at(prev) * &self.x + &*p.b.at(prev) * w;
        for (m, s) in p.sensors.iter().enumerate() {
            let v = &p.r_factors[m] * standard_normal(s.r.nrows(), rng);
            let zm = &*s.c.at(k as usize) * &self.x + &*s.d.at(k as usize) * v;
            z[m][..zm.len()].copy_from_slice(zm.as_slice());
        }
    }
}

/// `(m + mᵀ)/2`.
pub fn symmetric(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

/// Errors unless every entry is finite.
pub fn check_finite(m: &DMatrix<f64>, field: &str) -> Result<(), ScenarioError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ScenarioError::invalid(field, "contains NaN or ±∞"))
    }
}

/// Errors unless `shape == want`.
pub fn check_shape(
    shape: (usize, usize),
    want: (usize, usize),
    field: &str,
) -> Result<(), ScenarioError> {
    if shape == want {
        Ok(())
    } else {
        Err(ScenarioError::invalid(
            field,
            format!("must be {}×{}, got {}×{}", want.0, want.1, shape.0, shape.1),
        ))
    }
}

fn check_time_matrix(m: &TimeMatrix, field: &str) -> Result<(), ScenarioError> {
    let m0 = m.at(0);
    check_shape(m0.shape(), m.shape(), field)?;
    check_finite(&m0, field)
}

/// Checks that `m` is finite, symmetric (to 1e-9 relative) and positive definite; returns its
/// lower Cholesky factor.
pub fn check_pd(m: &DMatrix<f64>, field: &str) -> Result<DMatrix<f64>, ScenarioError> {
    check_symmetric(m, field)?;
    nalgebra::Cholesky::new(m.clone())
        .map(|c| c.l())
        .ok_or_else(|| ScenarioError::invalid(field, "is not positive definite"))
}

/// Checks that `m` is finite, symmetric and positive semi-definite; returns a factor `L`
/// with `L Lᵀ = m` (zero allowed: a deterministic quantity).
pub fn check_psd(m: &DMatrix<f64>, field: &str) -> Result<DMatrix<f64>, ScenarioError> {
    check_symmetric(m, field)?;
    let eig = nalgebra::SymmetricEigen::new(m.clone());
    let scale = m.amax().max(f64::MIN_POSITIVE);
    if eig.eigenvalues.iter().any(|&l| l < -1e-12 * scale) {
        return Err(ScenarioError::invalid(
            field,
            "is not positive semi-definite",
        ));
    }
    let sqrt = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    Ok(&eig.eigenvectors * DMatrix::from_diagonal(&sqrt))
}

fn check_symmetric(m: &DMatrix<f64>, field: &str) -> Result<(), ScenarioError> {
    if !m.is_square() || m.nrows() == 0 {
        return Err(ScenarioError::invalid(
            field,
            format!(
                "must be a non-empty square matrix, got {}×{}",
                m.nrows(),
                m.ncols()
            ),
        ));
    }
    check_finite(m, field)?;
    if (m - m.transpose()).amax() > 1e-9 * m.amax() {
        return Err(ScenarioError::invalid(field, "is not symmetric"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    fn plant() -> LinearPlant {
        LinearPlant::new(
            dmatrix![0.9, 0.2; -0.1, 0.8].into(),
            dmatrix![1.0; 0.5].into(),
            dmatrix![0.3],
            vec![LinearSensor {
                c: dmatrix![1.0, -1.0].into(),
                d: dmatrix![1.0].into(),
                r: dmatrix![0.5],
            }],
        )
        .unwrap()
    }

    #[test]
    fn run_streams_are_deterministic_and_distinct() {
        use rand_core::Rng;
        let a = run_rng(7, 3, Stream::Plant).next_u64();
        assert_eq!(a, run_rng(7, 3, Stream::Plant).next_u64());
        assert_ne!(a, run_rng(7, 4, Stream::Plant).next_u64());
        assert_ne!(a, run_rng(7, 3, Stream::Channel).next_u64());
        assert_ne!(a, run_rng(8, 3, Stream::Plant).next_u64());
    }

    /// Sample covariance of x_k over independent runs against the Lyapunov recursion
    /// Σ_{k+1} = A Σ_k Aᵀ + B Q Bᵀ computed separately here, and E[z zᵀ] = C Σ Cᵀ + R.
    #[test]
    fn state_and_measurement_covariance_match_lyapunov() {
        let p = plant();
        let a = dmatrix![0.9, 0.2; -0.1, 0.8];
        let bqb = dmatrix![1.0; 0.5] * 0.3 * dmatrix![1.0, 0.5];
        let c = dmatrix![1.0, -1.0];
        let mut sigma = DMatrix::<f64>::zeros(2, 2);
        let (runs, k_end) = (20_000, 12u32);
        let mut sum_xx = DMatrix::<f64>::zeros(2, 2);
        let mut sum_zz = 0.0;
        for run in 0..runs {
            let mut rng = run_rng(42, run, Stream::Plant);
            let mut r = p.start(&[0.0, 0.0]);
            let mut z = [[0.0; MAX_NY]; 1];
            for k in 1..=k_end {
                r.advance(k, &mut rng, &mut z);
            }
            let x = DVector::from_column_slice(r.state());
            sum_xx += &x * x.transpose();
            sum_zz += z[0][0] * z[0][0];
        }
        for _ in 0..k_end {
            sigma = &a * sigma * a.transpose() + &bqb;
        }
        let sample = sum_xx / runs as f64;
        // The sample covariance of n Gaussian draws has entry-wise standard error
        // ≤ sqrt((σ_ii σ_jj + σ_ij²)/n) ≤ sqrt(2/n)·max σ_ii; 5 standard errors.
        let tol = 5.0 * (2.0 / runs as f64).sqrt() * sigma.diagonal().max();
        assert!((&sample - &sigma).amax() < tol, "{sample} vs {sigma}");
        let zz = (&c * &sigma * c.transpose())[(0, 0)] + 0.5;
        assert!((sum_zz / runs as f64 - zz).abs() < 5.0 * (2.0 / runs as f64).sqrt() * zz);
    }

    #[test]
    fn validation_names_fields() {
        let bad_q = LinearPlant::new(
            dmatrix![1.0].into(),
            dmatrix![1.0].into(),
            dmatrix![-1.0],
            vec![],
        );
        assert!(bad_q.unwrap_err().to_string().contains("model.q"));
        let bad_c = LinearPlant::new(
            dmatrix![1.0].into(),
            dmatrix![1.0].into(),
            dmatrix![1.0],
            vec![LinearSensor {
                c: dmatrix![1.0, 2.0].into(),
                d: dmatrix![1.0].into(),
                r: dmatrix![1.0],
            }],
        );
        assert!(bad_c.unwrap_err().to_string().contains("sensors[0].c"));
        assert!(check_psd(&DMatrix::zeros(2, 2), "x").is_ok());
        assert!(check_psd(&dmatrix![1.0, 2.0; 2.0, 1.0], "x").is_err());
    }
}
