//! Seed 004, section 4: the scalars of Theorem 1 the example uses (docs/design.md,
//! "Seed 004").

use crate::filter::tobit::config::BoundScalars;
use crate::Real;

impl<T: Real> BoundScalars<T> {
    /// The example's values (section 4): ε₁…ε₅ = 0.05, ε₆…ε₁₃ = 0.7, ε₁₄ = 1.
    #[must_use]
    pub fn paper_example() -> Self {
        let mut eps = [T::lit(0.7); 14];
        for e in eps.iter_mut().take(5) {
            *e = T::lit(0.05);
        }
        eps[13] = T::one();
        Self { eps }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kappas_of_the_paper_example() {
        let k = BoundScalars::<f64>::paper_example().kappas().0;
        let want = [
            1.25,
            1.0 + 20.0 + 4.0 / 0.7,
            1.7,
            1.0 + 2.1 + 20.0,
            1.0 + 20.0 + 1.0 / 0.7 + 1.4,
            1.0 + 20.0 + 0.7,
            1.0 + 20.0 + 2.0 / 0.7 + 0.7,
            1.0 + 1.0 / 0.7,
        ];
        for i in 0..8 {
            assert!((k[i] - want[i]).abs() < 1e-12, "κ{}", i + 1);
        }
    }
}
