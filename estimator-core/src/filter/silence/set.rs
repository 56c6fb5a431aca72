//! The silence set in the forms the updates need (docs/tobit-fusion.md, eqs. S1-S3).
//!
//! ```text
//! ball (14):            ‖y − ȳ‖ < r̄                                                 (S1)
//! box in z, censored:   ℓ_j = −∞ if ȳ_j − r̄ ≤ τ_j, else ȳ_j − r̄;   u_j = ȳ_j + r̄      (S2)
//! uniform (Sijs–Lazar): mean ȳ, covariance r̄²/(n_y + 2) I on the ball; an axis the
//!                       censoring clips: uniform on [τ_j, ȳ_j + r̄]                   (S3)
//! ```
//!
//! (S2): `y_j = max(z_j, τ_j)`, so `y_j ∈ (ȳ_j − r̄, ȳ_j + r̄)` is `z_j` in the same interval
//! when it lies above τ_j, and `z_j < ȳ_j + r̄` when it reaches τ_j. The box contains the
//! ball: an outer set, so the update uses less than the set says, never more.
//!
//! (S3): the covariance of the uniform distribution on an n-ball of radius r is
//! `r²/(n + 2) I`. Where the ball crosses a censoring threshold the set is the ball cut by
//! `y_j ≥ τ_j`, which has no closed-form moments; the axis is then taken as uniform on its
//! extent `[τ_j, ȳ_j + r̄]` (mean at its middle, variance width²/12), off-diagonal 0 — an
//! approximation, like the uniform model itself.

use nalgebra::SVector;

use crate::protocol::trigger_knowledge::SilenceBall;
use crate::Real;

/// Per-axis bounds `(ℓ_j, u_j)` on the uncensored measurement z (`ℓ_j` may be −∞).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SilenceBox<T: Real, const NY: usize> {
    /// ℓ.
    pub lower: SVector<T, NY>,
    /// u.
    pub upper: SVector<T, NY>,
}

impl<T: Real, const NY: usize> SilenceBox<T, NY> {
    /// (S2): the ball's box, open below on the axes whose ball reaches the censoring threshold
    /// `tau` (no censoring: `None`).
    #[must_use]
    pub fn of_ball(ball: &SilenceBall<T, NY>, tau: Option<&SVector<T, NY>>) -> Self {
        let r = ball.radius;
        let minus_inf = -T::one() / T::zero();
        let lower = SVector::from_fn(|j, _| {
            let lo = ball.centre[j] - r;
            match tau {
                Some(t) if lo < t[j] => minus_inf,
                _ => lo,
            }
        });
        Self {
            lower,
            upper: ball.centre.add_scalar(r),
        }
    }
}

/// (S3): the mean and per-axis variance of the Sijs–Lazar uniform model of the set.
#[must_use]
pub fn uniform_moments<T: Real, const NY: usize>(
    ball: &SilenceBall<T, NY>,
    tau: Option<&SVector<T, NY>>,
) -> (SVector<T, NY>, SVector<T, NY>) {
    let r = ball.radius;
    let ball_var = r * r / T::lit(NY as f64 + 2.0);
    let mut mean = ball.centre;
    let mut var = SVector::repeat(ball_var);
    if let Some(t) = tau {
        for j in 0..NY {
            if ball.centre[j] - r < t[j] {
                let hi = ball.centre[j] + r;
                let w = hi - t[j];
                mean[j] = (hi + t[j]) * T::lit(0.5);
                var[j] = w * w / T::lit(12.0);
            }
        }
    }
    (mean, var)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::vector;

    #[test]
    fn box_and_uniform_moments() {
        let ball = SilenceBall {
            centre: vector![1.0, 0.1],
            radius: 0.5,
        };
        let b = SilenceBox::of_ball(&ball, None);
        assert_eq!((b.lower, b.upper), (vector![0.5, -0.4], vector![1.5, 0.6]));
        // τ = 0: axis 1's ball reaches below τ, so z_1 is open below.
        let b = SilenceBox::of_ball(&ball, Some(&vector![0.0, 0.0]));
        assert_eq!(b.lower[0], 0.5);
        assert!(b.lower[1] == f64::NEG_INFINITY && b.upper[1] == 0.6);
        let (m, v) = uniform_moments(&ball, None);
        assert_eq!(m, ball.centre);
        assert!((v[0] - 0.25 / 4.0).abs() < 1e-16 && v[0] == v[1]);
        let (m, v) = uniform_moments(&ball, Some(&vector![0.0, 0.0]));
        assert!((m[1] - 0.3).abs() < 1e-15 && (v[1] - 0.36 / 12.0).abs() < 1e-15);
        assert_eq!(m[0], 1.0);
    }

    #[test]
    fn uniform_ball_covariance_matches_a_grid() {
        // r²/(n+2) for n = 2 by a midpoint grid over the unit disc: 1/4 to 1e-4 (the grid's
        // boundary error at 2000² cells).
        let n = 2000;
        let (mut s, mut c) = (0.0, 0.0);
        for i in 0..n {
            for j in 0..n {
                let x = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let y = -1.0 + (j as f64 + 0.5) * 2.0 / n as f64;
                if x * x + y * y < 1.0 {
                    s += x * x;
                    c += 1.0;
                }
            }
        }
        let ball = SilenceBall {
            centre: vector![0.0, 0.0],
            radius: 1.0,
        };
        assert!((s / c - uniform_moments(&ball, None).1[0]).abs() < 1e-4);
    }
}
