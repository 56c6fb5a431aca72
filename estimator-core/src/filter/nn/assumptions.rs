//! Where the sufficient conditions of seed 003 fail, before ([`check_before_run`]) and during
//! ([`RunMonitor`]) a run.
//!
//! Theorem 1 guarantees `P_k ≤ P̄_k` only if its hypotheses hold; this module reports each one
//! that does not:
//!
//! * `P₀ ≤ P̄₀` (Lemma 1 starts the induction from `X₀ = Y₀`, i.e. `P̄₀ = P₀`);
//! * `‖φ(·)‖ ≤ φ̄` for the activation used (II-C; used in (24) and (30));
//! * `sup ‖f‖ ≤ H̄ φ̄ + ε̄` when `sup ‖f‖` is known (II-C: `f = Hφ + ε` with `‖H‖ ≤ H̄`,
//!   `‖φ‖ ≤ φ̄`, `‖ε‖ ≤ ε̄` cannot represent a larger `f`);
//! * the token-bucket ranges `a ≥ 1`, `b ≥ a`, `S ≥ b`, `z₀ ≤ S` (II-B);
//! * `δ₁ < 1`: not a hypothesis of Theorem 1 but the condition for the bound to be useful —
//!   `Q̄_{k+1} ≥ δ₁ Q̄_k` and `P̄_{k+1} ≥ (1+α₁⁻¹+α₃+α₄) φ̄² Q̄_k`, so `δ₁ ≥ 1` makes both bounds
//!   grow at least geometrically.
//!
//! During a run [`RunMonitor`] records the instants where `‖φ(x̂_k)‖ > φ̄` and the growth and
//! finiteness of `tr P̄_k`.

use core::fmt;

use nalgebra::SMatrix;

use super::bound::NnBoundConfig;
use super::estimator::NnTbcpEstimator;
use super::system::Activation;
use crate::linalg::eig::min_eigenvalue;
use crate::{Error, Real};

/// Token-bucket parameters as given (before validation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BucketParams {
    /// Token rate `a`.
    pub a: u32,
    /// Cost `b`.
    pub b: u32,
    /// Capacity `S`.
    pub s: u32,
    /// Initial level `z₀`.
    pub z0: u32,
}

/// The pre-run verdict. Every field holds the numbers, [`Self::violations`] the failures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreRunVerdict<T: Real> {
    /// `δ₁` of (16).
    pub delta1: T,
    /// `sup ‖φ‖` of the activation.
    pub phi_sup: T,
    /// The configured `φ̄`.
    pub phi_bar: T,
    /// `sup ‖f‖` if known.
    pub f_sup: Option<T>,
    /// `H̄ φ̄ + ε̄`, the largest `‖f‖` the NN model of II-C can represent.
    pub f_representable: T,
    /// `λ_min(P̄₀ − P₀)` (negative: `P₀ ≤ P̄₀` fails).
    pub p0_margin: T,
    /// `tr P₀` and `tr P̄₀`.
    pub p0_traces: (T, T),
    /// The bucket parameters.
    pub bucket: BucketParams,
}

/// One failed condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Violation {
    /// `δ₁ ≥ 1`: the bounds grow geometrically.
    Delta1AtLeastOne,
    /// `sup ‖φ‖ > φ̄`.
    ActivationExceedsPhiBar,
    /// `sup ‖f‖ > H̄ φ̄ + ε̄`.
    NonlinearityNotRepresentable,
    /// `P₀ ≤ P̄₀` fails.
    InitialCovarianceAboveBound,
    /// `a < 1`.
    BucketRateBelowOne,
    /// `b < a`.
    BucketCostBelowRate,
    /// `S < b`.
    BucketCapacityBelowCost,
    /// `z₀ > S`.
    BucketInitialLevelAboveCapacity,
}

impl Violation {
    /// A one-line description.
    pub fn describe(self) -> &'static str {
        match self {
            Violation::Delta1AtLeastOne => {
                "delta_1 >= 1: Q-bar and P-bar grow at least geometrically (bound uninformative)"
            }
            Violation::ActivationExceedsPhiBar => {
                "sup ||phi|| > phi_bar: the activation violates ||phi(.)|| <= phi_bar (II-C)"
            }
            Violation::NonlinearityNotRepresentable => {
                "sup ||f|| > H_bar*phi_bar + eps_bar: f = H phi + eps cannot hold (II-C)"
            }
            Violation::InitialCovarianceAboveBound => {
                "P_0 <= P_bar_0 fails: Lemma 1's induction has no base case"
            }
            Violation::BucketRateBelowOne => "token rate a < 1 (II-B)",
            Violation::BucketCostBelowRate => "transmission cost b < a (II-B)",
            Violation::BucketCapacityBelowCost => "capacity S < b (II-B)",
            Violation::BucketInitialLevelAboveCapacity => "initial level z0 > S (eq. 2)",
        }
    }
}

impl<T: Real> PreRunVerdict<T> {
    /// The failed conditions, in a fixed order (at most 8).
    pub fn violations(&self) -> heapless::Vec<Violation, 8> {
        let mut v = heapless::Vec::new();
        let mut push = |c: bool, x: Violation| {
            if c {
                // Capacity 8 = number of variants: cannot fail.
                let _ = v.push(x);
            }
        };
        push(self.delta1 >= T::one(), Violation::Delta1AtLeastOne);
        push(
            self.phi_sup > self.phi_bar,
            Violation::ActivationExceedsPhiBar,
        );
        push(
            self.f_sup.is_some_and(|f| f > self.f_representable),
            Violation::NonlinearityNotRepresentable,
        );
        push(
            self.p0_margin < T::zero(),
            Violation::InitialCovarianceAboveBound,
        );
        let b = self.bucket;
        push(b.a < 1, Violation::BucketRateBelowOne);
        push(b.b < b.a, Violation::BucketCostBelowRate);
        push(b.s < b.b, Violation::BucketCapacityBelowCost);
        push(b.z0 > b.s, Violation::BucketInitialLevelAboveCapacity);
        v
    }

    /// `true` when no condition fails.
    pub fn holds(&self) -> bool {
        self.violations().is_empty()
    }
}

impl<T: Real> fmt::Display for PreRunVerdict<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "delta_1 = {:.6} ({}); sup||phi|| = {:.4} vs phi_bar = {:.4}; lambda_min(P_bar_0 - P_0) = {:.4} (tr P_0 = {:.4}, tr P_bar_0 = {:.4})",
            self.delta1.to_f64(),
            if self.delta1 >= T::one() { "bound grows geometrically" } else { "< 1" },
            self.phi_sup.to_f64(),
            self.phi_bar.to_f64(),
            self.p0_margin.to_f64(),
            self.p0_traces.0.to_f64(),
            self.p0_traces.1.to_f64(),
        )?;
        if let Some(fs) = self.f_sup {
            writeln!(
                f,
                "sup||f|| = {:.4} vs H_bar*phi_bar + eps_bar = {:.4}",
                fs.to_f64(),
                self.f_representable.to_f64()
            )?;
        }
        let v = self.violations();
        if v.is_empty() {
            write!(f, "all sufficient conditions hold")
        } else {
            write!(f, "{} condition(s) fail:", v.len())?;
            for x in &v {
                write!(f, "\n  - {}", x.describe())?;
            }
            Ok(())
        }
    }
}

/// Checks the conditions that can be checked before a run.
///
/// `p0_true` is the actual initial error covariance `E[(x₀ − x̂₀)(x₀ − x̂₀)ᵀ]` (for the
/// deterministic `x₀, x̂₀` of section IV: `e₀ e₀ᵀ`), `p0_bar` the bound's initial value, `f_sup`
/// the largest `‖f(x)‖` if known.
pub fn check_before_run<T: Real, const NX: usize, const NPHI: usize, Act>(
    cfg: &NnBoundConfig<T>,
    act: &Act,
    eps_bar: T,
    p0_true: &SMatrix<T, NX, NX>,
    p0_bar: &SMatrix<T, NX, NX>,
    f_sup: Option<T>,
    bucket: BucketParams,
) -> Result<PreRunVerdict<T>, Error>
where
    Act: Activation<T, NX, NPHI>,
{
    let p0_margin = min_eigenvalue(&(p0_bar - p0_true), "P̄₀ − P₀")?;
    Ok(PreRunVerdict {
        delta1: cfg.delta1(),
        phi_sup: act.sup_norm(),
        phi_bar: cfg.phi_bar(),
        f_sup,
        f_representable: cfg.h_bar() * cfg.phi_bar() + eps_bar,
        p0_margin,
        p0_traces: (p0_true.trace(), p0_bar.trace()),
        bucket,
    })
}

/// Watches a run: instants with `‖φ(x̂_k)‖ > φ̄`, growth of `tr P̄_k`, and the first error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunMonitor<T: Real> {
    /// Steps observed.
    pub steps: usize,
    /// Instants with `‖φ(x̂_k)‖ > φ̄`.
    pub phi_exceed_count: usize,
    /// First such instant.
    pub phi_exceed_first: Option<usize>,
    /// Largest `‖φ(x̂_k)‖` seen.
    pub phi_max: T,
    /// Largest one-step ratio `tr P̄_{k+1} / tr P̄_k`.
    pub max_growth: T,
    /// Geometric mean of that ratio over the run.
    pub mean_log_growth: T,
    /// `tr P̄_k` at the last observed instant.
    pub last_trace: T,
    /// First step error (instant, error), e.g. the bound overflowing.
    pub first_error: Option<(usize, Error)>,
    first_trace: T,
    first_k: usize,
}

impl<T: Real> RunMonitor<T> {
    /// Starts watching an estimator at its current instant.
    pub fn new<
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        A,
    >(
        nn: &NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, A>,
    ) -> Self
    where
        A: Activation<T, NX, NPHI>,
    {
        let mut m = Self {
            steps: 0,
            phi_exceed_count: 0,
            phi_exceed_first: None,
            phi_max: T::zero(),
            max_growth: T::zero(),
            mean_log_growth: T::zero(),
            last_trace: nn.estimate().covariance().trace(),
            first_error: None,
            first_trace: nn.estimate().covariance().trace(),
            first_k: nn.instant(),
        };
        m.check_phi(nn.instant(), nn.phi_norm(), nn.config().phi_bar());
        m
    }

    fn check_phi(&mut self, k: usize, phi: T, phi_bar: T) {
        if phi > self.phi_max {
            self.phi_max = phi;
        }
        if phi > phi_bar {
            self.phi_exceed_count += 1;
            self.phi_exceed_first.get_or_insert(k);
        }
    }

    /// Records the estimator's state after a successful step.
    pub fn observe<
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        A,
    >(
        &mut self,
        nn: &NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, A>,
    ) where
        A: Activation<T, NX, NPHI>,
    {
        self.steps += 1;
        self.check_phi(nn.instant(), nn.phi_norm(), nn.config().phi_bar());
        let tr = nn.estimate().covariance().trace();
        if self.last_trace > T::zero() {
            let g = tr / self.last_trace;
            if g > self.max_growth {
                self.max_growth = g;
            }
        }
        self.last_trace = tr;
        let n = T::lit((nn.instant() - self.first_k) as f64);
        if n > T::zero() && self.first_trace > T::zero() {
            self.mean_log_growth = (tr / self.first_trace).ln() / n;
        }
    }

    /// Records a failed step.
    pub fn observe_error(&mut self, k: usize, e: Error) {
        self.first_error.get_or_insert((k, e));
    }
}

impl<T: Real> fmt::Display for RunMonitor<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} steps; ||phi(x_hat_k)|| > phi_bar at {} instants (first k = {:?}, max {:.4}); tr P_bar: last {:.3e}, mean growth x{:.3}/step, max x{:.3}",
            self.steps,
            self.phi_exceed_count,
            self.phi_exceed_first,
            self.phi_max.to_f64(),
            self.last_trace.to_f64(),
            libm::exp(self.mean_log_growth.to_f64()),
            self.max_growth.to_f64(),
        )?;
        if let Some((k, e)) = self.first_error {
            write!(f, "; first error at k = {k}: {e}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap, Tanh};
    use crate::papers::{Seed003Example, Seed003Nn};
    use crate::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
    use core::fmt::Write as _;

    fn example_verdict<T: Real>() -> PreRunVerdict<T> {
        let e0 = Seed003Example::x0::<T>() - Seed003Example::xhat0::<T>();
        check_before_run::<T, 3, 3, _>(
            &NnBoundConfig::seed003_example(),
            &Tanh,
            T::lit(0.1),
            &(e0 * e0.transpose()),
            &Seed003Example::p0(),
            Some(T::lit(8.0 * 3f64.sqrt())),
            BucketParams {
                a: 2,
                b: 3,
                s: 10,
                z0: 6,
            },
        )
        .unwrap()
    }

    #[test]
    fn paper_example_verdict() {
        let v = example_verdict::<f64>();
        // δ₁ = 5.5(1 − 1e-6)²; sup‖tanh‖ = √3 > φ̄ = 1; sup‖f‖ = 8√3 ≈ 13.86 > 8·1 + 0.1;
        // e₀e₀ᵀ has eigenvalue ‖e₀‖² = 32.6325 > 10, so P₀ ≤ 10 I fails with margin −22.6225.
        assert!((v.delta1 - 5.5 * (1.0f64 - 1e-6).powi(2)).abs() < 1e-12);
        assert!((v.p0_margin - (10.0 - 32.6325)).abs() < 1e-9);
        assert_eq!(
            v.violations().as_slice(),
            &[
                Violation::Delta1AtLeastOne,
                Violation::ActivationExceedsPhiBar,
                Violation::NonlinearityNotRepresentable,
                Violation::InitialCovarianceAboveBound,
            ]
        );
        let mut text = heapless::String::<4096>::new();
        write!(text, "{v}").unwrap();
        assert!(text.contains("4 condition(s) fail"), "{text}");
    }

    #[test]
    fn bucket_violations_are_reported_not_rejected() {
        let mut v = example_verdict::<f64>();
        v.bucket = BucketParams {
            a: 0,
            b: 3,
            s: 2,
            z0: 5,
        };
        let got = v.violations();
        assert!(got.contains(&Violation::BucketRateBelowOne));
        assert!(got.contains(&Violation::BucketCapacityBelowCost));
        assert!(got.contains(&Violation::BucketInitialLevelAboveCapacity));
        assert!(!got.contains(&Violation::BucketCostBelowRate));
    }

    #[test]
    fn monitor_sees_phi_exceedance_and_geometric_growth_in_the_example() {
        // Noise-free plant; the estimate quickly leaves the region where ‖tanh(x̂)‖ ≤ 1, and
        // tr P̄ grows by ≈ δ₁ ≈ 5.5 per step on average.
        let sys = Seed003Example;
        let mut nn = Seed003Nn::<f64>::seed003(NnBoundConfig::seed003_example()).unwrap();
        let mut mon = RunMonitor::new(&nn);
        let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
        let mut x = Seed003Example::x0::<f64>();
        for k in 0..100 {
            x = CoupledNoiseSystem::<f64, 3, 1, 2>::a(&sys, k) * x + sys.eval(&x);
            let y = CoupledNoiseSystem::<f64, 3, 1, 2>::c(&sys, k + 1) * x;
            match nn.step(&sys, tb.step().transmit.then_some(&y)) {
                Ok(()) => mon.observe(&nn),
                Err(e) => mon.observe_error(k + 1, e),
            }
        }
        assert_eq!(mon.steps, 100);
        assert!(mon.phi_exceed_count > 50, "{mon}");
        let g = mon.mean_log_growth.exp();
        assert!(g > 5.0 && g < 6.5, "{mon}");
        assert!(mon.first_error.is_none());
    }
}
