//! The innovation gate: a delivered measurement whose normalised innovation squared
//! `NIS = νᵀ S⁻¹ ν` exceeds the χ²_{n_y} quantile of a chosen probability is not used
//! (docs/gate.md).
//!
//! For a consistent filter the innovation `ν = y − ŷ⁻` of a delivered measurement is
//! `N(0, S)`, so its NIS is χ² with `n_y` degrees of freedom and a gate of probability `P`
//! rejects a fraction `1 − P` of good measurements — the innovation consistency test with
//! which flight-control EKFs (PX4's EKF2, ArduPilot's EKF3: "innovation test ratios") refuse
//! a glitching sensor. A finite outlier such as `y = 1e150`, which every estimator would
//! otherwise accept, gives an NIS far above any quantile (or one that overflows to `∞`) and
//! is rejected.
//!
//! * [`InnovationGate`] is configuration: one threshold per number of degrees of freedom
//!   (1..=[`MAX_DOF`]), from a probability ([`InnovationGate::chi2`], χ² quantiles computed
//!   here without `std`, [`chi2_quantile`]) or given directly
//!   ([`InnovationGate::with_thresholds`]). [`InnovationGate::off`] admits everything without
//!   a test.
//! * [`GateCounts`] is running state: measurements tested and rejected.
//! * [`GatedStep`] is the hook each filter implements: its own step, except that a delivered
//!   measurement the gate rejects is treated as no information (the filter's
//!   [`Packet::Lost`](crate::Packet::Lost): prediction only — for the occlusion filters never
//!   a dropout, which would say the state is in a region). [`Gated`] pairs a [`GatedStep`]
//!   estimator with a gate and its counts, as [`OnModel`](crate::OnModel) pairs a filter with
//!   its model, and is itself an [`Estimator`].
//!
//! A non-finite measurement stays an error ([`Error::NonFinite`]), gate or not: it is broken
//! input, not an outlier.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::Estimator;
use crate::filter::time_update::predict;
use crate::linalg::check_finite;
use crate::linalg::small::SmallLdl;
use crate::model::LinearSystem;
use crate::{Error, Real, Result};

/// The largest number of degrees of freedom (measurement dimension) a gate has a threshold
/// for.
pub const MAX_DOF: usize = 8;

/// Consecutive rejections after which [`InnovationGate::chi2`]'s gate admits the next
/// measurement untested (docs/gate.md, "Lock-out").
pub const DEFAULT_RECOVER_AFTER: u32 = 3;

/// Thresholds on the NIS, one per number of degrees of freedom `1..=MAX_DOF`, and the
/// lock-out rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InnovationGate<T: Real> {
    thresholds: [T; MAX_DOF],
    off: bool,
    recover_after: u32,
}

impl<T: Real> InnovationGate<T> {
    /// The gate that admits every measurement without computing its NIS: a [`Gated`]
    /// estimator with it gives the same bits as the estimator alone.
    pub fn off() -> Self {
        Self {
            thresholds: [T::one() / T::zero(); MAX_DOF],
            off: true,
            recover_after: 0,
        }
    }

    /// The χ² gate of probability `p` (`0 < p < 1`): a measurement of `n` components is
    /// admitted iff its NIS is at most the χ²_n quantile of `p` ([`chi2_quantile`]), so a
    /// consistent filter rejects a fraction `1 − p` of good measurements.
    pub fn chi2(p: f64) -> Result<Self> {
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(Error::InvalidConfig {
                field: "gate probability",
                reason: "must be finite and in (0, 1)",
            });
        }
        let mut thresholds = [T::zero(); MAX_DOF];
        for (i, t) in thresholds.iter_mut().enumerate() {
            *t = T::lit(chi2_quantile(p, i + 1)?);
        }
        Ok(Self {
            thresholds,
            off: false,
            recover_after: DEFAULT_RECOVER_AFTER,
        })
    }

    /// Explicit thresholds, `thresholds[n − 1]` for `n` degrees of freedom (each positive;
    /// `+∞` admits every finite NIS of that size).
    pub fn with_thresholds(thresholds: [T; MAX_DOF]) -> Result<Self> {
        if thresholds
            .iter()
            .any(|t| t.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater))
        {
            return Err(Error::InvalidConfig {
                field: "gate thresholds",
                reason: "must be positive",
            });
        }
        Ok(Self {
            thresholds,
            off: false,
            recover_after: DEFAULT_RECOVER_AFTER,
        })
    }

    /// After `n` consecutive rejected measurements, the next one is admitted untested
    /// ([`GateState`]; 0: never). A filter whose estimate has left its own covariance (a
    /// wrong occlusion label, a missed manoeuvre) sees every good measurement as an outlier;
    /// without this rule the gate would lock it out for good. Default
    /// [`DEFAULT_RECOVER_AFTER`].
    #[must_use]
    pub fn with_recovery(mut self, n: u32) -> Self {
        self.recover_after = n;
        self
    }

    /// The consecutive rejections after which a measurement is admitted untested (0: never).
    #[inline]
    pub fn recover_after(&self) -> u32 {
        self.recover_after
    }

    /// `true` for [`InnovationGate::off`].
    #[inline]
    pub fn is_off(&self) -> bool {
        self.off
    }

    /// The NIS threshold for `dof` degrees of freedom (`1..=MAX_DOF`).
    pub fn threshold(&self, dof: usize) -> Result<T> {
        match dof {
            1..=MAX_DOF => Ok(self.thresholds[dof - 1]),
            _ => Err(Error::InvalidConfig {
                field: "gate",
                reason: "measurement dimension outside 1..=8",
            }),
        }
    }

    /// Whether the innovation `nu` with covariance `s` passes: its NIS `νᵀ S⁻¹ ν` is finite
    /// and at most the threshold for `NY` degrees of freedom. The off gate admits without a
    /// test. `s` not positive definite is an error (the update it belongs to would fail too).
    pub fn admits<const NY: usize>(
        &self,
        nu: &SVector<T, NY>,
        s: &SMatrix<T, NY, NY>,
    ) -> Result<bool> {
        if self.off {
            return Ok(true);
        }
        let limit = self.threshold(NY)?;
        let nis = SmallLdl::new(s, "innovation covariance")?.mahalanobis(nu);
        // An NIS that overflowed (ν ≈ 1e300) is an outlier, not a numerical failure.
        Ok(nis.finite() && nis <= limit)
    }
}

/// Measurements a gate tested and rejected.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GateCounts {
    /// Delivered measurements the gate tested (one per node and instant).
    pub tested: u32,
    /// Of those, the ones it rejected (not used).
    pub rejected: u32,
}

impl GateCounts {
    /// No measurement.
    pub const NONE: Self = Self {
        tested: 0,
        rejected: 0,
    };

    /// One measurement, admitted or not.
    #[inline]
    pub fn one(admitted: bool) -> Self {
        Self {
            tested: 1,
            rejected: u32::from(!admitted),
        }
    }

    /// Adds `other` (saturating).
    #[inline]
    pub fn add(&mut self, other: Self) {
        self.tested = self.tested.saturating_add(other.tested);
        self.rejected = self.rejected.saturating_add(other.rejected);
    }
}

/// A gate's running state: its counts, and the rejections in a row that trigger the
/// lock-out rule ([`InnovationGate::with_recovery`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GateState {
    /// Measurements tested and rejected so far (a measurement admitted by the lock-out rule
    /// counts as tested, not rejected).
    pub counts: GateCounts,
    /// Measurements admitted untested by the lock-out rule.
    pub forced: u32,
    streak: u32,
}

impl GateState {
    /// The gate for the next step: `gate`, or [`InnovationGate::off`] when the last
    /// `gate.recover_after()` measurements were all rejected.
    #[inline]
    pub fn gate_for_next<T: Real>(&self, gate: &InnovationGate<T>) -> InnovationGate<T> {
        let n = gate.recover_after();
        if n > 0 && self.streak >= n {
            InnovationGate::off()
        } else {
            *gate
        }
    }

    /// Records a successful step's counts, taken with `used` (from
    /// [`GateState::gate_for_next`]).
    #[inline]
    pub fn record<T: Real>(&mut self, c: GateCounts, used: &InnovationGate<T>) {
        self.counts.add(c);
        if c.rejected > 0 {
            self.streak = self.streak.saturating_add(c.rejected);
        } else if c.tested > 0 {
            self.streak = 0;
            if used.is_off() {
                self.forced = self.forced.saturating_add(1);
            }
        }
    }
}

/// An estimator whose step can gate its delivered measurements.
pub trait GatedStep<T: Real, const NX: usize>: Estimator<T, NX> {
    /// [`Estimator::step`], except that a delivered measurement whose innovation `gate` does
    /// not admit is not used (the instant is stepped as if nothing had arrived, the
    /// filter's reading of [`Packet::Lost`](crate::Packet::Lost)). Returns what the gate
    /// tested and rejected at this instant. With [`InnovationGate::off`] it is
    /// [`Estimator::step`], bit for bit. On error nothing changes.
    fn step_gated(
        &mut self,
        k: usize,
        y: &Self::Measurement,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts>;
}

/// A [`GatedStep`] estimator `E` with its gate (configuration) and counts (running state).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gated<T: Real, E> {
    /// The estimator.
    pub estimator: E,
    /// The gate it runs with.
    pub gate: InnovationGate<T>,
    state: GateState,
}

impl<T: Real, E> Gated<T, E> {
    /// `estimator` behind `gate`, nothing counted yet.
    pub fn new(estimator: E, gate: InnovationGate<T>) -> Self {
        Self {
            estimator,
            gate,
            state: GateState::default(),
        }
    }

    /// Measurements tested and rejected so far.
    #[inline]
    pub fn counts(&self) -> GateCounts {
        self.state.counts
    }

    /// The gate's running state (counts, measurements admitted by the lock-out rule).
    #[inline]
    pub fn state(&self) -> &GateState {
        &self.state
    }
}

impl<T: Real, const NX: usize, E: GatedStep<T, NX>> Estimator<T, NX> for Gated<T, E> {
    type Measurement = E::Measurement;

    /// [`GatedStep::step_gated`] with the pair's gate (or none, by the lock-out rule); the
    /// state changes only on success.
    fn step(&mut self, k: usize, y: &Self::Measurement) -> Result<()> {
        let gate = self.state.gate_for_next(&self.gate);
        let c = self.estimator.step_gated(k, y, &gate)?;
        self.state.record(c, &gate);
        Ok(())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.estimator.estimate()
    }
}

/// The Kalman innovation of `y` against the prediction `(x⁻, P⁻)`: `ν = y − C x⁻`,
/// `S = C P⁻ Cᵀ + R` (`R` symmetric), the pair every Kalman-type arrival update uses.
#[inline]
pub fn kalman_innovation<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    y: &SVector<T, NY>,
) -> (SVector<T, NY>, SMatrix<T, NY, NY>) {
    let nu = y - c * x;
    let s = c * p * c.transpose() + r;
    (nu, (s + s.transpose()) * T::lit(0.5))
}

/// Whether `gate` admits `y_k` against the linear prediction of instant `k` from `(x, P)`
/// (the arrival innovation of the KF, IKF, CCE and ADF: [`kalman_innovation`] of the
/// model's `C_k`, `D R Dᵀ`). The off gate admits without computing anything. Errors as the
/// step would: a non-finite `y` or prediction.
pub fn admits_linear<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>>(
    gate: &InnovationGate<T>,
    model: &M,
    k: usize,
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    y: &SVector<T, NY>,
) -> Result<bool> {
    if gate.is_off() {
        return Ok(true);
    }
    check_finite(y, "measurement")?;
    let (xp, pp) = predict(model, k, x, p)?;
    let (nu, s) = kalman_innovation(&xp, &pp, &model.c(k), &model.measurement_cov(k), y);
    gate.admits(&nu, &s)
}

/// The χ²_n quantile of probability `p` (`0 < p < 1`, `n ≥ 1`): `x` with
/// `P(χ²_n ≤ x) = p`.
///
/// Started from [`wilson_hilferty`] and refined by safeguarded Newton steps on the exact
/// upper tail `Q(n/2, x/2)` (closed forms for integer `n`: a finite series times `e^{−x/2}`,
/// plus `erfc(√(x/2))` for odd `n`), so the result is accurate to about 1e-13 relative for
/// `n = 1..=8` and `p` in `[0.5, 0.9999]` (tested against an independent 40-digit table,
/// docs/gate.md). Computed in `f64` with `libm`, as on the MCU.
pub fn chi2_quantile(p: f64, n: usize) -> Result<f64> {
    if !(p.is_finite() && p > 0.0 && p < 1.0) || n == 0 || n > 1000 {
        return Err(Error::InvalidConfig {
            field: "chi2 quantile",
            reason: "needs 0 < p < 1 and 1 ≤ n ≤ 1000",
        });
    }
    let tail = 1.0 - p;
    // Bracket [lo, hi] with Q(lo) ≥ tail ≥ Q(hi); Q decreases in x.
    let (mut lo, mut hi) = (0.0f64, wilson_hilferty(p, n).max(1.0));
    while chi2_sf(hi, n) > tail {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return Err(Error::Numerical {
                what: "chi2 quantile bracket",
            });
        }
    }
    let mut x = wilson_hilferty(p, n);
    if !(x > lo && x < hi) {
        x = 0.5 * (lo + hi);
    }
    for _ in 0..200 {
        let q = chi2_sf(x, n);
        if q > tail {
            lo = x;
        } else {
            hi = x;
        }
        let f = chi2_pdf(x, n);
        let mut next = x + (q - tail) / f;
        if !(next > lo && next < hi && next.is_finite()) {
            next = 0.5 * (lo + hi);
        }
        if (next - x).abs() <= 4.0 * f64::EPSILON * x {
            return Ok(next);
        }
        x = next;
    }
    Ok(x)
}

/// The Wilson–Hilferty approximation of the χ²_n quantile of `p`:
/// `n (1 − 2/(9n) + z √(2/(9n)))³` with `z = Φ⁻¹(p)` (clamped at 0). Its worst relative
/// error over `p ∈ [0.5, 0.9999]` is 7.1 % for `n = 1`, 4.7 % for `n = 2` and falls to 1.4 %
/// at `n = 8` (tested); [`chi2_quantile`] refines it.
pub fn wilson_hilferty(p: f64, n: usize) -> f64 {
    let n = n as f64;
    let h = 2.0 / (9.0 * n);
    let c = 1.0 - h + normal_quantile(p) * libm::sqrt(h);
    if c <= 0.0 {
        return 0.0;
    }
    n * c * c * c
}

/// `Φ⁻¹(p)`, the standard normal quantile: Acklam's rational approximation (relative error
/// below 1.2e-9) with one Halley step on `erfc`.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let tail = |q: f64| {
        let q = libm::sqrt(-2.0 * libm::log(q));
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let x = if p < 0.02425 {
        tail(p)
    } else if p > 1.0 - 0.02425 {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    // Halley on Φ(x) − p, Φ(x) = erfc(−x/√2)/2.
    let e = 0.5 * libm::erfc(-x / core::f64::consts::SQRT_2) - p;
    let u = e * libm::sqrt(2.0 * core::f64::consts::PI) * libm::exp(0.5 * x * x);
    x - u / (1.0 + 0.5 * x * u)
}

/// `P(χ²_n > x)` for integer `n` (the regularised upper incomplete gamma `Q(n/2, x/2)`).
fn chi2_sf(x: f64, n: usize) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let h = 0.5 * x;
    let mut sum = 0.0;
    let even = n.is_multiple_of(2);
    if even {
        // Σ_{j<n/2} h^j / j!
        let mut term = 1.0;
        sum = 1.0;
        for j in 1..n / 2 {
            term *= h / j as f64;
            sum += term;
        }
    } else if n >= 3 {
        // Σ_{j=1}^{(n−1)/2} h^{j−1/2} / Γ(j + 1/2); Γ(3/2) = √π/2, Γ(j + 1/2) = (j − 1/2) Γ(j − 1/2)
        let mut term = 2.0 * libm::sqrt(h / core::f64::consts::PI);
        sum = term;
        for j in 2..=(n - 1) / 2 {
            term *= h / (j as f64 - 0.5);
            sum += term;
        }
    }
    let series = libm::exp(-h) * sum;
    if even {
        series
    } else {
        libm::erfc(libm::sqrt(h)) + series
    }
}

/// The χ²_n density at `x > 0`: `x^{n/2−1} e^{−x/2} / (2^{n/2} Γ(n/2))`, in logs.
fn chi2_pdf(x: f64, n: usize) -> f64 {
    let a = 0.5 * n as f64;
    libm::exp((a - 1.0) * libm::log(x) - 0.5 * x - a * core::f64::consts::LN_2 - libm::lgamma(a))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn survival_function_closed_forms() {
        // n = 2: e^{−x/2}; n = 1: erfc(√(x/2)); n = 3: erfc + √(2x/π) e^{−x/2};
        // n = 4: e^{−x/2}(1 + x/2).
        for x in [0.1, 1.0, 3.0, 10.0, 30.0] {
            let h: f64 = x / 2.0;
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs().max(1e-300);
            assert!(close(chi2_sf(x, 2), (-h).exp()));
            assert!(close(chi2_sf(x, 1), libm::erfc(h.sqrt())));
            let three =
                libm::erfc(h.sqrt()) + (2.0 * x / core::f64::consts::PI).sqrt() * (-h).exp();
            assert!(close(chi2_sf(x, 3), three), "{x}");
            assert!(close(chi2_sf(x, 4), (-h).exp() * (1.0 + h)));
            assert!(close(chi2_sf(x, 6), (-h).exp() * (1.0 + h + h * h / 2.0)));
        }
    }

    #[test]
    fn gate_validates_and_off_admits_everything() {
        assert!(InnovationGate::<f64>::chi2(1.0).is_err());
        assert!(InnovationGate::<f64>::chi2(0.0).is_err());
        assert!(InnovationGate::<f64>::chi2(f64::NAN).is_err());
        assert!(
            InnovationGate::<f64>::with_thresholds([1.0, 2.0, 3.0, 0.0, 1.0, 1.0, 1.0, 1.0])
                .is_err()
        );
        let off = InnovationGate::<f64>::off();
        let nu = SVector::<f64, 1>::new(1e300);
        let s = SMatrix::<f64, 1, 1>::new(1.0);
        assert_eq!(off.admits(&nu, &s), Ok(true));
        let g = InnovationGate::<f64>::chi2(0.99).unwrap();
        assert_eq!(g.admits(&nu, &s), Ok(false)); // NIS overflows to ∞
        assert_eq!(g.admits(&SVector::<f64, 1>::new(2.5), &s), Ok(true)); // 6.25 ≤ 6.63
        assert_eq!(g.admits(&SVector::<f64, 1>::new(2.6), &s), Ok(false)); // 6.76 > 6.63
        assert!(g.admits(&nu, &SMatrix::<f64, 1, 1>::new(-1.0)).is_err());
        let f = InnovationGate::<f32>::chi2(0.95).unwrap();
        assert!((f.threshold(2).unwrap() - 5.991_464_5).abs() < 1e-6);
        assert!(f.threshold(9).is_err() && f.threshold(0).is_err());
    }
}
