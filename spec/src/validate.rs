//! Parameter checks shared by plants, channel stages and the initial distribution. Every
//! error names the offending field (`model.q`, `sensors[1].r`), so the message of a bad TOML
//! file says which entry to fix.

use nalgebra::DMatrix;

use crate::error::SpecError;

/// Errors unless every entry is finite.
pub fn check_finite(m: &DMatrix<f64>, field: &str) -> Result<(), SpecError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(SpecError::invalid(field, "contains NaN or ±∞"))
    }
}

/// Errors unless `shape == want`.
pub fn check_shape(
    shape: (usize, usize),
    want: (usize, usize),
    field: &str,
) -> Result<(), SpecError> {
    if shape == want {
        Ok(())
    } else {
        Err(SpecError::invalid(
            field,
            format!("must be {}×{}, got {}×{}", want.0, want.1, shape.0, shape.1),
        ))
    }
}

/// Checks that `m` is finite, symmetric (to 1e-9 relative) and positive definite; returns its
/// lower Cholesky factor.
pub fn check_pd(m: &DMatrix<f64>, field: &str) -> Result<DMatrix<f64>, SpecError> {
    check_symmetric(m, field)?;
    nalgebra::Cholesky::new(m.clone())
        .map(|c| c.l())
        .ok_or_else(|| SpecError::invalid(field, "is not positive definite"))
}

/// Checks that `m` is finite, symmetric and positive semi-definite; returns a factor `L`
/// with `L Lᵀ = m` (zero allowed: a deterministic quantity).
pub fn check_psd(m: &DMatrix<f64>, field: &str) -> Result<DMatrix<f64>, SpecError> {
    check_symmetric(m, field)?;
    let eig = nalgebra::SymmetricEigen::new(m.clone());
    let scale = m.amax().max(f64::MIN_POSITIVE);
    if eig.eigenvalues.iter().any(|&l| l < -1e-12 * scale) {
        return Err(SpecError::invalid(field, "is not positive semi-definite"));
    }
    let sqrt = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    Ok(&eig.eigenvectors * DMatrix::from_diagonal(&sqrt))
}

fn check_symmetric(m: &DMatrix<f64>, field: &str) -> Result<(), SpecError> {
    if !m.is_square() || m.nrows() == 0 {
        return Err(SpecError::invalid(
            field,
            format!(
                "must be a non-empty square matrix, got {}×{}",
                m.nrows(),
                m.ncols()
            ),
        ));
    }
    check_finite(m, field)?;
    if (m - m.transpose()).amax() > 1e-9 * m.amax() {
        return Err(SpecError::invalid(field, "is not symmetric"));
    }
    Ok(())
}

/// Errors unless `p` is a probability.
pub fn check_probability(p: f64, field: &str) -> Result<(), SpecError> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(SpecError::invalid(
            field,
            format!("must be a probability in [0, 1], got {p}"),
        ))
    }
}
