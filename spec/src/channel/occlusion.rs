//! Seed 001's occlusion regions (eqs. 2-3) as the estimators know them: the packets of instant
//! `k` are lost iff `u_k = E x_k + n_k`, `n_k ~ N(0, Ψ)`, lies in one of the intervals
//! `[ζ_i − r_i, ζ_i + r_i]` (`n_e = 1`, as in the paper's example).

use estimator_core::protocol::occlusion::{Occlusion as CoreOcclusion, OcclusionRegions};
use nalgebra::{SMatrix, SVector};

use crate::error::SpecError;

/// The most occlusion regions a spec may declare (the estimators are compiled per count).
pub const MAX_OCCLUSION_REGIONS: usize = 4;

/// The largest `|ζ_i| + r_i` accepted: differences, sums and squares of centres and radii
/// stay finite.
pub const MAX_REGION_EXTENT: f64 = 1e150;

/// The occlusion model: `E`, `Ψ` and the regions' centres and half-widths.
#[derive(Clone, Debug, PartialEq)]
pub struct Occlusion {
    e: Vec<f64>,
    psi: f64,
    centres: Vec<f64>,
    radii: Vec<f64>,
}

impl Occlusion {
    /// Validates `E` (n_x finite entries), `Ψ` (a variance the estimators can factor) and the
    /// regions (1 to [`MAX_OCCLUSION_REGIONS`], disjoint, positive half-widths); errors name
    /// `occlusion.e`, `occlusion.psi`, `occlusion.centres`, `occlusion.radii`,
    /// `occlusion.regions`.
    pub fn new(
        e: Vec<f64>,
        psi: f64,
        centres: Vec<f64>,
        radii: Vec<f64>,
        nx: usize,
    ) -> Result<Self, SpecError> {
        if e.len() != nx || e.iter().any(|v| !v.is_finite()) {
            return Err(SpecError::invalid(
                "occlusion.e",
                format!("must be {nx} finite entries"),
            ));
        }
        // The estimators' own test of Ψ too (a Cholesky factor): a variance this rejects
        // (1e308: its factor overflows) must be refused here, naming the field, and not
        // later by every estimator as "does not match the plant".
        if !psi.is_finite()
            || psi <= 0.0
            || estimator_core::linalg::check_spd(&SMatrix::<f64, 1, 1>::new(psi), "Psi").is_err()
        {
            return Err(SpecError::invalid(
                "occlusion.psi",
                format!("must be a positive variance the estimators can factor, got {psi:e}"),
            ));
        }
        let n = centres.len();
        if n == 0 || n > MAX_OCCLUSION_REGIONS {
            return Err(SpecError::invalid(
                "occlusion.centres",
                format!("must have 1 to {MAX_OCCLUSION_REGIONS} entries, got {n}"),
            ));
        }
        if radii.len() != n {
            return Err(SpecError::invalid(
                "occlusion.radii",
                format!("must have one entry per centre ({n}), got {}", radii.len()),
            ));
        }
        // The core's overlap test subtracts centres and adds radii: beyond this bound those
        // overflow to ∞ and `∞ < ∞` let overlapping regions through (centres ±1e308, radii
        // 1.5e308); the estimators also square them.
        if centres
            .iter()
            .zip(&radii)
            .map(|(c, r)| c.abs() + r.abs())
            .any(|x| !x.is_finite() || x > MAX_REGION_EXTENT)
        {
            return Err(SpecError::invalid(
                "occlusion.regions",
                format!("every |centre| + radius must be finite and at most {MAX_REGION_EXTENT:e}"),
            ));
        }
        let out = Self {
            e,
            psi,
            centres,
            radii,
        };
        macro_rules! check {
            ($($s:literal)*) => {
                match n {
                    $($s => out.regions::<$s>().map(|_| ()),)*
                    _ => unreachable!("n is 1..=MAX_OCCLUSION_REGIONS"),
                }
            };
        }
        check!(1 2 3 4).map_err(|e| SpecError::invalid("occlusion.regions", e.to_string()))?;
        Ok(out)
    }

    /// E, the row of `u = E x + n`.
    pub fn e(&self) -> &[f64] {
        &self.e
    }
    /// Ψ, the variance of n.
    pub fn psi(&self) -> f64 {
        self.psi
    }
    /// ζ_i, the regions' centres.
    pub fn centres(&self) -> &[f64] {
        &self.centres
    }
    /// r_i, the regions' half-widths.
    pub fn radii(&self) -> &[f64] {
        &self.radii
    }
    /// The number of regions S.
    pub fn count(&self) -> usize {
        self.centres.len()
    }

    /// The regions at the compiled count `S` (an error unless `S` is [`Occlusion::count`]).
    pub fn regions<const S: usize>(&self) -> estimator_core::Result<OcclusionRegions<f64, 1, S>> {
        if self.count() != S {
            return Err(estimator_core::Error::InvalidConfig {
                field: "regions",
                reason: "count differs from the compiled one",
            });
        }
        OcclusionRegions::new(
            core::array::from_fn(|i| SVector::from([self.centres[i]])),
            core::array::from_fn(|i| self.radii[i]),
        )
    }

    /// The core's occlusion model at `NX` states and `S` regions (`None` when either differs).
    pub fn at<const NX: usize, const S: usize>(&self) -> Option<CoreOcclusion<f64, NX, 1, S>> {
        (self.e.len() == NX).then_some(())?;
        CoreOcclusion::new(
            SMatrix::<f64, 1, NX>::from_fn(|_, j| self.e[j]),
            SMatrix::<f64, 1, 1>::new(self.psi),
            self.regions::<S>().ok()?,
        )
        .ok()
    }
}
