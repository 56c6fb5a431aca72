//! State-dependent packet dropouts by occlusion regions (seed 001, eqs. (2)-(3)).
//!
//! The packet of instant `k` is lost iff the auxiliary variable `u_k = E x_k + n_k`
//! (`n_k ~ N(0, Ψ)`, eq. 3) lies in one of `S` closed balls `R_i = {u : ‖u − ζ_i‖ ≤ r_i}`
//! (intervals when `n_e = 1`); the region label is `h_k = i` (1-based) inside `R_i` and
//! `h_k = 0` outside every region. The paper's labels are unique, so the regions must be
//! disjoint: [`OcclusionRegions::new`] refuses overlapping interiors (`‖ζ_i − ζ_j‖ < r_i + r_j`);
//! regions that merely touch share a boundary point of probability zero, which is assigned to
//! the lower index.
//!
//! ```
//! use estimator_core::protocol::occlusion::OcclusionRegions;
//! use nalgebra::vector;
//! // The paper's example: ζ_i = 20 i, r_i = 5.
//! let r = OcclusionRegions::<f64, 1, 4>::new(
//!     [vector![20.0], vector![40.0], vector![60.0], vector![80.0]],
//!     [5.0; 4],
//! )?;
//! assert_eq!(r.label(&vector![41.0]), 2);
//! assert!(!r.drops(&vector![30.0]));
//! # Ok::<(), estimator_core::Error>(())
//! ```

use nalgebra::{SMatrix, SVector};

use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::{Error, Real, Result};

/// `S` disjoint closed balls in the `NE`-dimensional space of `u_k` (eq. 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionRegions<T: Real, const NE: usize, const S: usize> {
    centres: [SVector<T, NE>; S],
    radii: [T; S],
}

impl<T: Real, const NE: usize, const S: usize> OcclusionRegions<T, NE, S> {
    /// Validates finite centres, finite positive radii, `S ≥ 1`, `NE ≥ 1` and disjoint
    /// interiors.
    pub fn new(centres: [SVector<T, NE>; S], radii: [T; S]) -> Result<Self> {
        if S == 0 || NE == 0 {
            return Err(Error::InvalidConfig {
                field: "regions",
                reason: "need at least one region of dimension at least one",
            });
        }
        for c in &centres {
            check_finite(c, "region centre")?;
        }
        for &r in &radii {
            if !r.finite() {
                return Err(Error::NonFinite {
                    what: "region radius",
                });
            }
            if r <= T::zero() {
                return Err(Error::InvalidConfig {
                    field: "region radius",
                    reason: "must be positive",
                });
            }
        }
        for i in 0..S {
            for j in 0..i {
                if (centres[i] - centres[j]).norm() < radii[i] + radii[j] {
                    return Err(Error::InvalidConfig {
                        field: "regions",
                        reason: "occlusion regions overlap; the region label would be ambiguous",
                    });
                }
            }
        }
        Ok(Self { centres, radii })
    }

    /// Label `h` of a point `u`: `i ∈ 1..=S` if `u ∈ R_i`, 0 outside every region.
    #[must_use]
    pub fn label(&self, u: &SVector<T, NE>) -> usize {
        for i in 0..S {
            if (u - self.centres[i]).norm_squared() <= self.radii[i] * self.radii[i] {
                return i + 1;
            }
        }
        0
    }

    /// `true` iff the packet is dropped (`u` inside some region).
    #[inline]
    #[must_use]
    pub fn drops(&self, u: &SVector<T, NE>) -> bool {
        self.label(u) != 0
    }

    /// Centre `ζ_i` of region `i` (0-based index).
    #[inline]
    pub fn centre(&self, i: usize) -> &SVector<T, NE> {
        &self.centres[i]
    }

    /// Radius `r_i` of region `i` (0-based index).
    #[inline]
    pub fn radius(&self, i: usize) -> T {
        self.radii[i]
    }

    /// Lebesgue measure `|R_i|` of region `i` (0-based): `2r`, `πr²`, `4πr³/3`, ….
    #[must_use]
    pub fn volume(&self, i: usize) -> T {
        unit_ball_volume::<T>(NE) * self.radii[i].powi(NE as i32)
    }
}

impl<T: Real, const S: usize> OcclusionRegions<T, 1, S> {
    /// The regions as intervals `(lower, upper)`, sorted by lower end, with their 0-based
    /// region indices: the form the exact (interval-likelihood) filters need.
    #[must_use]
    pub fn sorted_intervals(&self) -> [(T, T, usize); S] {
        let mut out = [(T::zero(), T::zero(), 0usize); S];
        for (i, o) in out.iter_mut().enumerate() {
            let (c, r) = (self.centres[i][0], self.radii[i]);
            *o = (c - r, c + r, i);
        }
        // Insertion sort: S is small and this runs once, at construction.
        for i in 1..S {
            let mut j = i;
            while j > 0 && out[j].0 < out[j - 1].0 {
                out.swap(j, j - 1);
                j -= 1;
            }
        }
        out
    }
}

/// Volume of the unit ball in `d` dimensions, `V_d = V_{d−2} · 2π/d`.
fn unit_ball_volume<T: Real>(d: usize) -> T {
    let (mut v, mut k) = if d.is_multiple_of(2) {
        (1.0, 0)
    } else {
        (2.0, 1)
    };
    while k < d {
        k += 2;
        v *= 2.0 * core::f64::consts::PI / k as f64;
    }
    T::lit(v)
}

/// The full dropout mechanism: `u_k = E x_k + n_k`, `n_k ~ N(0, Ψ)`, and the regions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occlusion<T: Real, const NX: usize, const NE: usize, const S: usize> {
    /// Selection matrix `E` (eq. 3).
    pub e: SMatrix<T, NE, NX>,
    /// Covariance `Ψ` of the region-centre noise `n_k` (taken time-invariant).
    pub psi: SMatrix<T, NE, NE>,
    /// The regions `R_i`.
    pub regions: OcclusionRegions<T, NE, S>,
}

impl<T: Real, const NX: usize, const NE: usize, const S: usize> Occlusion<T, NX, NE, S> {
    /// Validates `E` finite and `Ψ` symmetric positive definite.
    pub fn new(
        e: SMatrix<T, NE, NX>,
        psi: SMatrix<T, NE, NE>,
        regions: OcclusionRegions<T, NE, S>,
    ) -> Result<Self> {
        check_finite(&e, "E")?;
        check_spd(&psi, "Psi")?;
        Ok(Self {
            e,
            psi: symmetrize(&psi),
            regions,
        })
    }

    /// `u = E x + n` for a given noise draw `n`.
    #[inline]
    #[must_use]
    pub fn u(&self, x: &SVector<T, NX>, n: &SVector<T, NE>) -> SVector<T, NE> {
        self.e * x + n
    }

    /// Label `h_k` of state `x` under noise draw `n` (0 = delivered).
    #[inline]
    #[must_use]
    pub fn label(&self, x: &SVector<T, NX>, n: &SVector<T, NE>) -> usize {
        self.regions.label(&self.u(x, n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{matrix, vector};

    fn paper() -> OcclusionRegions<f64, 1, 4> {
        OcclusionRegions::new(
            [vector![20.0], vector![40.0], vector![60.0], vector![80.0]],
            [5.0; 4],
        )
        .unwrap()
    }

    #[test]
    fn labels_on_the_papers_regions() {
        let r = paper();
        for (u, h) in [
            (14.99, 0),
            (15.0, 1),
            (25.0, 1),
            (25.01, 0),
            (40.0, 2),
            (63.0, 3),
            (84.9, 4),
            (-100.0, 0),
        ] {
            assert_eq!(r.label(&vector![u]), h, "u = {u}");
            assert_eq!(r.drops(&vector![u]), h != 0);
        }
        assert_eq!(r.volume(0), 10.0);
        let s = r.sorted_intervals();
        assert_eq!(s[0], (15.0, 25.0, 0));
        assert_eq!(s[3], (75.0, 85.0, 3));
    }

    #[test]
    fn validation() {
        assert!(
            OcclusionRegions::<f64, 1, 2>::new([vector![0.0], vector![9.0]], [5.0, 5.0]).is_err()
        );
        // Touching is allowed; the boundary point gets the lower index.
        let t =
            OcclusionRegions::<f64, 1, 2>::new([vector![0.0], vector![10.0]], [5.0, 5.0]).unwrap();
        assert_eq!(t.label(&vector![5.0]), 1);
        assert!(OcclusionRegions::<f64, 1, 1>::new([vector![0.0]], [0.0]).is_err());
        assert!(OcclusionRegions::<f64, 1, 1>::new([vector![f64::NAN]], [1.0]).is_err());
        assert!(OcclusionRegions::<f64, 1, 1>::new([vector![0.0]], [f64::INFINITY]).is_err());
        assert!(Occlusion::new(matrix![1.0, 0.0], matrix![-0.1], paper()).is_err());
    }

    #[test]
    fn balls_and_volumes() {
        let r =
            OcclusionRegions::<f64, 2, 2>::new([vector![0.0, 0.0], vector![3.0, 4.0]], [2.0, 3.0])
                .unwrap();
        assert_eq!(r.label(&vector![1.0, 1.0]), 1);
        assert_eq!(r.label(&vector![3.0, 6.5]), 2);
        assert_eq!(r.label(&vector![2.0, -2.0]), 0);
        assert!((r.volume(0) - core::f64::consts::PI * 4.0).abs() < 1e-12);
        let b = OcclusionRegions::<f64, 3, 1>::new([vector![0.0, 0.0, 0.0]], [2.0]).unwrap();
        assert!((b.volume(0) - 4.0 / 3.0 * core::f64::consts::PI * 8.0).abs() < 1e-12);
        let occ = Occlusion::new(matrix![1.0, 0.0, 0.0], matrix![0.1], paper()).unwrap();
        assert_eq!(occ.label(&vector![19.0, 7.0, 7.0], &vector![0.5]), 1);
    }
}
