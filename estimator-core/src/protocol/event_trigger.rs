//! The dynamic event-triggering protocol of one sensor node (seed 004, eqs. 11-15).
//!
//! At each instant the node compares its (censored) measurement `y_t` with the last
//! measurement it actually transmitted, `ε_t = y_ref − y_t` (eq. 12), and fires when
//!
//! ```text
//! η_t / χ + σ − ‖ε_t‖ ≤ 0                       (14), α_t = 1 if it holds (15)
//! η_{t+1} = λ η_t + σ − ‖ε_t‖,   η_0 given      (13)
//! ```
//!
//! Decisions this implementation makes where the paper is loose (docs/design.md, "Seed 004"):
//! * The reference `y_ref` changes only on an actual transmission (fired *and* granted a
//!   token by the shared bucket); it starts at the censoring threshold τ (ȳ starts at τ).
//! * The trigger condition uses `ε_t` against the reference *before* the decision; the
//!   recursion (13) uses it *after* the decision, i.e. `ε_t = 0` when the measurement was
//!   sent. That is the only reading under which the paper's claim "λχ > 1 ensures η ≥ 0"
//!   holds (if not fired, `σ − ‖ε‖ > −η/χ` so `η_{t+1} > (λ − 1/χ) η ≥ 0`; if sent,
//!   `η_{t+1} = λη + σ ≥ 0`), and the one under which the bound (33) holds at every instant.
//! * The first instant a node processes uses `η_0`.
//!
//! The paper requires `λχ > 1`; its own example (λ = 0.1 or 0.2, χ = 5) violates it, and η
//! then goes negative. [`EventTriggerConfig::new`] rejects such a configuration;
//! [`EventTriggerConfig::new_allowing_paper_violation`] accepts it and records that it did
//! ([`EventTriggerConfig::paper_violation`]), so that callers can report it.

use nalgebra::SVector;

use crate::linalg::check_finite;
use crate::{Error, Real, Result};

/// Validated parameters of one node's dynamic event trigger.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventTriggerConfig<T: Real> {
    sigma: T,
    chi: T,
    lambda: T,
    eta0: T,
    violation: bool,
}

/// Why `λχ ≤ 1` is refused (the text of [`Error::InvalidConfig`] and of the report).
pub const LAMBDA_CHI_REASON: &str =
    "the paper requires lambda*chi > 1 so that eta stays non-negative (seed 004, below eq. 13)";

impl<T: Real> EventTriggerConfig<T> {
    /// `σ ≥ 0` (σ = 0 with η₀ = 0 makes the node send at every instant), `χ > 0`, `λ > 0`,
    /// `η₀ ≥ 0`, all finite, and `λχ > 1` as the paper requires.
    pub fn new(sigma: T, chi: T, lambda: T, eta0: T) -> Result<Self> {
        let c = Self::new_allowing_paper_violation(sigma, chi, lambda, eta0)?;
        if c.violation {
            return Err(Error::InvalidConfig {
                field: "lambda*chi",
                reason: LAMBDA_CHI_REASON,
            });
        }
        Ok(c)
    }

    /// Like [`EventTriggerConfig::new`] but accepts `λχ ≤ 1` (as the paper's own example
    /// needs). Whether it was accepted is reported by [`EventTriggerConfig::paper_violation`].
    pub fn new_allowing_paper_violation(sigma: T, chi: T, lambda: T, eta0: T) -> Result<Self> {
        for (v, what) in [
            (sigma, "trigger sigma"),
            (chi, "trigger chi"),
            (lambda, "trigger lambda"),
            (eta0, "trigger eta0"),
        ] {
            if !v.finite() {
                return Err(Error::NonFinite { what });
            }
        }
        if sigma < T::zero() {
            return Err(Error::InvalidConfig {
                field: "sigma",
                reason: "must be non-negative",
            });
        }
        if chi <= T::zero() {
            return Err(Error::InvalidConfig {
                field: "chi",
                reason: "must be positive",
            });
        }
        if lambda <= T::zero() {
            return Err(Error::InvalidConfig {
                field: "lambda",
                reason: "must be positive",
            });
        }
        if eta0 < T::zero() {
            return Err(Error::InvalidConfig {
                field: "eta0",
                reason: "must be non-negative",
            });
        }
        Ok(Self {
            sigma,
            chi,
            lambda,
            eta0,
            violation: lambda * chi <= T::one(),
        })
    }

    /// `Some(reason)` when this configuration violates `λχ > 1` (accepted only through
    /// [`EventTriggerConfig::new_allowing_paper_violation`]).
    #[must_use]
    pub fn paper_violation(&self) -> Option<&'static str> {
        self.violation.then_some(LAMBDA_CHI_REASON)
    }

    /// σ.
    #[inline]
    pub fn sigma(&self) -> T {
        self.sigma
    }
    /// χ.
    #[inline]
    pub fn chi(&self) -> T {
        self.chi
    }
    /// λ.
    #[inline]
    pub fn lambda(&self) -> T {
        self.lambda
    }
    /// η₀.
    #[inline]
    pub fn eta0(&self) -> T {
        self.eta0
    }

    /// Converts to another scalar type (keeps the violation flag as validated in `T`).
    pub fn cast<U: Real>(&self) -> Result<EventTriggerConfig<U>> {
        let f = |x: T| U::lit(x.to_f64());
        let mut c = EventTriggerConfig::new_allowing_paper_violation(
            f(self.sigma),
            f(self.chi),
            f(self.lambda),
            f(self.eta0),
        )?;
        c.violation = self.violation;
        Ok(c)
    }
}

/// What the trigger did at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggerOutcome<T: Real> {
    /// α_t (eq. 15): the condition (14) held.
    pub triggered: bool,
    /// α_t β_t: fired and granted, so the measurement was transmitted.
    pub sent: bool,
    /// η_t used in the condition.
    pub eta: T,
    /// ‖ε_t‖ against the reference before the decision.
    pub error_norm: T,
}

/// One node's dynamic event trigger: η and the last transmitted measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventTrigger<T: Real, const NY: usize> {
    cfg: EventTriggerConfig<T>,
    eta: T,
    reference: SVector<T, NY>,
}

impl<T: Real, const NY: usize> EventTrigger<T, NY> {
    /// Starts with `η = η₀` and the reference at `initial_reference` (the censoring threshold
    /// τ in seed 004).
    pub fn new(cfg: EventTriggerConfig<T>, initial_reference: SVector<T, NY>) -> Result<Self> {
        check_finite(&initial_reference, "initial reference")?;
        Ok(Self {
            cfg,
            eta: cfg.eta0,
            reference: initial_reference,
        })
    }

    /// The configuration.
    #[inline]
    pub fn config(&self) -> &EventTriggerConfig<T> {
        &self.cfg
    }

    /// η for the next instant.
    #[inline]
    pub fn eta(&self) -> T {
        self.eta
    }

    /// The last transmitted measurement (what the receiver holds, eq. 19).
    #[inline]
    pub fn reference(&self) -> &SVector<T, NY> {
        &self.reference
    }

    /// Evaluates the condition (14) for `y` without changing anything: `(α_t, ‖ε_t‖)`.
    pub fn check(&self, y: &SVector<T, NY>) -> Result<(bool, T)> {
        check_finite(y, "measurement")?;
        let err = (self.reference - y).norm();
        let fired = self.eta / self.cfg.chi + self.cfg.sigma - err <= T::zero();
        Ok((fired, err))
    }

    /// One instant: decides α_t by (14), transmits iff also `granted` (β_t of the token
    /// bucket), then advances η by (13). Nothing changes on error.
    pub fn step(&mut self, y: &SVector<T, NY>, granted: bool) -> Result<TriggerOutcome<T>> {
        let (triggered, error_norm) = self.check(y)?;
        let sent = triggered && granted;
        let post_err = if sent { T::zero() } else { error_norm };
        let eta_next = self.cfg.lambda * self.eta + self.cfg.sigma - post_err;
        if !eta_next.finite() {
            return Err(Error::NonFinite {
                what: "trigger eta",
            });
        }
        let out = TriggerOutcome {
            triggered,
            sent,
            eta: self.eta,
            error_norm,
        };
        if sent {
            self.reference = *y;
        }
        self.eta = eta_next;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::vector;

    #[test]
    fn eta_recursion_by_hand() {
        // σ = 0.5, χ = 4, λ = 0.5 (λχ = 2), η₀ = 2, reference starts at 0.
        let cfg = EventTriggerConfig::new(0.5, 4.0, 0.5, 2.0).unwrap();
        let mut tr = EventTrigger::<f64, 1>::new(cfg, vector![0.0]).unwrap();
        // t=1: y = 0.8 → ‖ε‖ = 0.8; 2/4 + 0.5 − 0.8 = 0.2 > 0 → not fired;
        //       η = 0.5·2 + 0.5 − 0.8 = 0.7.
        let o = tr.step(&vector![0.8], true).unwrap();
        assert!(!o.triggered && !o.sent);
        assert!((tr.eta() - 0.7).abs() < 1e-15);
        // t=2: y = 1.5 → ‖ε‖ = 1.5; 0.7/4 + 0.5 − 1.5 = −0.825 ≤ 0 → fired and granted;
        //       sent, so ε = 0 in (13): η = 0.35 + 0.5 = 0.85; reference = 1.5.
        let o = tr.step(&vector![1.5], true).unwrap();
        assert!(o.triggered && o.sent);
        assert!((tr.eta() - 0.85).abs() < 1e-15);
        assert_eq!(tr.reference(), &vector![1.5]);
        // t=3: y = −0.5 → ‖ε‖ = 2; fires but no token: reference stays,
        //       η = 0.425 + 0.5 − 2 = −1.075 (a blocked trigger can drive η negative).
        let o = tr.step(&vector![-0.5], false).unwrap();
        assert!(o.triggered && !o.sent);
        assert!((tr.eta() + 1.075).abs() < 1e-15);
        assert_eq!(tr.reference(), &vector![1.5]);
    }

    #[test]
    fn lambda_chi_violation_needs_opt_in() {
        // The paper's example: λ = 0.1, χ = 5.
        assert_eq!(
            EventTriggerConfig::new(0.1, 5.0, 0.1, 1.5),
            Err(Error::InvalidConfig {
                field: "lambda*chi",
                reason: LAMBDA_CHI_REASON
            })
        );
        // Exactly 1 is also refused (the paper asks for >).
        assert!(EventTriggerConfig::new(0.1, 5.0, 0.2, 1.5).is_err());
        let c = EventTriggerConfig::new_allowing_paper_violation(0.1, 5.0, 0.1, 1.5).unwrap();
        assert_eq!(c.paper_violation(), Some(LAMBDA_CHI_REASON));
        assert_eq!(
            c.cast::<f32>().unwrap().paper_violation(),
            Some(LAMBDA_CHI_REASON)
        );
        assert_eq!(
            EventTriggerConfig::new(0.1, 5.0, 0.3, 1.5)
                .unwrap()
                .paper_violation(),
            None
        );
    }

    #[test]
    fn eta_stays_non_negative_when_lambda_chi_exceeds_one_and_tokens_never_lack() {
        // The invariant the paper claims, checked on a deterministic but irregular signal,
        // in f32 and f64.
        let cfg = EventTriggerConfig::new(0.3, 5.0, 0.25, 1.0).unwrap();
        let mut a = EventTrigger::<f64, 2>::new(cfg, vector![0.0, 0.0]).unwrap();
        let mut b = EventTrigger::<f32, 2>::new(cfg.cast().unwrap(), vector![0.0, 0.0]).unwrap();
        let mut fired = 0;
        for t in 0..2000 {
            let s = t as f64;
            let y = vector![(0.37 * s).sin() * 3.0, (0.11 * s).cos() + (1.3 * s).sin()];
            fired += a.step(&y, true).unwrap().sent as u32;
            b.step(&y.cast(), true).unwrap();
            assert!(a.eta() >= 0.0 && b.eta() >= 0.0, "η < 0 at t = {t}");
        }
        assert!(
            fired > 10 && fired < 2000,
            "trigger degenerate: {fired} sends"
        );
    }

    #[test]
    fn bad_input_leaves_state_unchanged() {
        assert_eq!(
            EventTriggerConfig::new(f64::NAN, 5.0, 0.3, 1.0),
            Err(Error::NonFinite {
                what: "trigger sigma"
            })
        );
        assert!(EventTriggerConfig::new(0.1, 0.0, 0.3, 1.0).is_err());
        assert!(EventTriggerConfig::new(0.1, 5.0, -0.3, 1.0).is_err());
        assert!(EventTriggerConfig::new(-0.1, 5.0, 0.3, 1.0).is_err());
        assert!(EventTriggerConfig::new(0.1, 5.0, 0.3, -1.0).is_err());
        let cfg = EventTriggerConfig::new(0.1, 5.0, 0.3, 1.0).unwrap();
        let mut tr = EventTrigger::<f64, 2>::new(cfg, vector![0.0, 0.0]).unwrap();
        tr.step(&vector![3.0, 1.0], true).unwrap();
        let before = tr;
        assert!(tr.step(&vector![f64::NAN, 1.0], true).is_err());
        assert_eq!(tr, before);
        assert!(EventTrigger::<f64, 1>::new(cfg, vector![f64::INFINITY]).is_err());
    }
}
