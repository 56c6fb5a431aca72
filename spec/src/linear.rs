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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Schedule;
    use nalgebra::dmatrix;

    /// `m₁ m₂ m₃ᵀ` by the definition, entry by entry.
    fn congruence(m: &DMatrix<f64>, s: &DMatrix<f64>) -> DMatrix<f64> {
        let (r, c) = m.shape();
        DMatrix::from_fn(r, r, |i, j| {
            let mut acc = 0.0;
            for k in 0..c {
                for l in 0..c {
                    acc += m[(i, k)] * s[(k, l)] * m[(j, l)];
                }
            }
            acc
        })
    }

    fn close(a: &DMatrix<f64>, b: &DMatrix<f64>) {
        assert_eq!(a.shape(), b.shape());
        for (x, y) in a.iter().zip(b.iter()) {
            assert!((x - y).abs() <= 1e-14 * (1.0 + y.abs()), "{a} vs {b}");
        }
    }

    /// nx = 3, nw = 2 (B not square), one node of ny = 2 with nv = 3.
    fn model() -> LinearModel {
        let a = dmatrix![0.9, 0.1, 0.0; 0.0, 0.8, 0.2; 0.1, 0.0, 0.7];
        let b = dmatrix![1.0, 0.5; -0.3, 2.0; 0.7, 0.0];
        let q = dmatrix![0.4, 0.1; 0.1, 0.3];
        let sensor = Sensor {
            c: dmatrix![1.0, 0.0, 2.0; 0.0, 1.0, -1.0],
            d: dmatrix![1.0, 0.2, 0.0; 0.0, 0.5, 1.5],
            r: dmatrix![0.2, 0.05, 0.0; 0.05, 0.3, 0.01; 0.0, 0.01, 0.1],
        };
        LinearModel::new(a, b, q, vec![sensor]).unwrap()
    }

    #[test]
    fn effective_covariances_are_the_symmetrised_congruences() {
        let m = model();
        let bqb = congruence(m.b(), m.q());
        close(m.process_cov(), &((&bqb + bqb.transpose()) * 0.5));
        // Exactly symmetric, as formed.
        assert_eq!(m.process_cov(), &m.process_cov().transpose());
        // By hand for the (0, 1) entry: Σ_kl B₀k Q_kl B₁l.
        let hand = 1.0 * 0.4 * -0.3 + 1.0 * 0.1 * 2.0 + 0.5 * 0.1 * -0.3 + 0.5 * 0.3 * 2.0;
        assert!((m.process_cov()[(0, 1)] - hand).abs() < 1e-15);
        let s = &m.sensors()[0];
        let drd = congruence(&s.d, &s.r);
        close(m.measurement_cov(0), &((&drd + drd.transpose()) * 0.5));
        assert_eq!((m.nx(), m.nodes(), m.node_ny(0)), (3, 1, 2));
        assert!(m.time_invariant());
    }

    #[test]
    fn input_into_is_b_u_times_u_k_for_every_schedule() {
        let bu = dmatrix![1.0, -2.0; 0.5, 0.0; 0.0, 3.0];
        // Reference: Σ_j B_u[r][j] u_j, with u_k given by the test's own formula.
        let expect =
            |u: [f64; 2]| -> [f64; 3] { [1.0 * u[0] - 2.0 * u[1], 0.5 * u[0], 3.0 * u[1]] };
        let with = |schedule: Schedule| {
            model()
                .with_control(Control::new(bu.clone(), schedule, 3).unwrap())
                .unwrap()
        };
        let check = |m: &LinearModel, k: usize, u: [f64; 2]| {
            // A sentinel past n_x must be left alone.
            let mut out = [f64::NAN, f64::NAN, f64::NAN, 42.0];
            assert!(m.input_into(k, &mut out));
            let want = expect(u);
            for r in 0..3 {
                assert!(
                    (out[r] - want[r]).abs() < 1e-12,
                    "k {k}: {out:?} vs {want:?}"
                );
            }
            assert_eq!(out[3], 42.0);
            assert!(!m.time_invariant());
        };

        let constant = with(Schedule::Constant(vec![2.0, -1.0]));
        for k in [0, 1, 1000, usize::MAX] {
            check(&constant, k, [2.0, -1.0]);
        }
        // u_k = offset + amplitude · sin(τ k / period + phase).
        let sinusoid = with(Schedule::Sinusoid {
            offset: vec![1.0, 0.0],
            amplitude: vec![3.0, -2.0],
            period: 8.0,
            phase: 0.5,
        });
        for k in 0..20 {
            let s = (std::f64::consts::TAU * k as f64 / 8.0 + 0.5).sin();
            check(&sinusoid, k, [1.0 + 3.0 * s, -2.0 * s]);
        }
        // k = 2: sin(π/2 + 0.5) = cos(0.5).
        check(
            &sinusoid,
            2,
            [1.0 + 3.0 * 0.5_f64.cos(), -2.0 * 0.5_f64.cos()],
        );
        let list = with(Schedule::List(vec![
            vec![1.0, 2.0],
            vec![3.0, 4.0],
            vec![5.0, 6.0],
        ]));
        for (k, u) in [
            (0, [1.0, 2.0]),
            (1, [3.0, 4.0]),
            (2, [5.0, 6.0]),
            (3, [1.0, 2.0]),
            (7, [3.0, 4.0]),
        ] {
            check(&list, k, u);
        }

        // Without a control: false, nothing written.
        let mut out = [7.0; 3];
        assert!(!model().input_into(5, &mut out));
        assert_eq!(out, [7.0; 3]);
    }

    #[test]
    fn each_bad_part_is_named() {
        let err = |r: Result<LinearModel, SpecError>| r.unwrap_err().to_string();
        let m = model();
        let s = m.sensors()[0].clone();
        let new = |a: DMatrix<f64>, b: DMatrix<f64>, q: DMatrix<f64>, s: Vec<Sensor>| {
            err(LinearModel::new(a, b, q, s))
        };
        let (a, b, q) = (m.a().clone(), m.b().clone(), m.q().clone());
        assert!(new(
            a.columns(0, 2).into(),
            b.clone(),
            q.clone(),
            vec![s.clone()]
        )
        .contains("`model.a`"));
        assert!(new(
            a.clone(),
            b.columns(0, 1).into(),
            q.clone(),
            vec![s.clone()]
        )
        .contains("`model.b`"));
        assert!(new(a.clone(), b.clone(), -q.clone(), vec![s.clone()]).contains("`model.q`"));
        assert!(new(a.clone(), b.clone(), q.clone(), vec![]).contains("`sensors`"));
        let mut bad = s.clone();
        bad.r[(0, 0)] = -1.0;
        assert!(
            new(a.clone(), b.clone(), q.clone(), vec![s.clone(), bad]).contains("`sensors[1].r`")
        );
        let mut bad = s.clone();
        bad.c = dmatrix![1.0, 0.0; 0.0, 1.0];
        assert!(new(a.clone(), b.clone(), q.clone(), vec![bad]).contains("`sensors[0].c`"));
        let mut bad = s;
        bad.d = dmatrix![1.0, 0.0; 0.0, 1.0];
        assert!(new(a, b, q, vec![bad]).contains("`sensors[0].d`"));
        let control = Control::new(dmatrix![1.0; 0.0], Schedule::Constant(vec![1.0]), 2).unwrap();
        assert!(err(model().with_control(control)).contains("`control.b`"));
    }
}
