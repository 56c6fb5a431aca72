//! Tobit censoring of a sensor's measurement (seed 004, eqs. 2-10).
//!
//! Each component `j` of `z = C x + v`, `v_j ~ N(0, R_j)`, is censored from below at the
//! threshold `τ_j` (eq. 2): `y_j = z_j` if `z_j > τ_j`, else `y_j = τ_j`. With
//! `ζ_j = (τ_j − (Cx)_j)/√R_j`:
//!
//! * eq. (5): `ϱ̄_j = P(z_j > τ_j) = Φ(−ζ_j)` — the probability that component `j` is *not*
//!   censored (the paper calls it the censoring probability; it is `P{ϱ_j = 1}` of eq. 4);
//! * eq. (6)/(9): `E{y_j | x} = ϱ̄_j ((Cx)_j + √R_j λ(ζ_j)) + (1 − ϱ̄_j) τ_j`, exact;
//! * eq. (7)/(10): `D{y_j | x} = R_j (1 − φ(ζ_j))`, with `φ(ζ) = λ(ζ)(λ(ζ) − ζ)`.
//!
//! Eq. (7) is the variance of the *truncated* Gaussian `z_j | z_j > τ_j`, not of the censored
//! `y_j` (which also carries the point mass at `τ_j`); [`paper_variance`] implements (7) as
//! written and [`censored_variance`] the exact `Var(y_j | x)` for callers that need it.
//!
//! λ and φ come from [`crate::gauss`], accurate in both tails, and `Φ(−ζ)` is evaluated as
//! `sf(ζ)` so that a far-censored component keeps its relative accuracy.

use nalgebra::SVector;

use crate::gauss::{cdf, inv_mills_delta, inv_mills_given_sf, sf};
use crate::linalg::check_finite;
use crate::{Error, Real, Result};

/// Censors a measurement (eqs. 2, 3, 8): returns `y` and the indicator `ϱ` (`true` where the
/// component was observed, `false` where it was replaced by the threshold).
pub fn censor<T: Real, const NY: usize>(
    z: &SVector<T, NY>,
    tau: &SVector<T, NY>,
) -> Result<(SVector<T, NY>, [bool; NY])> {
    check_finite(z, "measurement")?;
    check_finite(tau, "censoring threshold")?;
    let mut y = *z;
    let mut observed = [true; NY];
    for j in 0..NY {
        if z[j] <= tau[j] {
            y[j] = tau[j];
            observed[j] = false;
        }
    }
    Ok((y, observed))
}

/// `ζ = (τ − μ)/√R`, the standardised threshold of one component.
#[inline]
#[must_use]
pub fn standardized_threshold<T: Real>(mu: T, tau: T, r: T) -> T {
    (tau - mu) / r.sqrt()
}

/// Eq. (5): `P(z > τ) = Φ((μ − τ)/√R)` for `z ~ N(μ, R)`.
#[inline]
#[must_use]
pub fn prob_uncensored<T: Real>(mu: T, tau: T, r: T) -> T {
    sf(standardized_threshold(mu, tau, r))
}

/// Eq. (6): `E{y | x}` of the censored measurement, with `μ = (Cx)_j`.
#[must_use]
pub fn censored_mean<T: Real>(mu: T, tau: T, r: T) -> T {
    let z = standardized_threshold(mu, tau, r);
    let p = sf(z);
    p * (mu + r.sqrt() * inv_mills_given_sf(z, p)) + cdf(z) * tau
}

/// Eq. (7) as written: `R (1 − φ(ζ))`, which is `Var(z | z > τ)` (the truncated Gaussian).
#[must_use]
pub fn paper_variance<T: Real>(mu: T, tau: T, r: T) -> T {
    r * (T::one() - inv_mills_delta(standardized_threshold(mu, tau, r)))
}

/// The exact `Var(y | x)` of the censored measurement: a point mass at `τ` with probability
/// `1 − p` and the truncated Gaussian (mean `m`, variance `v`) with probability `p`, so
/// `Var = p v + p (1 − p)(m − τ)²` (law of total variance; no cancellation).
#[must_use]
pub fn censored_variance<T: Real>(mu: T, tau: T, r: T) -> T {
    let z = standardized_threshold(mu, tau, r);
    let s = r.sqrt();
    let p = sf(z);
    let v = r * (T::one() - inv_mills_delta(z));
    // m − τ = μ − τ + s λ(ζ) = s (λ(ζ) − ζ).
    let gap = s * (inv_mills_given_sf(z, p) - z);
    p * v + p * cdf(z) * gap * gap
}

/// The per-component Tobit statistics of a predicted measurement, as the filter uses them
/// (eqs. 5, 9, 23 and the Υ of eq. 30).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitStats<T: Real, const NY: usize> {
    /// `ζ_j = (τ_j − μ_j)/√R_j`.
    pub zeta: SVector<T, NY>,
    /// `ϱ̄_j = Φ(−ζ_j)` (eq. 5), the diagonal of `Q̄`.
    pub rho: SVector<T, NY>,
    /// `ϱ̄_j (1 − ϱ̄_j)`, the diagonal of `Υ` (eq. 30), computed as `Φ(−ζ)Φ(ζ)`.
    pub upsilon: SVector<T, NY>,
    /// `λ(ζ_j)`.
    pub lambda: SVector<T, NY>,
    /// `√R_j`.
    pub sqrt_r: SVector<T, NY>,
    /// Eq. (9)/(23): `E{y | x}` at the given mean, `Q̄(μ + λ∘√R) + (I − Q̄)τ`.
    pub mean: SVector<T, NY>,
}

impl<T: Real, const NY: usize> TobitStats<T, NY> {
    /// Statistics of `y` when `z ~ N(μ, diag(R))`, thresholds `τ`. `r` holds the variances
    /// `R_j`, which must be finite and positive.
    pub fn new(mu: &SVector<T, NY>, tau: &SVector<T, NY>, r: &SVector<T, NY>) -> Result<Self> {
        check_finite(mu, "predicted measurement")?;
        check_finite(tau, "censoring threshold")?;
        check_finite(r, "measurement variance")?;
        if r.iter().any(|&v| v <= T::zero()) {
            return Err(Error::NotPositiveDefinite {
                what: "measurement variance",
            });
        }
        let mut out = Self {
            zeta: SVector::zeros(),
            rho: SVector::zeros(),
            upsilon: SVector::zeros(),
            lambda: SVector::zeros(),
            sqrt_r: r.map(|v| v.sqrt()),
            mean: SVector::zeros(),
        };
        for j in 0..NY {
            let z = standardized_threshold(mu[j], tau[j], r[j]);
            let p = sf(z);
            let l = inv_mills_given_sf(z, p);
            out.zeta[j] = z;
            out.rho[j] = p;
            out.upsilon[j] = p * cdf(z);
            out.lambda[j] = l;
            out.mean[j] = p * (mu[j] + out.sqrt_r[j] * l) + (T::one() - p) * tau[j];
        }
        check_finite(&out.mean, "Tobit measurement estimate")?;
        check_finite(&out.lambda, "inverse Mills ratio")?;
        Ok(out)
    }

    /// Eq. (10) componentwise: `R_j (1 − φ(ζ_j))`.
    #[must_use]
    pub fn paper_variance(&self) -> SVector<T, NY> {
        SVector::from_fn(|j, _| {
            self.sqrt_r[j] * self.sqrt_r[j] * (T::one() - inv_mills_delta(self.zeta[j]))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gauss::inv_mills;
    use nalgebra::vector;

    /// Composite Simpson rule on [a, b] with `n` (even) intervals — independent of `erfc`.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            let x = a + i as f64 * h;
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(x);
        }
        s * h / 3.0
    }

    /// Moments of the standard normal truncated to (ζ, ∞), by quadrature of
    /// w(s) = exp(−ζ s − s²/2) = φ(ζ + s)/φ(ζ) on s ∈ [0, |ζ| + 20]:
    /// returns (λ(ζ), Var(Z | Z > ζ)).
    fn truncated_moments(zeta: f64) -> (f64, f64) {
        let w = |s: f64| (-zeta * s - 0.5 * s * s).exp();
        let upper = zeta.abs() + 20.0;
        let n = 400_000;
        let m0 = simpson(w, 0.0, upper, n);
        let m1 = simpson(|s| s * w(s), 0.0, upper, n);
        let m2 = simpson(|s| s * s * w(s), 0.0, upper, n);
        let mean = m1 / m0; // E[Z − ζ | Z > ζ]
        (1.0 / m0, m2 / m0 - mean * mean)
    }

    #[test]
    fn lambda_and_phi_match_quadrature_in_both_tails() {
        // Simpson with h ≤ 1e-4 on a smooth integrand: error far below 1e-11 relative; λ from
        // gauss is documented to 1e-13. Tolerance 1e-9 relative for λ; φ = 1 − Var loses
        // absolute accuracy only (≈1e-12), so 1e-10 absolute + 1e-8 relative.
        for &z in &[-6.0, -3.0, -1.0, 0.0, 0.7, 2.5, 4.0, 4.5, 8.0, 12.0] {
            let (lam, var) = truncated_moments(z);
            let got = inv_mills(z);
            assert!((got - lam).abs() <= 1e-9 * lam, "λ({z}) {got} vs {lam}");
            let delta = 1.0 - var;
            let got_d = inv_mills_delta(z);
            assert!(
                (got_d - delta).abs() <= 1e-10 + 1e-8 * delta,
                "φ({z}) {got_d} vs {delta}"
            );
        }
    }

    /// E{y}, Var(y) and Var(z | z > τ) of the censored N(μ, R) by direct quadrature over z.
    fn censored_by_quadrature(mu: f64, tau: f64, r: f64) -> (f64, f64, f64) {
        let s = r.sqrt();
        let dens = |z: f64| {
            (-(z - mu) * (z - mu) / (2.0 * r)).exp() / (s * (2.0 * core::f64::consts::PI).sqrt())
        };
        let hi = mu.max(tau) + 30.0 * s;
        let lo = mu.min(tau) - 30.0 * s;
        let n = 600_000;
        let p_up = simpson(dens, tau, hi, n);
        let p_down = simpson(dens, lo, tau, n);
        let m1 = simpson(|z| z * dens(z), tau, hi, n);
        let m2 = simpson(|z| z * z * dens(z), tau, hi, n);
        let ey = m1 + tau * p_down;
        let ey2 = m2 + tau * tau * p_down;
        let tmean = m1 / p_up;
        (ey, ey2 - ey * ey, m2 / p_up - tmean * tmean)
    }

    #[test]
    fn censored_statistics_match_quadrature() {
        // Quadrature error ≈ 1e-12 (h ≈ 1e-4 s); tolerances 1e-8 absolute.
        for &(mu, tau, r) in &[
            (0.0, 0.0, 0.5),
            (1.3, 0.0, 0.5),
            (-2.0, 0.0, 0.5),
            (5.0, 0.0, 0.5),
            (0.4, 1.0, 2.0),
            (-1.0, -0.5, 0.1),
        ] {
            let (ey, vy, vt) = censored_by_quadrature(mu, tau, r);
            let m = censored_mean(mu, tau, r);
            assert!((m - ey).abs() < 1e-8, "E{{y}} μ={mu} τ={tau}: {m} vs {ey}");
            let v = censored_variance(mu, tau, r);
            assert!((v - vy).abs() < 1e-8, "Var(y) μ={mu}: {v} vs {vy}");
            let pv = paper_variance(mu, tau, r);
            assert!((pv - vt).abs() < 1e-8, "eq.(7) μ={mu}: {pv} vs {vt}");
            let p = prob_uncensored(mu, tau, r);
            let p_q = 1.0 - 0.5 * libm::erfc((mu - tau) / (2.0 * r).sqrt());
            assert!((p - p_q).abs() < 1e-14);
        }
        // (7) is not the censored variance: at μ = τ they differ visibly.
        assert!((paper_variance(0.0f64, 0.0, 0.5) - censored_variance(0.0, 0.0, 0.5)).abs() > 0.01);
    }

    #[test]
    fn stats_vector_agrees_with_scalar_functions_f32_and_f64() {
        let mu = vector![1.5f64, -0.3];
        let tau = vector![0.0f64, 0.0];
        let r = vector![0.5f64, 0.5];
        let st = TobitStats::new(&mu, &tau, &r).unwrap();
        for j in 0..2 {
            assert!((st.mean[j] - censored_mean(mu[j], tau[j], r[j])).abs() < 1e-15);
            assert!((st.rho[j] - prob_uncensored(mu[j], tau[j], r[j])).abs() < 1e-15);
            assert!((st.upsilon[j] - st.rho[j] * (1.0 - st.rho[j])).abs() < 1e-15);
            assert!((st.paper_variance()[j] - paper_variance(mu[j], tau[j], r[j])).abs() < 1e-15);
        }
        let st32 = TobitStats::<f32, 2>::new(&mu.cast(), &tau.cast(), &r.cast()).unwrap();
        for j in 0..2 {
            assert!((st32.mean[j] as f64 - st.mean[j]).abs() < 1e-5);
        }
    }

    #[test]
    fn censor_and_bad_inputs() {
        let (y, obs) = censor(&vector![0.3, -0.2], &vector![0.0, 0.0]).unwrap();
        assert_eq!(y, vector![0.3, 0.0]);
        assert_eq!(obs, [true, false]);
        // Equality is censored (eq. 2 uses ≤).
        assert_eq!(censor(&vector![0.0], &vector![0.0]).unwrap().1, [false]);
        assert_eq!(
            censor(&vector![f64::NAN], &vector![0.0]),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(
            TobitStats::new(&vector![0.0], &vector![0.0], &vector![0.0]),
            Err(Error::NotPositiveDefinite {
                what: "measurement variance"
            })
        );
    }
}
