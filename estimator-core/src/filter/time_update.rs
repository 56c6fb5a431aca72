//! The time update of every linear-Gaussian estimator here (KF, IKF, CCE, ADF, KF-IO):
//! `x⁻ = A_{k−1} x̂_{k−1}`, `P⁻ = A_{k−1} P_{k−1} A_{k−1}ᵀ + B Q Bᵀ` (seed 001 eq. 11), plus
//! the known input term `G u_{k−1}` in `x⁻` for a system with one
//! ([`LinearSystem::input`]; a known input shifts the mean and leaves `P⁻` unchanged).

use nalgebra::{SMatrix, SVector};

use crate::linalg::all_finite;
use crate::linalg::small;
use crate::model::LinearSystem;
use crate::{Error, Real, Result};

/// `(A x, A P Aᵀ + Q)`, unchecked. `P⁻` is exactly symmetric (upper triangle computed and
/// mirrored; `Q`'s upper triangle is read).
#[inline]
pub fn predict_raw<T: Real, const NX: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    a: &SMatrix<T, NX, NX>,
    q: &SMatrix<T, NX, NX>,
) -> (SVector<T, NX>, SMatrix<T, NX, NX>) {
    #[cfg(simd_lanes)]
    if let Some(out) = crate::linalg::lanes::predict(x, p, a, q) {
        return out; // the same bits as below, several entries at a time
    }
    (small::mul_vec(a, x), small::congruence_add(a, p, q))
}

/// The prediction to instant `k` from the model's `A_{k−1}`, `B Q Bᵀ` and input term of
/// `k − 1`, refused when not finite ("predicted state" / "predicted covariance"). Always
/// inlined: it is the first half of every step, and as a call it returns `(x⁻, P⁻)` through
/// memory.
#[inline(always)]
pub fn predict<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>>(
    model: &M,
    k: usize,
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>)> {
    let km1 = k.saturating_sub(1);
    let (mut xp, pp) = predict_raw(x, p, &model.a(km1), &model.process_cov(km1));
    if let Some(gu) = model.input(km1) {
        xp += gu;
    }
    if !(all_finite(&xp) && all_finite(&pp)) {
        check_predicted(&xp, &pp)?;
    }
    Ok((xp, pp))
}

/// The errors of a non-finite prediction (state first).
#[cold]
pub fn check_predicted<T: Real, const NX: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
) -> Result<()> {
    predicted_error(x, p).map_or(Ok(()), Err)
}

/// [`check_predicted`]'s error, `None` for a finite prediction. Always inlined: where only the
/// failure matters (not its name), the tests are dead code and vanish.
#[inline(always)]
pub(crate) fn predicted_error<T: Real, const NX: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
) -> Option<Error> {
    // Both tests without a branch between them: dead together where the error is.
    let (x_ok, p_ok) = (all_finite(x), all_finite(p));
    let what = if !x_ok {
        "predicted state"
    } else {
        "predicted covariance"
    };
    (!(x_ok && p_ok)).then_some(Error::NonFinite { what })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::papers::Seed001Example;
    use crate::Error;
    use nalgebra::{matrix, vector};

    #[test]
    fn matches_the_textbook_products_and_is_symmetric() {
        let m = Seed001Example::model::<f64>().unwrap();
        let x = vector![1.0, -2.0, 0.5];
        let p = matrix![2.0, 0.3, -0.1; 0.3, 1.0, 0.2; -0.1, 0.2, 0.7];
        let (xp, pp) = predict(&m, 1, &x, &p).unwrap();
        assert!((xp - m.a * x).amax() < 1e-15);
        let want = m.a * p * m.a.transpose() + m.b * m.q * m.b.transpose();
        assert!((pp - want).amax() < 1e-14);
        assert_eq!(pp, pp.transpose());
    }

    #[test]
    fn overflow_is_an_error_naming_what() {
        let m = Seed001Example::model::<f64>().unwrap();
        let p = SMatrix::<f64, 3, 3>::identity() * 1.78e308;
        assert_eq!(
            predict(&m, 1, &vector![0.0, 0.0, 0.0], &p),
            Err(Error::NonFinite {
                what: "predicted covariance"
            })
        );
        assert_eq!(
            predict(&m, 1, &vector![1.7e308, 1.7e308, 0.0], &SMatrix::identity()),
            Err(Error::NonFinite {
                what: "predicted state"
            })
        );
    }
}
