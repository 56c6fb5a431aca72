//! The models the streams were simulated from, in `f32`: seed 001's linear model, prior and
//! occlusion mechanism (the occlusion stream), and seed 004's oscillator with the example's
//! event-trigger parameters (the Tobit stream). The token-bucket stream's system is the core's
//! `Seed003Example`.

use estimator_core::model::LinearModel;
use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use estimator_core::Error;
use nalgebra::{ComplexField, Matrix2, Matrix2x3, Matrix3, SMatrix, Vector2, Vector3};

use super::vectors::{NODES, NX, NY};

/// Seed 001 Section IV in `f32`: A, C as printed, B = I₃, D = I₂ (docs/design.md, Seed 001),
/// Q = 0.3 I₃, R = 0.2 I₂.
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

/// Seed 001's dropout mechanism in `f32`: E = [1 0 0], Ψ = 0.1, regions [20i − 5, 20i + 5].
pub fn occlusion() -> Result<Occlusion<f32, NX, 1, 4>, Error> {
    use nalgebra::{Matrix1, Matrix1x3, Vector1};
    let c = |z: f32| Vector1::new(z);
    let regions = OcclusionRegions::new([c(20.0), c(40.0), c(60.0), c(80.0)], [5.0; 4])?;
    Occlusion::new(Matrix1x3::new(1.0, 0.0, 0.0), Matrix1::new(0.1), regions)
}

/// σ_m of the example's triggers (seed 004, section 4).
pub const TOBIT_SIGMA: [f32; NODES] = [0.1, 0.2, 0.3];
/// λ_m of the example's triggers.
pub const TOBIT_LAMBDA: [f32; NODES] = [0.1, 0.2, 0.1];
/// χ_m (the example's "θ_m = 5", docs/design.md, Seed 004).
pub const TOBIT_CHI: f32 = 5.0;
/// η_{m,0}.
pub const TOBIT_ETA0: f32 = 1.5;

/// Seed 004's oscillator in `f32`, per instant and node as
/// [`TobitFusion::step`](estimator_core::filter::TobitFusion::step) takes it:
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
