//! `eval`'s delaying transport (`--transport-delay`, docs/pipeline.md "Late packets"): each
//! slot reaches the estimators on time or a whole number of instants late, drawn from a named
//! distribution with its own random stream, so the plant's and the channel's random numbers
//! are the same whatever the delays.
//!
//! A slot of instant `k` that is `d ≥ 1` instants late is missing (lost) when `k` is stepped
//! and arrives after instant `k + d − 1` was stepped: what a receiver that hands an instant on
//! at its deadline sees of a packet that missed it by `d − 1` sampling periods or more. With
//! `--lag L ≥ d` the estimators fold it in ([`crate::Estimator::fold_late`]); otherwise it
//! stays lost (counted `transport_late`, and `transport_too_old` beyond the lag).

use std::fmt;
use std::str::FromStr;

use channel_sim::rng::splitmix64;

/// The longest delay a distribution may produce (instants).
pub const MAX_DELAY: u32 = 64;

/// How many instants late a slot is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Delay {
    /// `mix:P:D`: late with probability `P`, then `1..=D` instants late, uniformly.
    Mix {
        /// Probability that a slot is late.
        p: f64,
        /// The longest delay (instants).
        max: u32,
    },
    /// `geom:P`: `d` instants late with probability `(1 − P) Pᵈ` (each further instant with
    /// probability `P`), at most [`MAX_DELAY`].
    Geometric {
        /// Probability of each further instant of delay.
        p: f64,
    },
}

impl Delay {
    /// The delay of slot `seq` (`(k − 1)·nodes + node`) of run `run`: 0 on time.
    pub fn of(&self, seed: u64, run: u64, seq: u64) -> u32 {
        // "delay": the stream's tag.
        let stream = splitmix64(splitmix64(splitmix64(seed ^ 0x0064_656c_6179) ^ run));
        let mut draw = seq.wrapping_mul(2);
        let mut unit = || {
            draw = draw.wrapping_add(1);
            let bits = splitmix64(stream.wrapping_add(draw.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
            ((bits >> 11) as f64) * (1.0 / (1u64 << 53) as f64)
        };
        match *self {
            Delay::Mix { p, max } => {
                if unit() < p {
                    1 + ((unit() * f64::from(max)) as u32).min(max - 1)
                } else {
                    0
                }
            }
            Delay::Geometric { p } => {
                // Inversion: d = ⌊ln U / ln P⌋, one draw per slot.
                let u = unit().max(f64::MIN_POSITIVE);
                let d = (u.ln() / p.ln()).floor();
                if d.is_finite() {
                    (d as u32).min(MAX_DELAY)
                } else {
                    0
                }
            }
        }
    }

    /// The longest delay this distribution produces.
    pub fn max(&self) -> u32 {
        match *self {
            Delay::Mix { max, .. } => max,
            Delay::Geometric { .. } => MAX_DELAY,
        }
    }
}

impl fmt::Display for Delay {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Delay::Mix { p, max } => write!(f, "mix:{p}:{max}"),
            Delay::Geometric { p } => write!(f, "geom:{p}"),
        }
    }
}

impl FromStr for Delay {
    type Err = String;

    /// `mix:P:D` (`0 ≤ P ≤ 1`, `1 ≤ D ≤ 64`) or `geom:P` (`0 ≤ P < 1`).
    fn from_str(s: &str) -> Result<Self, String> {
        let prob = |v: &str| -> Result<f64, String> {
            let p: f64 = v.parse().map_err(|e| format!("{v}: {e}"))?;
            if p.is_finite() && (0.0..=1.0).contains(&p) {
                Ok(p)
            } else {
                Err(format!("{v} is not a probability in [0, 1]"))
            }
        };
        let parts: Vec<&str> = s.split(':').collect();
        match parts.as_slice() {
            ["mix", p, d] => {
                let max: u32 = d.parse().map_err(|e| format!("{d}: {e}"))?;
                if !(1..=MAX_DELAY).contains(&max) {
                    return Err(format!("the longest delay {max} is not in 1..={MAX_DELAY}"));
                }
                Ok(Delay::Mix { p: prob(p)?, max })
            }
            ["geom", p] => {
                let p = prob(p)?;
                if p >= 1.0 {
                    return Err("geom:P needs P < 1".into());
                }
                Ok(Delay::Geometric { p })
            }
            _ => Err(format!(
                "{s:?}: expected mix:P:D (late with probability P, 1..=D instants) or geom:P"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_named_distributions_and_refuses_the_rest() {
        assert_eq!(
            "mix:0.3:3".parse::<Delay>(),
            Ok(Delay::Mix { p: 0.3, max: 3 })
        );
        assert_eq!("geom:0.5".parse::<Delay>(), Ok(Delay::Geometric { p: 0.5 }));
        for bad in [
            "",
            "mix",
            "mix:0.3",
            "mix:1.5:3",
            "mix:0.3:0",
            "mix:0.3:65",
            "mix:nan:3",
            "geom:1",
            "geom:-0.1",
            "uniform:0.3:3",
            "mix:0.3:3:1",
        ] {
            assert!(bad.parse::<Delay>().is_err(), "{bad}");
        }
    }

    /// The draws follow the distribution: the late fraction and the delays' histogram within
    /// 5 standard errors over 200 000 slots (a fixed seed; the bound fails only on a wrong
    /// draw, not by chance).
    #[test]
    fn delays_follow_their_distribution() {
        let n = 200_000u64;
        let d = Delay::Mix { p: 0.3, max: 3 };
        let mut hist = [0u64; 4];
        for seq in 0..n {
            hist[d.of(7, 1, seq) as usize] += 1;
        }
        let close = |count: u64, p: f64| {
            let se = (p * (1.0 - p) / n as f64).sqrt();
            ((count as f64 / n as f64) - p).abs() < 5.0 * se
        };
        assert!(close(hist[0], 0.7), "{hist:?}");
        for h in &hist[1..] {
            assert!(close(*h, 0.1), "{hist:?}");
        }
        let g = Delay::Geometric { p: 0.5 };
        let mut geo = [0u64; 3];
        for seq in 0..n {
            let v = g.of(7, 1, seq) as usize;
            if v < 3 {
                geo[v] += 1;
            }
        }
        assert!(
            close(geo[0], 0.5) && close(geo[1], 0.25) && close(geo[2], 0.125),
            "{geo:?}"
        );
        // Its own stream: another run, another pattern; the same run, the same.
        assert_ne!(
            (0..64).map(|s| d.of(7, 1, s)).collect::<Vec<_>>(),
            (0..64).map(|s| d.of(7, 2, s)).collect::<Vec<_>>()
        );
        assert_eq!(d.of(7, 1, 5), d.of(7, 1, 5));
    }
}
