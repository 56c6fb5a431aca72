//! The linear-Gaussian plant: `x_{k+1} = A_k x_k + B_k w_k`, `w_k ~ N(0, Q)` (plus a known
//! `B_u u_k` with a [`Control`] input), and sensors
//! `z_{m,k} = C_{m,k} x_k + D_{m,k} v_{m,k}`, `v_{m,k} ~ N(0, R_m)`, independent across nodes.
//! The plant of the `linear`, `occlusion` and `tobit-fusion` presets and of every TOML file.

use std::any::Any;

use estpipe_wire::Fnv1a64;
use nalgebra::{DMatrix, DVector};

use super::control::Control;
use super::time_matrix::TimeMatrix;
use super::{fingerprint_matrix, LinearDescription, Plant, PlantRun};
use crate::error::ScenarioError;
use crate::rng::{fill_standard_normal, SimRng};
use crate::sim::{MAX_NODES, MAX_NX, MAX_NY};
use crate::validate::{check_finite, check_pd, check_shape};

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
    control: Option<Control>,
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
        let mut r_factors = Vec::with_capacity(sensors.len());
        for (m, s) in sensors.iter().enumerate() {
            let field = |f: &str| format!("sensors[{m}].{f}");
            // Each sensor has its own ny (its rows); the columns are the plant's nx.
            let (ny, cols) = s.c.shape();
            if ny == 0 || ny > MAX_NY || cols != nx {
                return Err(ScenarioError::invalid(
                    field("c"),
                    format!(
                        "must have 1 to {MAX_NY} rows (the sensor's ny) and nx = {nx} \
                         columns, got {ny}×{cols}"
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
            control: None,
        })
    }

    /// The same plant driven by a known input as well: `x_{k+1} = A x_k + B_u u_k + B w_k`
    /// (`control` validated for this plant's nx).
    pub fn with_control(mut self, control: Control) -> Result<Self, ScenarioError> {
        if control.b().nrows() != self.a.shape().0 {
            return Err(ScenarioError::invalid(
                "control.b",
                format!("must have nx = {} rows", self.a.shape().0),
            ));
        }
        self.control = Some(control);
        Ok(self)
    }

    /// The control input, if any.
    pub fn control(&self) -> Option<&Control> {
        self.control.as_ref()
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
        (0..self.sensors.len())
            .map(|m| self.node_ny(m))
            .max()
            .unwrap_or(0)
    }
    fn node_ny(&self, node: usize) -> usize {
        self.sensors[node].c.shape().0
    }
    fn nodes(&self) -> usize {
        self.sensors.len()
    }
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun> {
        let nw = self.q.nrows();
        let nv = self.sensors.iter().map(|s| s.r.nrows()).max().unwrap_or(0);
        let nx = x0.len();
        Box::new(LinearRun {
            plant: self.clone(),
            x: x0.to_vec(),
            scratch: Scratch {
                normal: vec![0.0; nw.max(nv)],
                noise: vec![0.0; nw.max(nv)],
                ax: vec![0.0; nx],
                bw: vec![0.0; nx],
            },
        })
    }
    fn fingerprint(&self, h: &mut Fnv1a64) {
        h.str("linear");
        self.a.fingerprint(h);
        self.b.fingerprint(h);
        fingerprint_matrix(h, &self.q);
        h.u64(self.sensors.len() as u64);
        for s in &self.sensors {
            s.c.fingerprint(h);
            s.d.fingerprint(h);
            fingerprint_matrix(h, &s.r);
        }
        // Only with an input, so that the plants without one keep their fingerprints.
        if let Some(c) = &self.control {
            c.fingerprint(h);
        }
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
    fn input(&self, k: usize) -> Option<DVector<f64>> {
        self.control.as_ref().map(|c| c.input(k))
    }
    fn time_invariant(&self) -> bool {
        let constant = |m: &TimeMatrix| matches!(m, TimeMatrix::Constant(_));
        self.control.is_none()
            && constant(&self.a)
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
    x: Vec<f64>,
    scratch: Scratch,
}

/// The buffers of one step, allocated once per run (a step allocates nothing).
#[derive(Debug)]
struct Scratch {
    normal: Vec<f64>,
    noise: Vec<f64>,
    ax: Vec<f64>,
    bw: Vec<f64>,
}

impl PlantRun for LinearRun {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]) {
        let p = &self.plant;
        let s = &mut self.scratch;
        let prev = k.saturating_sub(1) as usize;
        // w = L_Q n, x = A x + B w, then per node v = L_R n, z = C x + D v: the random draws
        // in that order, every product summed as nalgebra's `gemv` sums it (`mat_vec`).
        let nw = p.q.nrows();
        fill_standard_normal(&mut s.normal[..nw], rng);
        mat_vec(&p.q_factor, &s.normal[..nw], &mut s.noise[..nw]);
        mat_vec(&p.a.at(prev), &self.x, &mut s.ax);
        mat_vec(&p.b.at(prev), &s.noise[..nw], &mut s.bw);
        for ((x, ax), bw) in self.x.iter_mut().zip(&s.ax).zip(&s.bw) {
            *x = ax + bw;
        }
        if let Some(c) = &p.control {
            for (x, u) in self.x.iter_mut().zip(c.input(prev).iter()) {
                *x += u;
            }
        }
        for ((s_m, l_r), z_m) in p.sensors.iter().zip(&p.r_factors).zip(z.iter_mut()) {
            let nv = s_m.r.nrows();
            fill_standard_normal(&mut s.normal[..nv], rng);
            mat_vec(l_r, &s.normal[..nv], &mut s.noise[..nv]);
            let (c, d) = (s_m.c.at(k as usize), s_m.d.at(k as usize));
            for i in 0..c.nrows() {
                z_m[i] = row_dot(&c, i, &self.x) + row_dot(&d, i, &s.noise[..nv]);
            }
        }
    }
}

/// `out = m x`, each entry `Σ_j m_ij x_j` summed from `j = 0` up, as nalgebra's `gemv`
/// (column by column, `y ← m_j x_j + y`; the sum commutes bit for bit) sums it: the same bits
/// without allocating.
fn mat_vec(m: &DMatrix<f64>, x: &[f64], out: &mut [f64]) {
    for (i, o) in out.iter_mut().enumerate().take(m.nrows()) {
        *o = row_dot(m, i, x);
    }
}

/// `Σ_j m_ij x_j`, from `j = 0` up (`m` is stored column by column).
#[inline]
fn row_dot(m: &DMatrix<f64>, i: usize, x: &[f64]) -> f64 {
    let (rows, cols, d) = (m.nrows(), m.ncols().min(x.len()), m.as_slice());
    if cols == 0 {
        return 0.0;
    }
    let mut acc = d[i] * x[0];
    for j in 1..cols {
        acc += d[i + j * rows] * x[j];
    }
    acc
}

/// `(m + mᵀ)/2`.
pub fn symmetric(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

fn check_time_matrix(m: &TimeMatrix, field: &str) -> Result<(), ScenarioError> {
    let m0 = m.at(0);
    check_shape(m0.shape(), m.shape(), field)?;
    check_finite(&m0, field)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{run_rng, Stream};
    use crate::validate::check_psd;
    use nalgebra::{dmatrix, DVector};

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
