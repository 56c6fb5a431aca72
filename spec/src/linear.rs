//! The linear-Gaussian model a Kalman-type estimator runs on:
//! `x_{k+1} = A x_k + B_u u_k + B w_k`, `w_k ~ N(0, Q)` (the input term only with a
//! [`Control`]), and per sensor node `z_{m,k} = C_m x_k + D_m v_{m,k}`, `v_{m,k} ~ N(0, R_m)`,
//! the nodes' noises independent.
//!
//! The matrices are constant; only the known input `B_u u_k` depends on k, and it is evaluated
//! without allocating ([`LinearModel::input_into`]), so an estimator on a controlled model
//! steps without allocating too. The effective covariances `B Q Bᵀ` and `D R Dᵀ` are formed
//! once, here, for the simulator and every estimator alike.

use nalgebra::DMatrix;

use crate::control::Control;
use crate::error::SpecError;
use crate::validate::{check_pd, check_shape};
use estpipe_wire::{MAX_NODES, MAX_NX, MAX_NY};

/// One sensor node: `z = C x + D v`, `v ~ N(0, R)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// C (ny × nx): the node's ny is its row count.
    pub c: DMatrix<f64>,
    /// D (ny × nv).
    pub d: DMatrix<f64>,
    /// R (nv × nv), symmetric positive definite.
    pub r: DMatrix<f64>,
}

/// A validated linear-Gaussian model (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearModel {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    q: DMatrix<f64>,
    sensors: Vec<Sensor>,
    control: Option<Control>,
    /// `B Q Bᵀ`, symmetrised.
    bqb: DMatrix<f64>,
    /// `D_m R_m D_mᵀ` per node, symmetrised.
    drd: Vec<DMatrix<f64>>,
}

impl LinearModel {
    /// Validates the model; errors name the fields as a TOML file spells them (`model.a`,
    /// `sensors[1].r`).
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        q: DMatrix<f64>,
        sensors: Vec<Sensor>,
    ) -> Result<Self, SpecError> {
        let (nx, ncols) = a.shape();
        if nx == 0 || nx != ncols || nx > MAX_NX {
            return Err(SpecError::invalid(
                "model.a",
                format!("must be square n×n with 1 ≤ n ≤ {MAX_NX}, got {nx}×{ncols}"),
            ));
        }
        crate::validate::check_finite(&a, "model.a")?;
        let nw = q.nrows();
        crate::validate::check_finite(&b, "model.b")?;
        check_shape(b.shape(), (nx, nw), "model.b")?;
        check_pd(&q, "model.q")?;
        if sensors.is_empty() || sensors.len() > MAX_NODES {
            return Err(SpecError::invalid(
                "sensors",
                format!(
                    "need between 1 and {MAX_NODES} sensors, got {}",
                    sensors.len()
                ),
            ));
        }
        let mut drd = Vec::with_capacity(sensors.len());
        for (m, s) in sensors.iter().enumerate() {
            let field = |f: &str| format!("sensors[{m}].{f}");
            // Each sensor has its own ny (its rows); the columns are the plant's nx.
            let (ny, cols) = s.c.shape();
            if ny == 0 || ny > MAX_NY || cols != nx {
                return Err(SpecError::invalid(
                    field("c"),
                    format!(
                        "must have 1 to {MAX_NY} rows (the sensor's ny) and nx = {nx} \
                         columns, got {ny}×{cols}"
                    ),
                ));
            }
            crate::validate::check_finite(&s.c, &field("c"))?;
            crate::validate::check_finite(&s.d, &field("d"))?;
            check_shape(s.d.shape(), (ny, s.r.nrows()), &field("d"))?;
            check_pd(&s.r, &field("r"))?;
            let cov = &s.d * &s.r * s.d.transpose();
            check_pd(&cov, &field("d r dᵀ"))?;
            drd.push(symmetric(cov));
        }
        let bqb = symmetric(&b * &q * b.transpose());
        Ok(Self {
            a,
            b,
            q,
            sensors,
            control: None,
            bqb,
            drd,
        })
    }

    /// With the known input `B_u u_k` of `control`.
    pub fn with_control(mut self, control: Control) -> Result<Self, SpecError> {
        if control.b().nrows() != self.nx() {
            return Err(SpecError::invalid(
                "control.b",
                format!("must have nx = {} rows", self.nx()),
            ));
        }
        self.control = Some(control);
        Ok(self)
    }

    /// n_x.
    pub fn nx(&self) -> usize {
        self.a.nrows()
    }
    /// The number of sensor nodes.
    pub fn nodes(&self) -> usize {
        self.sensors.len()
    }
    /// n_y of node `node`.
    pub fn node_ny(&self, node: usize) -> usize {
        self.sensors[node].c.nrows()
    }
    /// A.
    pub fn a(&self) -> &DMatrix<f64> {
        &self.a
    }
    /// B.
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }
    /// Q.
    pub fn q(&self) -> &DMatrix<f64> {
        &self.q
    }
    /// The sensors, node 0 first.
    pub fn sensors(&self) -> &[Sensor] {
        &self.sensors
    }
    /// The control input, if any.
    pub fn control(&self) -> Option<&Control> {
        self.control.as_ref()
    }
    /// The effective process-noise covariance `B Q Bᵀ`.
    pub fn process_cov(&self) -> &DMatrix<f64> {
        &self.bqb
    }
    /// C of node `node`.
    pub fn c(&self, node: usize) -> &DMatrix<f64> {
        &self.sensors[node].c
    }
    /// The effective measurement-noise covariance `D R Dᵀ` of node `node`.
    pub fn measurement_cov(&self, node: usize) -> &DMatrix<f64> {
        &self.drd[node]
    }
    /// `B_u u_k` into `out[..nx]` and `true`, or `false` (nothing written) without an input.
    pub fn input_into(&self, k: usize, out: &mut [f64]) -> bool {
        match &self.control {
            Some(c) => {
                c.input_into(k, out);
                true
            }
            None => false,
        }
    }
    /// `true` when nothing depends on k (no control input): an estimator may convert the model
    /// once.
    pub fn time_invariant(&self) -> bool {
        self.control.is_none()
    }
}

/// `(m + mᵀ) / 2`.
pub fn symmetric(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}
