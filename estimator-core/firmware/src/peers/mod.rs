//! The core's Kalman filter side by side with its Rust peers (`adskalman` 0.18, `typed-kalman`
//! 0.1, `minikalman` 0.8, all `no_std` without `alloc`) on the benches' two KF problems
//! (`benches/src/problems.rs`): seed 001's 3-state, 2-measurement model and a planar
//! constant-velocity tracker with 4 states and 2 measurements, both in `f32`.
//!
//! Every implementation runs over the same measurement stream: the sensor measurements z_k of
//! the embedded occlusion stream (k = 1..100, every instant, as the lossless `kf` binary takes
//! them), from the problem's prior, each instant one predict and one update. The 3x2 problem is
//! the model that stream was simulated from; the tracker reads the two measurements as the
//! two positions (the tracker's model does not fit that motion, which changes nothing for the
//! work of a step: a Kalman step has no data-dependent branch).
//!
//! All of them go through one driver ([`drive_kf`], the loop of [`crate::run::drive`] without
//! labels: construction in a frame of its own, the step out of line, the digest of x̂_k and P_k
//! after every step), so that the instruction counts differ only by the filters' steps. The
//! same source runs on the host (`tests/firmware_qemu.rs`), which checks the result lines bit
//! for bit and the peers' estimates against ours.
#![forbid(unsafe_code)]

mod ads;
mod floor;
mod mk;
mod tk;

pub use ads::Ads;
pub use floor::{ops, Floor, Ops};
pub use mk::{mk3x2, mk4x2, Mk};
pub use tk::Tk;

use estimator_core::filter::{CovarianceForm, JosephForm, KalmanFilter, StandardForm};
use estimator_core::model::{LinearModel, LinearSystem};
use estimator_core::Error;
use nalgebra::{Matrix2x4, Matrix4, SMatrix, SVector, Vector2};

use crate::run::mark::{branch, step_mark, BEGIN, REFUSED};
use crate::run::{model, prior, Fnv1a64, Link, Stream, Summary, MAX_NX};

/// Measurements per instant (both problems).
pub const NY: usize = 2;

/// A KF problem: the model (B = I, D = I) and the prior.
#[derive(Clone, Copy, Debug)]
pub struct Problem<const NX: usize> {
    /// A, C, Q, R.
    pub model: LinearModel<f32, NX, NX, NY, NY>,
    /// x̂₀.
    pub x0: SVector<f32, NX>,
    /// P₀.
    pub p0: SMatrix<f32, NX, NX>,
}

impl<const NX: usize> Problem<NX> {
    /// A (time-invariant).
    pub fn a(&self) -> SMatrix<f32, NX, NX> {
        self.model.a(0)
    }
    /// Q (= B Q Bᵀ with B = I).
    pub fn q(&self) -> SMatrix<f32, NX, NX> {
        self.model.process_cov(0)
    }
    /// C.
    pub fn c(&self) -> SMatrix<f32, NY, NX> {
        self.model.c(0)
    }
    /// R (= D R Dᵀ with D = I).
    pub fn r(&self) -> SMatrix<f32, NY, NY> {
        self.model.measurement_cov(0)
    }
}

/// The benches' `3x2_f32`: seed 001's model and prior (x̂₀ = [5 5 5]ᵀ, P₀ = 4 I₃).
pub fn problem_3x2() -> Result<Problem<3>, Error> {
    let (x0, p0) = prior();
    Ok(Problem {
        model: model()?,
        x0,
        p0,
    })
}

/// The benches' `4x2_f32`: state [x, y, ẋ, ẏ], positions measured, dt = 0.01, white
/// acceleration of intensity 100 (Q), R = 0.01 I₂; x̂₀ = 0, P₀ = 10 I₄.
pub fn problem_4x2() -> Result<Problem<4>, Error> {
    let dt = 0.01f32;
    let q = 100.0f32;
    let (t3, t2) = (dt * dt * dt / 3.0 * q, dt * dt / 2.0 * q);
    #[rustfmt::skip]
    let a = Matrix4::new(
        1.0, 0.0, dt, 0.0,
        0.0, 1.0, 0.0, dt,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    #[rustfmt::skip]
    let qm = Matrix4::new(
        t3, 0.0, t2, 0.0,
        0.0, t3, 0.0, t2,
        t2, 0.0, dt * q, 0.0,
        0.0, t2, 0.0, dt * q,
    );
    let model = LinearModel::new(
        a,
        SMatrix::identity(),
        Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
        SMatrix::identity(),
        qm,
        SMatrix::identity() * 0.01,
    )?;
    Ok(Problem {
        model,
        x0: SVector::zeros(),
        p0: SMatrix::identity() * 10.0,
    })
}

/// A Kalman filter implementation as [`drive_kf`] runs it.
pub trait KfStep<const NX: usize> {
    /// Instant k ≥ 1: predict from k − 1, update with `y`. `false` if the implementation
    /// refused (what it then keeps is its own rule).
    fn step(&mut self, k: usize, y: &Vector2<f32>) -> bool;
    /// Entry i of x̂_k.
    fn x(&self, i: usize) -> f32;
    /// Entry (i, j) of P_k.
    fn p(&self, i: usize, j: usize) -> f32;
}

/// The core's Kalman filter (every input and result validated) on the problem's model, its
/// covariance form fixed at compile time (`F`: Joseph by default), so that the binary links
/// that form only.
#[derive(Clone, Debug)]
pub struct Ours<const NX: usize, F: CovarianceForm = JosephForm> {
    /// The model.
    pub model: LinearModel<f32, NX, NX, NY, NY>,
    /// The filter.
    pub kf: KalmanFilter<f32, NX, F>,
}

impl<const NX: usize> Ours<NX> {
    /// The filter (Joseph form) at the problem's prior.
    pub fn new(p: &Problem<NX>) -> Result<Self, Error> {
        Ok(Self {
            model: p.model,
            kf: KalmanFilter::new(p.x0, p.p0)?.with_form(JosephForm),
        })
    }

    /// The same filter with the optimal-gain covariance form P − K Gᵀ
    /// ([`StandardForm`]).
    pub fn standard(self) -> Ours<NX, StandardForm> {
        Ours {
            model: self.model,
            kf: self.kf.with_form(StandardForm),
        }
    }
}

impl<const NX: usize, F: CovarianceForm> KfStep<NX> for Ours<NX, F> {
    #[inline(never)]
    fn step(&mut self, k: usize, y: &Vector2<f32>) -> bool {
        self.kf.step(&self.model, k, y).is_ok()
    }
    fn x(&self, i: usize) -> f32 {
        self.kf.estimate().state()[i]
    }
    fn p(&self, i: usize, j: usize) -> f32 {
        self.kf.estimate().covariance()[(i, j)]
    }
}

/// See [`crate::run::drive`]'s `construct`: the constructor's temporaries in a frame of
/// their own.
#[inline(never)]
fn construct<E>(build: impl FnOnce() -> Option<E>) -> Option<E> {
    build()
}

/// Runs the implementation `build` makes over the first `steps` instants of the occlusion
/// stream's sensor measurements (every instant, the lossless link), digesting after every
/// step a zero label byte, x̂_k and the upper triangle of P_k (as [`Fnv1a64::estimate`]
/// does, through [`KfStep::x`] and [`KfStep::p`] for every implementation alike).
pub fn drive_kf<const NX: usize, E: KfStep<NX>>(
    name: &'static str,
    stream: &Stream<'_>,
    steps: usize,
    build: impl FnOnce() -> Option<E>,
) -> Summary {
    let mut s = Summary {
        name,
        steps: 0,
        arrivals: 0,
        dropouts: 0,
        errors: 0,
        first_error: 0,
        digest: Fnv1a64::default().0,
        nx: 0,
        x_bits: [0; MAX_NX],
    };
    let mut built = construct(build);
    let Some(est) = &mut built else {
        s.errors = 1;
        return s;
    };
    s.digest = step_all(&mut s, est, stream, steps);
    s.nx = NX.min(MAX_NX);
    for (i, b) in s.x_bits.iter_mut().enumerate().take(s.nx) {
        *b = est.x(i).to_bits();
    }
    s
}

/// The loop of [`drive_kf`], in a frame of its own. Marks each step's start and end for the
/// instruction-count plugin (see [`crate::run::mark`]).
#[inline(never)]
fn step_all<const NX: usize, E: KfStep<NX>>(
    s: &mut Summary,
    est: &mut E,
    stream: &Stream<'_>,
    steps: usize,
) -> u64 {
    let mut h = Fnv1a64::default();
    step_mark(0, 0);
    for inst in stream.instants(Link::Lossless).take(steps) {
        s.steps += 1;
        let [y] = inst.y;
        let Some(y) = y else {
            // Not on the lossless link: every instant has its measurement.
            s.dropouts += 1;
            refused(s, inst.k);
            continue;
        };
        s.arrivals += 1;
        let code = branch([true], |_| false);
        step_mark(inst.k, BEGIN);
        let ok = est.step(inst.k as usize, &y);
        step_mark(inst.k, if ok { code } else { code | REFUSED });
        if !ok {
            refused(s, inst.k);
        }
        h.bytes(&[0]);
        for i in 0..NX {
            h.f32(est.x(i));
        }
        for i in 0..NX {
            for j in i..NX {
                h.f32(est.p(i, j));
            }
        }
    }
    h.0
}

/// Counts a refused step at instant `k`.
fn refused(s: &mut Summary, k: u32) {
    if s.errors == 0 {
        s.first_error = k;
    }
    s.errors += 1;
}

/// Ours on the 3x2 problem.
pub fn run_kf3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("kf3x2", stream, steps, || {
        Ours::new(&problem_3x2().ok()?).ok()
    })
}

/// Ours on the 4x2 problem.
pub fn run_kf4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("kf4x2", stream, steps, || {
        Ours::new(&problem_4x2().ok()?).ok()
    })
}

/// Ours on the 3x2 problem with the optimal-gain covariance form P − K Gᵀ (the form
/// `minikalman` uses; ours keeps it exactly symmetric and validates as in the Joseph form).
pub fn run_kfs3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("kfs3x2", stream, steps, || {
        Ours::new(&problem_3x2().ok()?).ok().map(Ours::standard)
    })
}

/// Ours on the 4x2 problem with the optimal-gain covariance form.
pub fn run_kfs4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("kfs4x2", stream, steps, || {
        Ours::new(&problem_4x2().ok()?).ok().map(Ours::standard)
    })
}

/// `adskalman` on the 3x2 problem (Joseph form).
pub fn run_ads3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("ads3x2", stream, steps, || {
        Some(Ads::new(&problem_3x2().ok()?))
    })
}

/// `adskalman` on the 4x2 problem (Joseph form).
pub fn run_ads4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("ads4x2", stream, steps, || {
        Some(Ads::new(&problem_4x2().ok()?))
    })
}

/// `typed-kalman` on the 3x2 problem (its `LinearKf`, Joseph form).
pub fn run_tk3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("tk3x2", stream, steps, || {
        Some(Tk::new(&problem_3x2().ok()?))
    })
}

/// `typed-kalman` on the 4x2 problem.
pub fn run_tk4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("tk4x2", stream, steps, || {
        Some(Tk::new(&problem_4x2().ok()?))
    })
}

/// `minikalman` on the 3x2 problem (its regular filter: P − K H P, no Joseph form).
pub fn run_mk3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("mk3x2", stream, steps, || Some(mk3x2(&problem_3x2().ok()?)))
}

/// `minikalman` on the 4x2 problem.
pub fn run_mk4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("mk4x2", stream, steps, || Some(mk4x2(&problem_4x2().ok()?)))
}

/// The floor (straight-line, nothing validated) on the 3x2 problem.
pub fn run_floor3x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("floor3x2", stream, steps, || {
        Some(Floor::new(&problem_3x2().ok()?))
    })
}

/// The floor on the 4x2 problem.
pub fn run_floor4x2(stream: &Stream<'_>, steps: usize) -> Summary {
    drive_kf("floor4x2", stream, steps, || {
        Some(Floor::new(&problem_4x2().ok()?))
    })
}
