//! The silence set in the forms the updates need (docs/tobit-fusion.md, eqs. S1-S3; S3' here).
//!
//! ```text
//! ball (14):            ‖y − ȳ‖ < r̄                                                 (S1)
//! box in z, censored:   ℓ_j = −∞ if ȳ_j − r̄ < τ_j, else ȳ_j − r̄;   u_j = ȳ_j + r̄      (S2)
//! uniform (Sijs–Lazar): mean ȳ, covariance r̄²/(n_y + 2) I on the ball                 (S3)
//! an axis whose ball reaches τ_j (ȳ_j − r̄ < τ_j), with w = u_j − τ_j, z_j ~ N(μ_j, R_j):
//!   y_j ~ π δ(τ_j) + (1 − π) U(τ_j, u_j),   π = Φ((τ_j − μ_j)/√R_j) / Φ((u_j − μ_j)/√R_j)
//!   mean τ_j + (1 − π) w/2,   variance (1 − π)(1 + 3π) w²/12                          (S3')
//! ```
//!
//! (S2): `y_j = max(z_j, τ_j)`, so `y_j ∈ (ȳ_j − r̄, ȳ_j + r̄)` is `z_j` in the same interval
//! when it lies above τ_j, and `z_j < ȳ_j + r̄` when it reaches τ_j. The box contains the
//! ball: an outer set, so the update uses less than the set says, never more.
//!
//! (S3): the covariance of the uniform distribution on an n-ball of radius r is
//! `r²/(n + 2) I`. Where the ball crosses a censoring threshold the set is the ball cut by
//! `y_j ≥ τ_j`, which has no closed-form moments; the axis is then modelled on its own, off
//! the diagonal 0 — an approximation, like the uniform model itself.
//!
//! (S3'): on such an axis the censored `y_j` is not spread over `[τ_j, u_j)`: every
//! `z_j ≤ τ_j` reads exactly `τ_j`, inside the set, so `y_j` has an atom there. A uniform
//! model without it puts the mean near the middle of the interval when the node reads τ_j
//! most of the time (a censored reference), a bias of about r̄/2. The atom's weight is the
//! one thing the set cannot give: it is `P(z_j ≤ τ_j | z_j < u_j)` under the prior of the
//! uncensored measurement ([`CensoredPrior`]); the continuous part stays uniform, as
//! Sijs–Lazar take it. The moments: `E y = π τ + (1 − π)(τ + w/2)`, and with `d = y − τ`,
//! `E d² = (1 − π) w²/3`, so `Var y = (1 − π) w²/3 − (1 − π)² w²/4 = (1 − π)(1 + 3π) w²/12`
//! (`w²/12` at π = 0, the uniform; 0 at π = 1, the atom alone). The same holds whether or
//! not the reference ȳ_j is itself censored: the atom is in the set as soon as the ball
//! reaches τ_j, and the prior decides how much of the set it is. π is a ratio of two normal
//! cdfs, taken in the log domain ([`crate::gauss::ln_cdf`]) so that both far in the lower
//! tail (μ_j far above the set) give a small π instead of `0/0`.

use nalgebra::SVector;

use crate::gauss::ln_cdf;
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

/// The censoring of the node's measurement and the prior of its uncensored `z = C x + v`
/// that (S3') weighs the atom at τ with: `z_j ~ N(mean_j, var_j)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CensoredPrior<T: Real, const NY: usize> {
    /// τ, the censoring thresholds.
    pub tau: SVector<T, NY>,
    /// The prior mean of z.
    pub mean: SVector<T, NY>,
    /// The prior variances of z.
    pub var: SVector<T, NY>,
}

impl<T: Real, const NY: usize> CensoredPrior<T, NY> {
    /// (S3'): the probability of the atom at `τ_j` given that `y_j` lies in `[τ_j, upper)`,
    /// `Φ(a)/Φ(b)` with `a = (τ_j − μ_j)/√var_j`, `b = (upper − μ_j)/√var_j`; 1 when the set
    /// holds the atom alone (`upper ≤ τ_j`).
    #[must_use]
    pub fn atom_weight(&self, j: usize, upper: T) -> T {
        let s = self.var[j].sqrt();
        let a = (self.tau[j] - self.mean[j]) / s;
        let b = (upper - self.mean[j]) / s;
        (ln_cdf(a) - ln_cdf(b)).exp().clamp(T::zero(), T::one())
    }
}

/// (S3), (S3'): the mean and per-axis variance of the Sijs–Lazar uniform model of the set,
/// with the atom at τ on every axis whose ball reaches the censoring threshold (no
/// censoring: `None`, the ball's moments alone).
#[must_use]
pub fn uniform_moments<T: Real, const NY: usize>(
    ball: &SilenceBall<T, NY>,
    censoring: Option<&CensoredPrior<T, NY>>,
) -> (SVector<T, NY>, SVector<T, NY>) {
    let r = ball.radius;
    let ball_var = r * r / T::lit(NY as f64 + 2.0);
    let mut mean = ball.centre;
    let mut var = SVector::repeat(ball_var);
    if let Some(c) = censoring {
        let t = &c.tau;
        for j in 0..NY {
            if ball.centre[j] - r < t[j] {
                let hi = ball.centre[j] + r;
                let w = (hi - t[j]).max(T::zero());
                let pi = c.atom_weight(j, hi);
                let q = T::one() - pi;
                mean[j] = t[j] + q * w * T::lit(0.5);
                var[j] = q * (T::one() + T::lit(3.0) * pi) * w * w / T::lit(12.0);
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
        // A prior far above the set: no atom, the uniform on [τ, ȳ + r̄] (π ≈ 1e-13 here).
        let far = prior(vector![0.0, 0.0], vector![50.0, 50.0], vector![1.0, 1.0]);
        let (m, v) = uniform_moments(&ball, Some(&far));
        assert!((m[1] - 0.3).abs() < 1e-12 && (v[1] - 0.36 / 12.0).abs() < 1e-12);
        assert_eq!((m[0], v[0]), (1.0, 0.25 / 4.0));
        // A prior far below τ: the atom alone.
        let below = prior(vector![0.0, 0.0], vector![-50.0, -50.0], vector![1.0, 1.0]);
        let (m, v) = uniform_moments(&ball, Some(&below));
        assert_eq!((m[1], v[1]), (0.0, 0.0));
        assert_eq!((m[0], v[0]), (1.0, 0.25 / 4.0));
    }

    fn prior(
        tau: SVector<f64, 2>,
        mean: SVector<f64, 2>,
        var: SVector<f64, 2>,
    ) -> CensoredPrior<f64, 2> {
        CensoredPrior { tau, mean, var }
    }

    /// Composite Simpson rule on [a, b] with `n` (even) intervals.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(a + i as f64 * h);
        }
        s * h / 3.0
    }

    /// (τ, ȳ, r̄, μ, R): censored references with the prior below, at and above τ, a reference
    /// above τ whose ball reaches it, and one of the far tail, where Φ(a)/Φ(b) is 0/0 in f64.
    const CASES: [(f64, f64, f64, f64, f64); 7] = [
        (0.0, 0.0, 0.3, -0.5, 0.5),
        (0.0, 0.0, 0.3, 0.0, 0.5),
        (0.0, 0.0, 0.3, 0.8, 0.5),
        (0.0, 0.0, 0.12, 0.3, 0.01),
        (-1.0, -0.8, 0.4, -0.2, 0.09),
        (0.5, 0.6, 0.2, 0.9, 0.04),
        (0.0, 0.0, 0.1, 4.0, 0.0025),
    ];

    #[test]
    fn the_atom_weight_matches_quadrature_and_survives_the_tail() {
        // Φ(a)/Φ(b) by Simpson over the normal density from 14 s.d. below the mean (where
        // the density's mass is below 1e-44 relative), independent of erfc: 1e-9 relative.
        // The tail case (a ≈ −80) has a reference from the asymptote
        // Φ(a)/Φ(b) ≈ exp((b² − a²)/2)·(b/a)·(1 − 1/a² + …)/(1 − 1/b² + …), 1e-6 relative.
        for &(tau, centre, r, mu, var) in &CASES[..6] {
            let s: f64 = var.sqrt();
            let dens = |z: f64| (-(z - mu) * (z - mu) / (2.0 * var)).exp();
            let lo = mu - 14.0 * s;
            let upper = centre + r;
            let want = simpson(dens, lo, tau, 200_000) / simpson(dens, lo, upper, 200_000);
            let p = prior(vector![tau, tau], vector![mu, mu], vector![var, var]);
            let got = p.atom_weight(0, upper);
            assert!(
                (got - want).abs() <= 1e-9 * want,
                "{got} vs {want} at μ = {mu}"
            );
        }
        let (tau, centre, r, mu, var) = CASES[6];
        let s: f64 = var.sqrt();
        let (a, b) = ((tau - mu) / s, (centre + r - mu) / s);
        let series = |x: f64| 1.0 - 1.0 / (x * x) + 3.0 / x.powi(4) - 15.0 / x.powi(6);
        let want = ((b * b - a * a) / 2.0).exp() * (b / a) * series(a) / series(b);
        let got =
            prior(vector![tau, tau], vector![mu, mu], vector![var, var]).atom_weight(0, centre + r);
        assert!(
            want > 0.0 && (got - want).abs() <= 1e-6 * want,
            "{got} vs {want}"
        );
        // f32 from a ≈ −14 on (where Φ underflows in f32): finite, and the f64 value to 1e-3.
        for mu in [0.7_f64, 1.0, 1.5] {
            let p32 = CensoredPrior::<f32, 1> {
                tau: vector![0.0],
                mean: vector![mu as f32],
                var: vector![0.0025],
            };
            let p64 = CensoredPrior::<f64, 1> {
                tau: vector![0.0],
                mean: vector![mu],
                var: vector![0.0025],
            };
            let (g32, g64) = (p32.atom_weight(0, 0.1), p64.atom_weight(0, 0.1));
            assert!(
                g64 > 0.0 && ((f64::from(g32) - g64) / g64).abs() < 1e-3,
                "{g32} vs {g64}"
            );
        }
    }

    #[test]
    fn the_censored_axis_moments_match_a_monte_carlo_of_the_model() {
        // The model of (S3') simulated: z ~ N(μ, R) given z < u (the silence on this axis),
        // then y = τ if z ≤ τ (the atom, with its prior probability), else y uniform on
        // (τ, u) (Sijs–Lazar's continuous part). Neither π nor the closed forms enter. The
        // sample mean and variance must agree within 5 of their standard errors (10⁶ draws;
        // fixed seed, so the check is deterministic).
        let mut state = 0x5EED_u64;
        let mut u01 = move || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        for &(tau, centre, r, mu, var) in &CASES[..6] {
            let upper = centre + r;
            let n = 1_000_000;
            // Power sums of d = y − τ (bounded by the set's width: no cancellation to fear).
            let mut p = [0.0_f64; 5];
            let mut k = 0;
            while k < n {
                let (a, b) = (u01().max(1e-300), u01());
                let z =
                    mu + var.sqrt() * (-2.0 * a.ln()).sqrt() * (core::f64::consts::TAU * b).cos();
                if z >= upper {
                    continue;
                }
                let d = if z <= tau { 0.0 } else { (upper - tau) * u01() };
                let mut dk = 1.0;
                for pk in &mut p {
                    *pk += dk;
                    dk *= d;
                }
                k += 1;
            }
            let e = |i: usize| p[i] / n as f64;
            let md = e(1);
            let v = e(2) - md * md;
            let m4 = e(4) - 4.0 * md * e(3) + 6.0 * md * md * e(2) - 3.0 * md.powi(4);
            let m = tau + md;
            let (se_m, se_v) = ((v / n as f64).sqrt(), ((m4 - v * v) / n as f64).sqrt());
            let ball = SilenceBall {
                centre: vector![centre, centre],
                radius: r,
            };
            let p = prior(vector![tau, tau], vector![mu, mu], vector![var, var]);
            let (gm, gv) = uniform_moments(&ball, Some(&p));
            assert!(
                (gm[0] - m).abs() < 5.0 * se_m,
                "mean {} vs {m} ± {se_m}",
                gm[0]
            );
            assert!(
                (gv[0] - v).abs() < 5.0 * se_v,
                "var {} vs {v} ± {se_v}",
                gv[0]
            );
        }
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
