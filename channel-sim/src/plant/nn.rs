//! The plant of seed 003, section IV: a time-varying nonlinear system whose single noise
//! `w_k` drives both the state and the measurement (eq. 1):
//!
//! ```text
//! x_{k+1} = A_k x_k + f(x_k) + B_k w_k
//! y_k     = C_k x_k + D_k w_k,          w_k ~ N(0, w̄²)  (docs/design.md, Seed 003: w̄² = 0.1)
//! ```
//!
//! The matrices and `f` come from `estimator_core::papers::Seed003Example`, the
//! same code the estimators use. Because `w_k` enters `y_k` *and* `x_{k+1}`, one run keeps the
//! `w_k` drawn for `y_k` and uses it in the next state transition.
//!
//! The sensor measures from k = 0, as the paper's timing has it (eq. (2) decides at k = 0 and
//! eq. (5) uses `y₀` for `x̂₁`; docs/design.md, "Seed 003"): [`PlantRun::initial_measurement`]
//! draws `w₀`, writes `y₀ = C₀ x₀ + D₀ w₀` and keeps `w₀` for `x₁`. The draws come in the
//! order `w₀, w₁, …` either way, so `x_k` and `y_k` for k ≥ 1 are the same numbers whether or
//! not `y₀` is read. The plant offers no linear model ([`Plant::linear`]): it is
//! neither linear nor has independent process and measurement noise.

use std::any::Any;

use estimator_core::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap};
use estimator_core::papers::Seed003Example;
use nalgebra::SVector;
use rand_distr::{Distribution, StandardNormal};

use super::{Plant, PlantRun};
use crate::error::ScenarioError;
use crate::rng::SimRng;
use crate::sim::MAX_NY;

/// The section IV plant with noise variance `w_var` (= w̄²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seed003Plant {
    w_var: f64,
}

impl Seed003Plant {
    /// A plant with `w_k ~ N(0, w_var)`; `w_var` must be finite and positive.
    pub fn new(w_var: f64) -> Result<Self, ScenarioError> {
        if !(w_var.is_finite() && w_var > 0.0) {
            return Err(ScenarioError::invalid(
                "model.w_var",
                format!("must be a finite positive variance, got {w_var}"),
            ));
        }
        Ok(Self { w_var })
    }

    /// `w̄²`.
    pub fn w_var(&self) -> f64 {
        self.w_var
    }
}

impl Plant for Seed003Plant {
    fn nx(&self) -> usize {
        3
    }
    fn ny(&self) -> usize {
        2
    }
    fn nodes(&self) -> usize {
        1
    }
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun> {
        Box::new(Seed003Run {
            sd: self.w_var.sqrt(),
            x: SVector::from_column_slice(&x0[..3]),
            pending_w: None,
        })
    }
    fn model(&self) -> Option<estpipe_spec::Model> {
        Some(estpipe_spec::Model::Seed003 { w_var: self.w_var })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[derive(Debug)]
struct Seed003Run {
    sd: f64,
    x: SVector<f64, 3>,
    /// `w_{k}` already used in `y_k`, to be used in `x_{k+1}`.
    pending_w: Option<f64>,
}

impl Seed003Run {
    /// `w ~ N(0, w̄²)` from the plant stream.
    fn draw(&self, rng: &mut SimRng) -> f64 {
        let n: f64 = StandardNormal.sample(rng);
        self.sd * n
    }

    /// `y_k = C_k x_k + D_k w_k` of the current state with `w`.
    fn measure(&self, k: u32, w: f64, z: &mut [[f64; MAX_NY]]) {
        let sys = Seed003Example;
        let c: nalgebra::SMatrix<f64, 2, 3> = sys.c(k as usize);
        let d: nalgebra::SMatrix<f64, 2, 1> = sys.d(k as usize);
        let y = c * self.x + d * w;
        z[0][..2].copy_from_slice(y.as_slice());
    }
}

impl PlantRun for Seed003Run {
    fn state(&self) -> &[f64] {
        self.x.as_slice()
    }

    fn initial_measurement(&mut self, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]) -> bool {
        // w₀: the first draw of the run, the one `advance(1)` would otherwise make for x₁.
        let w0 = self.draw(rng);
        self.measure(0, w0, z);
        self.pending_w = Some(w0);
        true
    }

    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]) {
        let sys = Seed003Example;
        let prev = k.saturating_sub(1) as usize;
        // w_{k−1}: kept from y_{k−1} (from y₀ when the run measured at k = 0).
        let w_prev = match self.pending_w.take() {
            Some(w) => w,
            None => self.draw(rng),
        };
        let a: nalgebra::SMatrix<f64, 3, 3> = sys.a(prev);
        let b: nalgebra::SMatrix<f64, 3, 1> = sys.b(prev);
        self.x = a * self.x + sys.eval(&self.x) + b * w_prev;
        let w = self.draw(rng);
        self.measure(k, w, z);
        self.pending_w = Some(w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{run_rng, Stream};

    #[test]
    fn same_noise_drives_measurement_and_next_state() {
        // Reconstruct w_k from y_k (first row, D = 0.95) and check x_{k+1} with it.
        let p = Seed003Plant::new(0.1).unwrap();
        let mut run = p.start(&[3.1, -2.65, 4.0]);
        let mut rng = run_rng(1, 0, Stream::Plant);
        let mut z = [[0.0; MAX_NY]; 1];
        let sys = Seed003Example;
        run.advance(1, &mut rng, &mut z);
        for k in 2..50u32 {
            let xk = SVector::<f64, 3>::from_column_slice(run.state());
            let c: nalgebra::SMatrix<f64, 2, 3> = sys.c(k as usize - 1);
            let wk = (z[0][0] - (c * xk)[0]) / 0.95;
            // Second row agrees with the same w_k.
            let d1 = 0.65 * ((k - 1) as f64).sin();
            assert!((z[0][1] - (c * xk)[1] - d1 * wk).abs() < 1e-9);
            run.advance(k, &mut rng, &mut z);
            let a: nalgebra::SMatrix<f64, 3, 3> = sys.a(k as usize - 1);
            let b: nalgebra::SMatrix<f64, 3, 1> = sys.b(k as usize - 1);
            let expect = a * xk + sys.eval(&xk) + b * wk;
            let got = SVector::<f64, 3>::from_column_slice(run.state());
            assert!(
                (got - expect).amax() < 1e-9 * expect.amax().max(1.0),
                "k={k}"
            );
        }
        assert!(Seed003Plant::new(-1.0).is_err());
    }

    #[test]
    fn y0_shares_w0_with_x1_and_leaves_later_instants_unchanged() {
        // y₀ = C₀ x₀ + D₀ w₀ with D₀ = [0.95, 0]ᵀ (sin 0 = 0): w₀ = (y₀ − C₀ x₀)₁ / 0.95, and
        // the second row carries no noise at all. The same w₀ must drive x₁.
        let p = Seed003Plant::new(0.1).unwrap();
        let sys = Seed003Example;
        let x0 = SVector::<f64, 3>::new(3.1, -2.65, 4.0);
        let mut run = p.start(x0.as_slice());
        let mut rng = run_rng(5, 0, Stream::Plant);
        let mut z = [[0.0; MAX_NY]; 1];
        assert!(run.initial_measurement(&mut rng, &mut z));
        let c0: nalgebra::SMatrix<f64, 2, 3> = sys.c(0);
        let r = SVector::<f64, 2>::new(z[0][0], z[0][1]) - c0 * x0;
        assert_eq!(r[1], 0.0);
        let w0 = r[0] / 0.95;
        run.advance(1, &mut rng, &mut z);
        let a0: nalgebra::SMatrix<f64, 3, 3> = sys.a(0);
        let b0: nalgebra::SMatrix<f64, 3, 1> = sys.b(0);
        let x1 = a0 * x0 + sys.eval(&x0) + b0 * w0;
        let got = SVector::<f64, 3>::from_column_slice(run.state());
        assert!((got - x1).amax() < 1e-12, "{got} vs {x1}");
        // Reading y₀ or not: x_k and y_k for k ≥ 1 are the same bits (w₀ is the first draw
        // either way).
        let mut with = p.start(x0.as_slice());
        let mut without = p.start(x0.as_slice());
        let (mut r1, mut r2) = (run_rng(6, 3, Stream::Plant), run_rng(6, 3, Stream::Plant));
        let (mut z1, mut z2) = ([[0.0; MAX_NY]; 1], [[0.0; MAX_NY]; 1]);
        assert!(with.initial_measurement(&mut r1, &mut z1));
        for k in 1..=50 {
            with.advance(k, &mut r1, &mut z1);
            without.advance(k, &mut r2, &mut z2);
            assert_eq!(with.state(), without.state(), "k = {k}");
            assert_eq!(z1, z2, "k = {k}");
        }
    }

    #[test]
    fn noise_has_the_configured_variance() {
        // The first-row residual y_k − C_k x_k = 0.95 w_k; its sample variance over 20 000
        // draws should be 0.95²·0.1 within 5 standard errors (SE of a variance estimate is
        // σ²·sqrt(2/n)).
        let p = Seed003Plant::new(0.1).unwrap();
        let sys = Seed003Example;
        let n = 20_000;
        let mut s2 = 0.0;
        for run in 0..n {
            let mut r = p.start(&[0.0, 0.0, 0.0]);
            let mut rng = run_rng(3, run, Stream::Plant);
            let mut z = [[0.0; MAX_NY]; 1];
            r.advance(1, &mut rng, &mut z);
            let c: nalgebra::SMatrix<f64, 2, 3> = sys.c(1);
            let res = z[0][0] - (c * SVector::<f64, 3>::from_column_slice(r.state()))[0];
            s2 += res * res;
        }
        let var = s2 / n as f64;
        let want = 0.95f64.powi(2) * 0.1;
        assert!(
            (var - want).abs() < 5.0 * want * (2.0 / n as f64).sqrt(),
            "{var}"
        );
    }
}
