//! The linear-Gaussian plant: `x_{k+1} = A_k x_k + B_k w_k`, `w_k ~ N(0, Q)` (plus a known
//! `B_u u_k` with a [`Control`] input), and sensors
//! `z_{m,k} = C_{m,k} x_k + D_{m,k} v_{m,k}`, `v_{m,k} ~ N(0, R_m)`, independent across nodes.
//! The plant of the `linear`, `occlusion` and `tobit-fusion` presets and of every TOML file.

use std::any::Any;

use estpipe_spec::{LinearModel, Model};
use nalgebra::DMatrix;

use super::control::Control;
use super::{Plant, PlantRun};
use crate::error::ScenarioError;
use crate::rng::{fill_standard_normal, SimRng};
use crate::sim::MAX_NY;
use crate::validate::check_pd;

/// One sensor node: `z = C x + D v`, `v ~ N(0, R)` (the estimator spec's [`Sensor`](estpipe_spec::Sensor)).
pub use estpipe_spec::Sensor as LinearSensor;

/// The linear-Gaussian plant: the estimators' [`LinearModel`] and the noise factors that
/// draw its noises.
#[derive(Clone, Debug)]
pub struct LinearPlant {
    model: LinearModel,
    /// `L_Q`, `Q = L_Q L_Qᵀ`.
    q_factor: DMatrix<f64>,
    /// `L_R` per node.
    r_factors: Vec<DMatrix<f64>>,
}

impl LinearPlant {
    /// Validates the model ([`LinearModel::new`]; errors name `model.a`, `sensors[1].r`, …).
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        q: DMatrix<f64>,
        sensors: Vec<LinearSensor>,
    ) -> Result<Self, ScenarioError> {
        Ok(Self::of(LinearModel::new(a, b, q, sensors)?))
    }

    /// The plant of a validated model.
    pub fn of(model: LinearModel) -> Self {
        let factor = |m: &DMatrix<f64>| check_pd(m, "").expect("validated by LinearModel::new");
        Self {
            q_factor: factor(model.q()),
            r_factors: model.sensors().iter().map(|s| factor(&s.r)).collect(),
            model,
        }
    }

    /// With the known input of `control`.
    pub fn with_control(mut self, control: Control) -> Result<Self, ScenarioError> {
        self.model = self.model.with_control(control)?;
        Ok(self)
    }

    /// The model the estimators know.
    pub fn model(&self) -> &LinearModel {
        &self.model
    }
}

impl Plant for LinearPlant {
    fn nx(&self) -> usize {
        self.model.nx()
    }
    fn ny(&self) -> usize {
        (0..self.model.nodes())
            .map(|m| self.model.node_ny(m))
            .max()
            .unwrap_or(0)
    }
    fn node_ny(&self, node: usize) -> usize {
        self.model.node_ny(node)
    }
    fn nodes(&self) -> usize {
        self.model.nodes()
    }
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun> {
        let nw = self.model.q().nrows();
        let nv = self
            .model
            .sensors()
            .iter()
            .map(|s| s.r.nrows())
            .max()
            .unwrap_or(0);
        let nx = x0.len();
        Box::new(LinearRun {
            plant: self.clone(),
            x: x0.to_vec(),
            scratch: Scratch {
                normal: vec![0.0; nw.max(nv)],
                noise: vec![0.0; nw.max(nv)],
                ax: vec![0.0; nx],
                bw: vec![0.0; nx],
                input: vec![0.0; nx],
            },
        })
    }
    fn model(&self) -> Option<Model> {
        Some(Model::Linear(self.model.clone()))
    }
    fn linear(&self) -> Option<&LinearModel> {
        Some(&self.model)
    }
    fn as_any(&self) -> &dyn Any {
        self
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
    input: Vec<f64>,
}

impl PlantRun for LinearRun {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]) {
        let p = &self.plant;
        let m = &p.model;
        let s = &mut self.scratch;
        let prev = k.saturating_sub(1) as usize;
        // w = L_Q n, x = A x + B w, then per node v = L_R n, z = C x + D v: the random draws
        // in that order, every product summed as nalgebra's `gemv` sums it (`mat_vec`).
        let nw = m.q().nrows();
        fill_standard_normal(&mut s.normal[..nw], rng);
        mat_vec(&p.q_factor, &s.normal[..nw], &mut s.noise[..nw]);
        mat_vec(m.a(), &self.x, &mut s.ax);
        mat_vec(m.b(), &s.noise[..nw], &mut s.bw);
        for ((x, ax), bw) in self.x.iter_mut().zip(&s.ax).zip(&s.bw) {
            *x = ax + bw;
        }
        if m.input_into(prev, &mut s.input) {
            for (x, u) in self.x.iter_mut().zip(&s.input) {
                *x += u;
            }
        }
        for ((s_m, l_r), z_m) in m.sensors().iter().zip(&p.r_factors).zip(z.iter_mut()) {
            let nv = s_m.r.nrows();
            fill_standard_normal(&mut s.normal[..nv], rng);
            mat_vec(l_r, &s.normal[..nv], &mut s.noise[..nv]);
            let (c, d) = (&s_m.c, &s_m.d);
            for i in 0..c.nrows() {
                z_m[i] = row_dot(c, i, &self.x) + row_dot(d, i, &s.noise[..nv]);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{run_rng, Stream};
    use crate::validate::check_psd;
    use nalgebra::{dmatrix, DVector};

    fn plant() -> LinearPlant {
        LinearPlant::new(
            dmatrix![0.9, 0.2; -0.1, 0.8],
            dmatrix![1.0; 0.5],
            dmatrix![0.3],
            vec![LinearSensor {
                c: dmatrix![1.0, -1.0],
                d: dmatrix![1.0],
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
        let bad_q = LinearPlant::new(dmatrix![1.0], dmatrix![1.0], dmatrix![-1.0], vec![]);
        assert!(bad_q.unwrap_err().to_string().contains("model.q"));
        let bad_c = LinearPlant::new(
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![1.0],
            vec![LinearSensor {
                c: dmatrix![1.0, 2.0],
                d: dmatrix![1.0],
                r: dmatrix![1.0],
            }],
        );
        assert!(bad_c.unwrap_err().to_string().contains("sensors[0].c"));
        assert!(check_psd(&DMatrix::zeros(2, 2), "x").is_ok());
        assert!(check_psd(&dmatrix![1.0, 2.0; 2.0, 1.0], "x").is_err());
    }
}
