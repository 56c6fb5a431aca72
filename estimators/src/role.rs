//! Whose each estimator is: the paper's, the product's, a baseline, the reference, or an
//! oracle, for the summary tables (README.md, "What is in it", has the same split per seed).

use std::fmt;

/// Where an estimator comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The estimator a seed paper proposes (cce, nn, tobit-m, fused).
    Paper,
    /// The product's own estimator or option beside the faithful one (adf, the `-mix`,
    /// `-predict`, `-silence`, `-sl` readings, `ekf-std`, the innovation gate).
    Product,
    /// What a practitioner would run instead (ikf, kf-io, seed 003's kf and ekf, tobit-kf and
    /// the textbook filters).
    Baseline,
    /// The particle filter: near-optimal and slow, the yardstick.
    Reference,
    /// An estimator fed what no receiver has: `eval`'s full-information `kf` reads every
    /// measurement before the channel and its protocol ([`crate::Estimator::full_information`]),
    /// so it is a bound to read the others against, not a competitor.
    Oracle,
}

impl Role {
    /// The role of the estimator called `name` (with its `+gate` or `~lag` suffixes) that
    /// reads the channel's output. A name alone cannot tell an oracle: `kf` is the oracle on a
    /// linear spec and the paper's channel-fed KF on seed 003's (estimators/nn.rs); see
    /// [`Role::of_estimator`].
    pub fn of(name: &str) -> Self {
        let base = name.split(['+', '~']).next().unwrap_or(name);
        if base != name {
            return Self::Product;
        }
        match base {
            "cce" | "nn" | "fused" | "tobit-1" | "tobit-2" | "tobit-3" => Self::Paper,
            "pf" | "pf-mix" => Self::Reference,
            "kf" | "ikf" | "kf-io" | "ekf" | "kf-indep" | "ekf-indep" | "tobit-kf" => {
                Self::Baseline
            }
            _ => Self::Product,
        }
    }

    /// The role of an estimator called `name` that reads the observations before the channel
    /// when `full_information` ([`crate::Estimator::full_information`]): an oracle whatever its
    /// name or options, since the data it is fed is what sets it apart; otherwise
    /// [`Role::of`].
    pub fn of_estimator(name: &str, full_information: bool) -> Self {
        if full_information {
            Self::Oracle
        } else {
            Self::of(name)
        }
    }

    /// The word printed in the tables.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Product => "product",
            Self::Baseline => "baseline",
            Self::Reference => "reference",
            Self::Oracle => "oracle",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.as_str())
    }
}

/// Said once under every table of MSEs.
pub const MSE_NOTE: &str = "MSE: mean squared error of x̂ against the truth, lower is better; \
role: the paper's estimator, the product's, a baseline, the reference, or an oracle fed what no \
receiver has (README.md)\n";

/// An MSE (or any error figure) for a table of `width` (≥ 12) columns: fixed point while it reads,
/// scientific notation beyond 1e6 (a diverged filter would print 35 digits), and the words
/// for what is not a number.
pub fn figure(v: f64, width: usize) -> String {
    if v.is_nan() {
        format!("{:>width$}", "NaN")
    } else if v.is_infinite() {
        format!("{:>width$}", "diverged")
    } else if v.abs() >= 1e6 {
        format!("{v:>width$.3e}")
    } else {
        // Six decimals, fewer where the integer part needs the room.
        let int_digits = (v.abs().log10().floor().max(0.0) as usize) + 1;
        let decimals = width
            .saturating_sub(int_digits + 1 + usize::from(v < 0.0))
            .min(6);
        format!("{v:>width$.decimals$}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_seed_estimator_has_the_readme_role() {
        for (n, r) in [
            ("cce", Role::Paper),
            ("adf", Role::Product),
            ("adf-mix", Role::Product),
            ("ikf", Role::Baseline),
            ("kf-io", Role::Baseline),
            ("pf", Role::Reference),
            ("nn", Role::Paper),
            ("ekf", Role::Baseline),
            ("ekf-std", Role::Product),
            ("kf-indep", Role::Baseline),
            ("tobit-2", Role::Paper),
            ("fused", Role::Paper),
            ("fused-predict", Role::Product),
            ("fused-sl", Role::Product),
            ("kf-silence", Role::Product),
            ("fused+gate", Role::Product),
            ("tobit-kf", Role::Baseline),
            ("tobit-cmm", Role::Product),
            ("tobit-cmm-held", Role::Product),
        ] {
            assert_eq!(Role::of(n), r, "{n}");
            assert_eq!(Role::of_estimator(n, false), r, "{n}");
        }
        // The full-information `kf` (and its gated variant) is the oracle; seed 003's `kf`,
        // the paper's KF on the channel's output, stays a baseline.
        assert_eq!(Role::of_estimator("kf", true), Role::Oracle);
        assert_eq!(Role::of_estimator("kf+gate", true), Role::Oracle);
        assert_eq!(Role::of_estimator("kf", false), Role::Baseline);
        assert_eq!(Role::Oracle.as_str(), "oracle");
        assert_eq!(format!("{:<9}|", Role::Oracle), "oracle   |");
    }

    #[test]
    fn figures_stay_within_their_column() {
        assert_eq!(figure(3.043_6, 12), "    3.043600");
        assert_eq!(figure(1.540_700_620_069_003e34, 12), "    1.541e34");
        assert_eq!(figure(-2.5e7, 12), "    -2.500e7");
        assert_eq!(figure(f64::INFINITY, 12), "    diverged");
        assert_eq!(figure(f64::NAN, 5), "  NaN");
        for v in [0.0, 999_999.0, 1e6, 1e300, -1e300] {
            assert!(figure(v, 12).len() <= 12, "{v}: {}", figure(v, 12));
        }
    }
}
