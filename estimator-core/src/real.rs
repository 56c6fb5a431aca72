//! The scalar abstraction: everything in the core is generic over [`Real`] (`f32` or `f64`).

use nalgebra::RealField;

/// A floating-point scalar the estimators can run on.
///
/// A thin layer over nalgebra's [`RealField`] that adds what the core needs and nalgebra does
/// not offer in `no_std`: literal conversion, `erfc` from `libm`, and the machine epsilon.
pub trait Real: RealField + Copy + Default + core::fmt::Debug {
    /// Machine epsilon of the type.
    const EPS: Self;
    /// Converts an `f64` literal (rounding for `f32`).
    fn lit(x: f64) -> Self;
    /// Widens to `f64` (exact for both implementors).
    fn to_f64(self) -> f64;
    /// Complementary error function, `libm::erfc`/`erfcf`.
    fn erfc(self) -> Self;
    /// `true` when neither NaN nor infinite.
    fn finite(self) -> bool;
}

impl Real for f64 {
    const EPS: Self = f64::EPSILON;
    #[inline]
    fn lit(x: f64) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn erfc(self) -> Self {
        libm::erfc(self)
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Real for f32 {
    const EPS: Self = f32::EPSILON;
    #[inline]
    fn lit(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn erfc(self) -> Self {
        libm::erfcf(self)
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
}
