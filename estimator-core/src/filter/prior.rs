//! The initial estimate `(x̂₀, P₀)` the Kalman-type filters start from.

use nalgebra::{SMatrix, SVector};

use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::{Real, Result};

/// Validates an initial estimate: `x0` finite (error names "x0"), `p0` symmetric positive
/// definite (error names "P0"). Returns them with `P₀` symmetrised.
pub fn validated<T: Real, const NX: usize>(
    x0: SVector<T, NX>,
    p0: SMatrix<T, NX, NX>,
) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>)> {
    check_finite(&x0, "x0")?;
    check_spd(&p0, "P0")?;
    Ok((x0, symmetrize(&p0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Error;
    use nalgebra::{matrix, vector};

    #[test]
    fn refuses_what_a_filter_cannot_start_from() {
        let (x, p) = validated(vector![1.0, 2.0], matrix![2.0, 0.5; 0.5, 1.0]).unwrap();
        assert_eq!((x, p), (vector![1.0, 2.0], matrix![2.0, 0.5; 0.5, 1.0]));
        assert_eq!(
            validated(vector![f64::NAN, 0.0], SMatrix::identity()),
            Err(Error::NonFinite { what: "x0" })
        );
        assert_eq!(
            validated(vector![0.0, 0.0], matrix![1.0, 2.0; 2.0, 1.0]),
            Err(Error::NotPositiveDefinite { what: "P0" })
        );
    }
}
