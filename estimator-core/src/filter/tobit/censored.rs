//! The moment-matched update with censored measurements (docs/tobit-fusion.md, "At the
//! information bound", eqs. C1-C4): the kernel of [`super::MomentMatchedTobit`].
//!
//! Each component of a node's measurement is a scalar `z = c x + v`, `v ~ N(0, r)` independent
//! of the others (seed 004's R is diagonal), censored from below at τ (eq. 2). With the prior
//! `x ~ N(x̂, P)`, `μ = c x̂`, `s = c P cᵀ + r`, `g = P cᵀ`:
//!
//! ```text
//! observed, y > τ:   x̂ ← x̂ + g (y − μ)/s,            P ← P − g gᵀ/s                    (C1)
//! censored, y = τ:   b = (τ − μ)/√s, (m, v) = mean, variance of N(0,1) below b          (C2)
//!                    x̂ ← x̂ + g m/√s,                  P ← P − (1 − v) g gᵀ/s            (C3)
//! ```
//!
//! (C1) is the Kalman update with one component. (C2)-(C3) are the exact first two moments of
//! `x` given `z ≤ τ`: `(x, z)` is jointly Gaussian, `x | z` has a mean linear in `z` and a
//! constant covariance, so conditioning on the half-line needs only the truncated moments of
//! `z` — the prediction covariance enters through `s`, where the paper's filter (5) and the
//! Tobit Kalman filter use the noise-only censoring probability.
//!
//! **Order (C4).** An instant applies every observed component of every node first (exact:
//! the observed components are jointly Gaussian with x, so their sequence is the joint Kalman
//! update in any order), then the censored ones. A single censored component is then exact;
//! several are the assumed-density sequence (each truncates the moment-matched Gaussian of the
//! previous ones, Simon & Simon 2010), whose error against a 2-D quadrature is measured in the
//! tests below and in docs/tobit-fusion.md.

use nalgebra::{SMatrix, SVector};

use crate::filter::occlusion::truncnorm::truncated_std_normal;
use crate::{Error, Real, Result};

/// The information one scalar component carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Component<T: Real> {
    /// Observed above the threshold: `z = y` (C1).
    Observed(T),
    /// Censored: `z ≤ τ` (C2)-(C3).
    AtMost(T),
}

/// One component's update of `(x̂, P)` in place: `c` is the component's row of C, `r` its noise
/// variance. Returns the squared normalised innovation `(y − μ)²/s` of an observed component
/// (0 for a censored one), so that a caller can gate the observed part of a measurement. An
/// error (a non-positive `s`, a half-line of zero probability, a non-finite result) leaves
/// `(x̂, P)` unchanged.
pub fn condition<T: Real, const NX: usize>(
    x: &mut SVector<T, NX>,
    p: &mut SMatrix<T, NX, NX>,
    c: &SVector<T, NX>,
    r: T,
    info: Component<T>,
) -> Result<T> {
    let g = *p * c;
    let s = c.dot(&g) + r;
    if !s.finite() || s <= T::zero() {
        return Err(Error::NotPositiveDefinite {
            what: "censored innovation variance",
        });
    }
    let mu = c.dot(x);
    let (shift, shrink, nis) = match info {
        Component::Observed(y) => {
            let d = y - mu;
            (d / s, T::one() / s, d * d / s)
        }
        Component::AtMost(tau) => {
            let sd = s.sqrt();
            let minus_inf = -T::one() / T::zero();
            let (ln_z, m, v) = truncated_std_normal(minus_inf, (tau - mu) / sd);
            if !ln_z.finite() {
                return Err(Error::InvalidConfig {
                    field: "censored measurement",
                    reason: "has zero probability under the prior",
                });
            }
            (m / sd, (T::one() - v) / s, T::zero())
        }
    };
    let nx = *x + g * shift;
    let np = *p - g * g.transpose() * shrink;
    if !nx.iter().chain(np.iter()).all(|v| v.finite()) || !nis.finite() {
        return Err(Error::NonFinite {
            what: "censored update",
        });
    }
    *x = nx;
    *p = np;
    Ok(nis)
}

/// What one node delivered, component by component: `y_j > τ_j` is observed, `y_j ≤ τ_j`
/// censored at τ_j (eq. 2 gives `y_j = τ_j` exactly; a value below is read as censored too).
#[inline]
pub fn component<T: Real>(y: T, tau: T) -> Component<T> {
    if y > tau {
        Component::Observed(y)
    } else {
        Component::AtMost(tau)
    }
}

/// (C1) for every observed component of `y` (`c`, `r`: the node's C and variances), in place.
/// Returns the summed squared normalised innovations and how many components were observed:
/// the NIS of the observed subvector and its degrees of freedom (the sequential scalar
/// innovations of a jointly Gaussian vector are independent, so their squares add up to the
/// joint NIS).
pub fn observe<T: Real, const NX: usize, const NY: usize>(
    x: &mut SVector<T, NX>,
    p: &mut SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SVector<T, NY>,
    y: &SVector<T, NY>,
    tau: &SVector<T, NY>,
) -> Result<(T, usize)> {
    let (mut nis, mut dof) = (T::zero(), 0);
    for j in 0..NY {
        if let info @ Component::Observed(_) = component(y[j], tau[j]) {
            nis += condition(x, p, &c.row(j).transpose(), r[j], info)?;
            dof += 1;
        }
    }
    Ok((nis, dof))
}

/// (C2)-(C3) for every censored component of `y`, in place.
pub fn truncate_censored<T: Real, const NX: usize, const NY: usize>(
    x: &mut SVector<T, NX>,
    p: &mut SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SVector<T, NY>,
    y: &SVector<T, NY>,
    tau: &SVector<T, NY>,
) -> Result<()> {
    for j in 0..NY {
        if let info @ Component::AtMost(_) = component(y[j], tau[j]) {
            condition(x, p, &c.row(j).transpose(), r[j], info)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
