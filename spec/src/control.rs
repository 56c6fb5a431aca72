//! A known control input: `x_{k+1} = A x_k + B_u u_k + B w_k`, with `u_k` a deterministic
//! schedule that the plant and every estimator evaluate alike (the estimators' time update
//! adds the same `B_u u_k`; docs/pipeline.md, "Scenario files").
//!
//! The schedules: a constant, a sinusoid `offset + amplitude · sin(2π k / period + phase)`
//! (entry-wise), or a list of vectors repeated cyclically (`u_k = values[k mod len]`).
//! Evaluating one draws nothing and allocates nothing.

use estpipe_wire::Fnv1a64;
use nalgebra::{DMatrix, DVector};

use crate::error::SpecError;
use crate::fingerprint::fingerprint_matrix;
use crate::validate::check_finite;

/// How `u_k` depends on k.
#[derive(Clone, Debug, PartialEq)]
pub enum Schedule {
    /// `u_k = value`.
    Constant(Vec<f64>),
    /// `u_k = offset + amplitude · sin(2π k / period + phase)`, entry-wise.
    Sinusoid {
        /// The mean of every entry.
        offset: Vec<f64>,
        /// The amplitude of every entry.
        amplitude: Vec<f64>,
        /// Period in instants (> 0).
        period: f64,
        /// Phase in radians.
        phase: f64,
    },
    /// `u_k = values[k mod values.len()]`.
    List(Vec<Vec<f64>>),
}

/// `B_u` and the schedule of `u`.
#[derive(Clone, Debug, PartialEq)]
pub struct Control {
    b: DMatrix<f64>,
    schedule: Schedule,
}

impl Control {
    /// Validates `b` (nx × nu, finite) and the schedule (vectors of nu finite entries, a
    /// positive finite period, a non-empty list); errors name `control.b`, `control.u.*`.
    pub fn new(b: DMatrix<f64>, schedule: Schedule, nx: usize) -> Result<Self, SpecError> {
        check_finite(&b, "control.b")?;
        if b.nrows() != nx || b.ncols() == 0 {
            return Err(SpecError::invalid(
                "control.b",
                format!(
                    "must have nx = {nx} rows and one column per input, got {}×{}",
                    b.nrows(),
                    b.ncols()
                ),
            ));
        }
        let nu = b.ncols();
        let vector = |v: &[f64], field: &str| {
            if v.len() != nu {
                return Err(SpecError::invalid(
                    field,
                    format!(
                        "must have nu = {nu} entries (the columns of control.b), got {}",
                        v.len()
                    ),
                ));
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(SpecError::invalid(field, "contains NaN or ±∞"));
            }
            Ok(())
        };
        match &schedule {
            Schedule::Constant(v) => vector(v, "control.u.value")?,
            Schedule::Sinusoid {
                offset,
                amplitude,
                period,
                phase,
            } => {
                vector(offset, "control.u.offset")?;
                vector(amplitude, "control.u.amplitude")?;
                // 2πk/period must stay finite for every k a stream can have (u32): a
                // subnormal period made u NaN, which was then blamed on `initial.cov`.
                let angle = 2.0 * std::f64::consts::PI * f64::from(u32::MAX) / *period;
                if !(period.is_finite() && *period > 0.0 && angle.is_finite()) {
                    return Err(SpecError::invalid(
                        "control.u.period",
                        format!(
                            "must be a positive number of instants (2πk/period finite for \
                             every k), got {period:e}"
                        ),
                    ));
                }
                if !phase.is_finite() {
                    return Err(SpecError::invalid("control.u.phase", "is not finite"));
                }
            }
            Schedule::List(values) => {
                if values.is_empty() {
                    return Err(SpecError::invalid(
                        "control.u.values",
                        "must have at least one vector",
                    ));
                }
                for (i, v) in values.iter().enumerate() {
                    vector(v, &format!("control.u.values[{i}]"))?;
                }
            }
        }
        Ok(Self { b, schedule })
    }

    /// `B_u`.
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }

    /// The schedule.
    pub fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    /// Entry `i` of `u_k`.
    pub fn u(&self, k: usize, i: usize) -> f64 {
        match &self.schedule {
            Schedule::Constant(v) => v[i],
            Schedule::Sinusoid {
                offset,
                amplitude,
                period,
                phase,
            } => {
                let t = 2.0 * std::f64::consts::PI * (k as f64) / period + phase;
                offset[i] + amplitude[i] * t.sin()
            }
            Schedule::List(values) => values[k % values.len()][i],
        }
    }

    /// `B_u u_k` into `out[..nx]`, without allocating.
    pub fn input_into(&self, k: usize, out: &mut [f64]) {
        let (nx, nu) = self.b.shape();
        for (r, o) in out.iter_mut().enumerate().take(nx) {
            let mut acc = 0.0;
            for j in 0..nu {
                acc += self.b[(r, j)] * self.u(k, j);
            }
            *o = acc;
        }
    }

    /// `B_u u_k`.
    pub fn input(&self, k: usize) -> DVector<f64> {
        let mut v = DVector::zeros(self.b.nrows());
        self.input_into(k, v.as_mut_slice());
        v
    }

    /// Feeds `B_u` and the schedule to a model fingerprint.
    pub fn fingerprint(&self, h: &mut Fnv1a64) {
        h.str("control");
        fingerprint_matrix(h, &self.b);
        match &self.schedule {
            Schedule::Constant(v) => {
                h.u64(0).f64s(v);
            }
            Schedule::Sinusoid {
                offset,
                amplitude,
                period,
                phase,
            } => {
                h.u64(1)
                    .f64s(offset)
                    .f64s(amplitude)
                    .f64(*period)
                    .f64(*phase);
            }
            Schedule::List(values) => {
                h.u64(2).u64(values.len() as u64);
                for v in values {
                    h.f64s(v);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    #[test]
    fn schedules_and_their_validation() {
        let b = dmatrix![0.0; 1.0];
        let c = Control::new(b.clone(), Schedule::Constant(vec![2.0]), 2).unwrap();
        assert_eq!(c.input(7).as_slice(), &[0.0, 2.0]);
        let s = Control::new(
            b.clone(),
            Schedule::Sinusoid {
                offset: vec![1.0],
                amplitude: vec![3.0],
                period: 4.0,
                phase: 0.0,
            },
            2,
        )
        .unwrap();
        // sin(2π·1/4) = 1: u_1 = 1 + 3.
        assert!((s.u(1, 0) - 4.0).abs() < 1e-12 && (s.u(0, 0) - 1.0).abs() < 1e-12);
        let l = Control::new(b.clone(), Schedule::List(vec![vec![1.0], vec![-1.0]]), 2).unwrap();
        assert_eq!(
            (l.u(0, 0), l.u(1, 0), l.u(2, 0), l.u(5, 0)),
            (1.0, -1.0, 1.0, -1.0)
        );
        let err = |r: Result<Control, SpecError>| r.unwrap_err().to_string();
        assert!(err(Control::new(
            b.clone(),
            Schedule::Constant(vec![1.0, 2.0]),
            2
        ))
        .contains("control.u.value"));
        assert!(
            err(Control::new(b.clone(), Schedule::Constant(vec![1.0]), 3)).contains("control.b")
        );
        assert!(
            err(Control::new(b.clone(), Schedule::List(vec![]), 2)).contains("control.u.values")
        );
        // 0, and a subnormal period whose 2πk/period overflows (it was blamed on
        // `initial.cov`).
        for period in [0.0, 1e-320] {
            assert!(err(Control::new(
                b.clone(),
                Schedule::Sinusoid {
                    offset: vec![0.0],
                    amplitude: vec![1.0],
                    period,
                    phase: 0.0
                },
                2
            ))
            .contains("control.u.period"));
        }
    }
}
