//! An estimator with or without the core's fixed-lag history ([`FixedLag`], docs/pipeline.md
//! "Late packets"): `--lag 0` steps the estimator itself, exactly as without this layer; a lag
//! `L > 0` keeps the last [`MAX_LAG`] instants and folds in a late slot up to `L` instants
//! late.

use estimator_core::{Estimator, FixedLag, LostMeasurement, Revise, Revision};

use crate::LateFold;

/// The longest `--lag` (instants): the history every lagged estimator keeps. A longer lag
/// would only help a link that delays by more than this many sampling periods, where waiting
/// (`--instant-deadline-ms`) is the better trade.
pub const MAX_LAG: u32 = 16;

/// An estimator `X` on measurements `M`, with the history of `--lag L` when `L > 0`.
#[derive(Clone, Debug)]
pub(crate) enum Lagged<X, M> {
    /// `--lag 0`: no history.
    Off(X),
    /// A history of [`MAX_LAG`] instants, folding in what is at most `lag` late.
    On {
        est: Box<FixedLag<X, M, { MAX_LAG as usize }>>,
        lag: u32,
    },
}

impl<X, M> Lagged<X, M> {
    /// `x` with the history of `lag` (`0`: none; at most [`MAX_LAG`]).
    pub(crate) fn new(x: X, lag: u32) -> Self {
        match lag.min(MAX_LAG) {
            0 => Self::Off(x),
            lag => Self::On {
                est: Box::new(FixedLag::new(x)),
                lag,
            },
        }
    }

    /// The estimator after the newest instant.
    pub(crate) fn inner(&self) -> &X {
        match self {
            Self::Off(x) => x,
            Self::On { est, .. } => est.inner(),
        }
    }
}

impl<X: Clone, M> Lagged<X, M> {
    /// From now on, the history of `lag` (`0`: none). The history starts empty: call before
    /// the first step.
    pub(crate) fn set_lag(&mut self, lag: u32) {
        *self = Self::new(self.inner().clone(), lag);
    }
}

impl<X, M> Lagged<X, M>
where
    X: Clone,
    M: Clone + LostMeasurement + Revise,
{
    /// Steps instant `k`.
    pub(crate) fn step<const NX: usize>(&mut self, k: usize, y: &M) -> estimator_core::Result<()>
    where
        X: Estimator<f64, NX, Measurement = M>,
    {
        match self {
            Self::Off(x) => x.step(k, y),
            Self::On { est, .. } => est.step(k, y),
        }
    }

    /// Folds `late`, a part of instant `k` that arrived after it was stepped, into the history.
    pub(crate) fn fold<const NX: usize>(&mut self, k: usize, late: &M) -> LateFold
    where
        X: Estimator<f64, NX, Measurement = M>,
    {
        let Self::On { est, lag } = self else {
            return LateFold::TooOld;
        };
        match est.newest() {
            Some(newest) if k <= newest && newest - k < *lag as usize => {}
            _ => return LateFold::TooOld,
        }
        match est.fold_in(k, late) {
            Ok(Revision::Folded { .. }) => LateFold::Folded,
            Ok(Revision::Unchanged) => LateFold::Unchanged,
            Err(
                estimator_core::Error::TooLate { .. } | estimator_core::Error::OutOfOrder { .. },
            ) => LateFold::TooOld,
            Err(_) => LateFold::Refused,
        }
    }
}

#[cfg(test)]
mod tests {
    use estpipe_wire::{Observation, FLAG_IPC_LOST};

    use crate::{build_all, BuildOptions, RunStart, FACTORIES};
    use crate::{Estimator, LateFold};

    /// Every estimator's estimate and covariance.
    fn state(ests: &[Box<dyn Estimator>], nx: usize) -> Vec<(&'static str, Vec<u64>)> {
        ests.iter()
            .map(|e| {
                let (mut x, mut p) = (vec![0.0; nx], vec![0.0; nx * nx]);
                e.estimate(&mut x);
                e.covariance(&mut p);
                let bits = x.iter().chain(&p).map(|v| v.to_bits()).collect();
                (e.name(), bits)
            })
            .collect()
    }

    /// The application's estimators of the four presets (every one that runs on slots, gated
    /// or not) with `--lag 3`: slots 1-3 instants late give, once they are in, the estimates
    /// (and covariances) of the on-time stream bit for bit; on time, `--lag 3` is `--lag 0`.
    #[test]
    fn late_slots_within_the_lag_give_the_on_time_estimates() {
        for (preset, gate) in [
            ("linear", None),
            ("occlusion", Some(0.99)),
            ("occlusion", None),
            ("nn-token-bucket", None),
            ("tobit-fusion", None),
            ("tobit-fusion", Some(0.99)),
        ] {
            let (spec, mut sim) = crate::presets::preset_run(preset, 3, 1);
            let initial: Option<Vec<Observation>> = sim.initial_observations().map(<[_]>::to_vec);
            let start = RunStart {
                seed: 3,
                run: 1,
                initial: initial.as_deref(),
            };
            let nx = spec.nx();
            let build = |lag: u32| {
                let options = BuildOptions {
                    particles: 0,
                    gate,
                    lag,
                    ..BuildOptions::default()
                };
                let mut all = build_all(FACTORIES, &spec, &options, &start).unwrap();
                all.retain(|e| !e.full_information());
                all
            };
            let (mut plain, mut on_time, mut late) = (build(0), build(3), build(3));
            let t = 150u32;
            let instants: Vec<Vec<Observation>> =
                (0..t).map(|_| sim.next_instant().obs.to_vec()).collect();
            // Delays: 30 % of the slots 1..=3 instants late (a fixed pattern of the test).
            let delay = |k: u32, n: usize| -> u32 {
                let h = (u64::from(k) * 0x9E37_79B9 + n as u64 * 0x85EB_CA6B) % 1000;
                if h < 300 {
                    1 + (h % 3) as u32
                } else {
                    0
                }
            };
            let (mut compared, mut folded) = (0, 0);
            for k in 1..=t {
                let obs = &instants[k as usize - 1];
                let mut with_late = obs.clone();
                for (n, o) in with_late.iter_mut().enumerate() {
                    if delay(k, n) > 0 {
                        *o = Observation::dropped(k, n as u8, o.ny, FLAG_IPC_LOST);
                    }
                }
                for e in plain.iter_mut().chain(on_time.iter_mut()) {
                    let _ = e.step(k, obs);
                }
                for e in late.iter_mut() {
                    let _ = e.step(k, &with_late);
                }
                // What arrives after instant k: the slots of j with j + d − 1 = k.
                for j in k.saturating_sub(3).max(1)..=k {
                    for (n, o) in instants[j as usize - 1].iter().enumerate() {
                        let d = delay(j, n);
                        if d > 0 && j + d - 1 == k {
                            let mut only: Vec<Observation> = instants[j as usize - 1]
                                .iter()
                                .map(|p| Observation::dropped(j, p.node, p.ny, FLAG_IPC_LOST))
                                .collect();
                            only[n] = *o;
                            for e in late.iter_mut() {
                                let r = e.fold_late(j, &only);
                                assert_ne!(
                                    r,
                                    LateFold::TooOld,
                                    "{preset} {}: {j} at {k}",
                                    e.name()
                                );
                                folded += u32::from(r == LateFold::Folded);
                            }
                        }
                    }
                }
                assert_eq!(
                    state(&plain, nx),
                    state(&on_time, nx),
                    "{preset}: --lag 3 on time at {k}"
                );
                let all_in = (k.saturating_sub(2).max(1)..=k).all(|j| {
                    (0..obs.len()).all(|n| {
                        let d = delay(j, n);
                        d == 0 || j + d - 1 <= k
                    })
                });
                if all_in {
                    assert_eq!(
                        state(&late, nx),
                        state(&on_time, nx),
                        "{preset} {gate:?} at {k}"
                    );
                    compared += 1;
                }
            }
            assert!(
                compared > 10 && folded > 20,
                "{preset}: {compared} compared, {folded} folded"
            );
        }
    }
}
