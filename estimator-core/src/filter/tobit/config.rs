//! Configuration of one node's local Tobit filter (seed 004, Theorem 1): the scalars
//! ε₁ … ε₁₄ and the κ₁ … κ₈ formed from them, the censoring thresholds τ, the node's trigger
//! parameters and the scalars `d`, `e` of Ξ, and where Υ enters the κ₃ term.
//!
//! The placement decision (docs/design.md, "Seed 004"): `C(Υ∘Ω₁)Cᵀ` is read as written (it
//! needs `n_x = n_y`); the product also offers the dimensionally general `Υ∘(CΩ₁Cᵀ)` — what
//! the proof's `E{Q̃ C x xᵀ Cᵀ Q̃ᵀ}` is — as [`UpsilonPlacement::OutsideC`]. What an instant
//! without a measurement does is [`Silence`]: the paper's update with the held measurement
//! (the default), or the product's prediction only.

use nalgebra::{SMatrix, SVector};

use crate::linalg::check_finite;
use crate::protocol::event_trigger::EventTriggerConfig;
use crate::{Error, Real, Result};

/// The scalars ε₁ … ε₁₄ of Theorem 1 (all finite and positive).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundScalars<T: Real> {
    pub(crate) eps: [T; 14],
}

/// κ₁ … κ₈ of Theorem 1 (index 0 is κ₁).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kappas<T: Real>(pub [T; 8]);

impl<T: Real> BoundScalars<T> {
    /// `eps[j − 1]` is ε_j.
    pub fn new(eps: [T; 14]) -> Result<Self> {
        for e in eps {
            if !e.finite() {
                return Err(Error::NonFinite {
                    what: "bound scalar epsilon",
                });
            }
            if e <= T::zero() {
                return Err(Error::InvalidConfig {
                    field: "epsilon",
                    reason: "Theorem 1 needs positive scalars epsilon_1..epsilon_14",
                });
            }
        }
        Ok(Self { eps })
    }

    /// ε_j for `j` in 1..=14.
    #[inline]
    pub fn eps(&self, j: usize) -> T {
        self.eps[j - 1]
    }

    /// κ₁ … κ₈ (Theorem 1).
    #[must_use]
    pub fn kappas(&self) -> Kappas<T> {
        let e = |j: usize| self.eps[j - 1];
        let inv = |j: usize| T::one() / self.eps[j - 1];
        let one = T::one();
        Kappas([
            one + e(1) + e(2) + e(3) + e(4) + e(5),
            one + inv(1) + inv(7) + inv(10) + inv(12) + inv(13),
            one + e(6),
            one + e(7) + e(8) + e(9) + inv(2),
            one + inv(3) + inv(8) + e(10) + e(11),
            one + inv(4) + e(12),
            one + inv(5) + inv(9) + inv(11) + e(13),
            one + inv(6),
        ])
    }

    pub(super) fn cast<U: Real>(&self) -> BoundScalars<U> {
        BoundScalars {
            eps: self.eps.map(|e| U::lit(e.to_f64())),
        }
    }
}

/// Where Υ enters the κ₃ term.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpsilonPlacement {
    /// `C (Υ∘Ω₁) Cᵀ` as printed in (30)/(37); needs `n_x = n_y` (the paper's default).
    #[default]
    AsWritten,
    /// `Υ∘(C Ω₁ Cᵀ)`, the covariance of `(ϱ − ϱ̄) C x` that the proof bounds; any dimensions.
    OutsideC,
}

/// What a local filter does at an instant its node delivered nothing (θ = 1: the trigger did
/// not fire, the bucket blocked the packet, or it was lost).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Silence {
    /// The paper's: (22) and (30) with the held ȳ and the θ² terms of M (Algorithm 1 line 12,
    /// Remark 3: "the filter gain can be calculated under two cases, θ = 1 and θ = 0").
    #[default]
    HeldMeasurement,
    /// The product's option (docs/tobit-fusion.md, "Predict on silence"): no update at all,
    /// `x̂_{t|t} = x̂_{t|t−1}` and `P̄_{t|t} = P̄_{t|t−1}` of (29). The error is then the
    /// prediction error, which (29) already bounds, so Theorem 1's bound still holds; Ḡ
    /// still advances by Ξ, the held ȳ stays.
    Predict,
    /// The product's option (docs/tobit-fusion.md, "Silence that speaks"): a silence the
    /// bucket mirror calls held is the Sijs–Lazar pseudo-measurement — the set's mean
    /// with `M + Σ_set` in (37), (22), (30) at θ = 0 — on the silence ball intersected with
    /// the censoring region, the atom at τ weighed by the filter's censoring model
    /// ([`crate::filter::silence::set::uniform_moments`]); any other
    /// silence predicts only, as [`Silence::Predict`].
    PseudoMeasurement,
    /// The product's option: a held silence is the moment-matched truncated Gaussian of the
    /// uncensored measurement on the set's box, open below where the censoring reaches
    /// ([`crate::filter::silence::truncated::truncate_box`] with the prediction bound
    /// P̄_{t|t−1} as the prior covariance); any other silence predicts only.
    TruncatedGaussian,
}

impl Silence {
    /// Whether the filter reads the trigger's silence set (and so keeps the trigger
    /// knowledge).
    #[inline]
    #[must_use]
    pub fn reads_set(self) -> bool {
        matches!(
            self,
            Silence::PseudoMeasurement | Silence::TruncatedGaussian
        )
    }
}

/// Configuration of one node's local Tobit filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitFilterConfig<T: Real, const NY: usize> {
    /// Censoring thresholds τ_m (eq. 2).
    pub tau: SVector<T, NY>,
    /// ε₁ … ε₁₄.
    pub scalars: BoundScalars<T>,
    /// The node's event-trigger parameters (σ, χ, λ, η₀ enter Ξ).
    pub trigger: EventTriggerConfig<T>,
    /// `d_t` of Ξ (positive).
    pub d: T,
    /// `e_t` of Ξ (positive).
    pub e: T,
    /// Placement of Υ in the κ₃ term.
    pub placement: UpsilonPlacement,
    /// What an instant without a measurement (θ = 1) does.
    pub silence: Silence,
}

impl<T: Real, const NY: usize> TobitFilterConfig<T, NY> {
    /// Validates τ, d, e (the scalars and trigger are validated by their constructors).
    pub fn new(
        tau: SVector<T, NY>,
        scalars: BoundScalars<T>,
        trigger: EventTriggerConfig<T>,
        d: T,
        e: T,
    ) -> Result<Self> {
        check_finite(&tau, "censoring threshold")?;
        for (v, field) in [(d, "d"), (e, "e")] {
            if !v.finite() {
                return Err(Error::NonFinite { what: field });
            }
            if v <= T::zero() {
                return Err(Error::InvalidConfig {
                    field,
                    reason: "the scalars of Xi must be positive",
                });
            }
        }
        Ok(Self {
            tau,
            scalars,
            trigger,
            d,
            e,
            placement: UpsilonPlacement::AsWritten,
            silence: Silence::HeldMeasurement,
        })
    }

    /// Selects where Υ enters the κ₃ term.
    #[must_use]
    pub fn with_placement(mut self, placement: UpsilonPlacement) -> Self {
        self.placement = placement;
        self
    }

    /// Selects what an instant without a measurement does ([`Silence`]).
    #[must_use]
    pub fn with_silence(mut self, silence: Silence) -> Self {
        self.silence = silence;
        self
    }

    /// Ξ(Ḡ) (Theorem 1).
    #[must_use]
    pub fn xi(&self, g: T) -> T {
        let one = T::one();
        let (d, e) = (self.d, self.e);
        let (lam, chi, sig) = (
            self.trigger.lambda(),
            self.trigger.chi(),
            self.trigger.sigma(),
        );
        ((one + d) * (one + e) * lam * lam + (one + chi) * (one + one / d) / (chi * chi)) * g
            + ((one + d) * (one + one / e) + (one + one / d) * (one + one / chi)) * sig * sig
    }

    /// Converts to another scalar type.
    pub fn cast<U: Real>(&self) -> Result<TobitFilterConfig<U, NY>> {
        let f = |x: T| U::lit(x.to_f64());
        Ok(TobitFilterConfig::new(
            self.tau.map(f),
            self.scalars.cast(),
            self.trigger.cast()?,
            f(self.d),
            f(self.e),
        )?
        .with_placement(self.placement)
        .with_silence(self.silence))
    }
}

/// The variances of a diagonal measurement covariance; refuses correlated noise, which the
/// per-component Tobit model (eqs. 5-7) cannot represent.
pub fn diagonal_variances<T: Real, const NY: usize>(
    r: &SMatrix<T, NY, NY>,
) -> Result<SVector<T, NY>> {
    check_finite(r, "measurement covariance")?;
    let tol = T::EPS.sqrt();
    for i in 0..NY {
        for j in 0..NY {
            if i != j && r[(i, j)].abs() > tol * (r[(i, i)] * r[(j, j)]).abs().sqrt() {
                return Err(Error::InvalidConfig {
                    field: "measurement covariance",
                    reason: "the Tobit model (eqs. 5-7) needs independent components (diagonal R)",
                });
            }
        }
    }
    let d = r.diagonal();
    if d.iter().any(|&v| v <= T::zero()) {
        return Err(Error::NotPositiveDefinite {
            what: "measurement covariance",
        });
    }
    Ok(d)
}
