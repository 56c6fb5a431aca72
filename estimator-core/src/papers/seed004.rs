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
