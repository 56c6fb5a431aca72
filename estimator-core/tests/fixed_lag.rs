//! [`FixedLag`]: packets up to `L` instants late give, once they are in, the estimate the
//! on-time stream gives, bit for bit, for every estimator of the core (IKF, the Kalman filter
//! on packets, CCE, ADF, KF-IO, the NN estimator, the Tobit fusion), in `f64` and `f32`;
//! older packets are counted and dropped (the estimate is then the one of a stream where they
//! were lost); an error leaves everything as it was.

use estimator_core::filter::nn::NnBoundConfig;
use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
use estimator_core::filter::{
    AssumedDensityFilter, CrossCoupledEstimator, IntermittentKalmanFilter, KfIo, TobitFusion,
};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearModel;
use estimator_core::papers::{Seed001Example, Seed003Example, Seed003Nn};
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::{
    Error, Estimate, Estimator, FixedLag, LostMeasurement, OnModel, Packet, Real, Result, Revise,
    Revision,
};
use nalgebra::{matrix, vector, SMatrix, SVector};

/// A small deterministic generator (SplitMix64): the test streams need no statistics, only
/// reproducible variety.
struct Mix(u64);

impl Mix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.unit().max(1e-300), self.unit());
        (-2.0 * u.ln()).sqrt() * (core::f64::consts::TAU * v).cos()
    }
}

/// A measurement made of parts that can arrive separately (one per node).
trait Parts: Clone + Revise + LostMeasurement {
    const N: usize;
    /// Only part `i`, the others lost.
    fn only(&self, i: usize) -> Self;
    /// Part `i` lost.
    fn lose(&mut self, i: usize);
}

impl<T: Real, const NY: usize> Parts for Packet<T, NY> {
    const N: usize = 1;
    fn only(&self, _i: usize) -> Self {
        *self
    }
    fn lose(&mut self, _i: usize) {
        *self = Packet::Lost;
    }
}

impl<T: Real, const NY: usize, const L: usize> Parts for [Packet<T, NY>; L] {
    const N: usize = L;
    fn only(&self, i: usize) -> Self {
        core::array::from_fn(|m| if m == i { self[m] } else { Packet::Lost })
    }
    fn lose(&mut self, i: usize) {
        self[i] = Packet::Lost;
    }
}

/// Delays of every (instant, part): 0 on time, else `1..=max` instants late with probability
/// `p_late`.
fn delays(n: usize, parts: usize, p_late: f64, max: usize, seed: u64) -> Vec<Vec<usize>> {
    let mut g = Mix(seed);
    (0..n)
        .map(|_| {
            (0..parts)
                .map(|_| {
                    if g.unit() < p_late {
                        1 + (g.next() % max as u64) as usize
                    } else {
                        0
                    }
                })
                .collect()
        })
        .collect()
}

/// What a lagged run saw.
#[derive(Debug, Default)]
struct Seen {
    /// Instants at which every part of every instant so far had arrived (and was compared).
    compared: usize,
    folded: u32,
    too_old: u32,
}

/// Runs `ys` (instants 1..) on time through `make()`, and with the parts delayed by `delay`
/// through `FixedLag<_, _, LAG>`: a part `d` late arrives after instant `k + d − 1` was stepped.
/// Whenever every part of the instants so far is in, the lagged estimate must equal the on-time
/// one bit for bit, and so must every instant still in the history. Parts later than `LAG` are
/// too old: the on-time reference then has them lost.
fn check<T, const NX: usize, E, const LAG: usize>(
    make: impl Fn() -> E,
    ys: &[E::Measurement],
    delay: &[Vec<usize>],
) -> Seen
where
    T: Real,
    E: Estimator<T, NX> + Clone,
    E::Measurement: Parts,
{
    // The reference: what arrives within the lag, on time; what arrives later, or after the
    // last instant, lost.
    let mut reference = ys.to_vec();
    let n = ys.len();
    for (k, y) in reference.iter_mut().enumerate() {
        for i in 0..E::Measurement::N {
            let d = delay[k][i];
            if d > LAG || k + d > n {
                y.lose(i);
            }
        }
    }
    let mut on_time = make();
    let mut after: Vec<E> = Vec::new();
    for (k, y) in reference.iter().enumerate() {
        on_time
            .step(k + 1, y)
            .unwrap_or_else(|e| panic!("on-time step {}: {e}", k + 1));
        after.push(on_time.clone());
    }

    let mut lagged = FixedLag::<E, E::Measurement, LAG>::new(make());
    let mut seen = Seen::default();
    let n = ys.len();
    for k in 1..=n {
        {
            let mut y = ys[k - 1].clone();
            for i in 0..E::Measurement::N {
                if delay[k - 1][i] > 0 {
                    y.lose(i);
                }
            }
            lagged.step(k, &y).expect("lagged step");
        }
        // The parts arriving now, oldest first.
        for j in (1..=k.min(n)).rev() {
            for i in 0..E::Measurement::N {
                let d = delay[j - 1][i];
                if d > 0 && j + d - 1 == k {
                    let late = ys[j - 1].only(i);
                    match lagged.fold_in(j, &late) {
                        Ok(Revision::Folded { from, restepped }) => {
                            assert_eq!(from, j);
                            assert_eq!(restepped, k.min(n) - j + 1);
                        }
                        Ok(Revision::Unchanged) => {
                            assert!(late.clone().revise(&late) == 0 || d > LAG)
                        }
                        Err(Error::TooLate { got, .. }) => {
                            assert_eq!(got, j);
                            assert!(d > LAG, "a part {d} late refused with lag {LAG}");
                        }
                        Err(e) => panic!("fold of instant {j} at {k}: {e}"),
                    }
                }
            }
        }
        let newest = k.min(n);
        let all_in = (1..=newest).all(|j| {
            (0..E::Measurement::N).all(|i| {
                let d = delay[j - 1][i];
                d == 0 || d > LAG || j + d - 1 <= k || j + d - 1 > n
            })
        });
        if all_in {
            assert_eq!(
                lagged.estimate(),
                after[newest - 1].estimate(),
                "lag {LAG}: instant {newest} after the arrivals of {k}"
            );
            for j in newest.saturating_sub(LAG).max(1)..newest {
                if let Some(e) = lagged.after(j) {
                    assert_eq!(e.estimate(), after[j - 1].estimate(), "history at {j}");
                }
            }
            seen.compared += 1;
        }
    }
    seen.folded = lagged.counts().folded;
    seen.too_old = lagged.counts().too_old;
    seen
}

/// Seed 001's plant and its sensor, with occlusion-like dropouts: packets delivered, dropped
/// (20 %) or lost (5 %).
fn seed001_stream<T: Real>(n: usize, seed: u64) -> Vec<Packet<T, 2>> {
    let m = Seed001Example::model::<f64>().unwrap();
    let mut g = Mix(seed);
    let mut x: SVector<f64, 3> = Seed001Example::x0();
    (0..n)
        .map(|_| {
            x = m.a * x + SVector::<f64, 3>::from_fn(|_, _| 0.5 * g.normal());
            let y = m.c * x + SVector::<f64, 2>::from_fn(|_, _| g.normal());
            match g.unit() {
                u if u < 0.20 => Packet::Dropped,
                u if u < 0.25 => Packet::Lost,
                _ => Packet::Delivered(y.map(T::lit)),
            }
        })
        .collect()
}

const N: usize = 300;

fn seed001_all<T: Real>() {
    let model = Seed001Example::model::<T>().unwrap();
    let (x0, p0) = (Seed001Example::x0::<T>(), Seed001Example::p0::<T>());
    let occ = Seed001Example::occlusion::<T>().unwrap();
    let ys = seed001_stream::<T>(N, 1);
    let d = delays(N, 1, 0.3, 3, 2);
    let ikf = || OnModel::<_, _, 2>::new(&model, IntermittentKalmanFilter::new(x0, p0).unwrap());
    let g = GaussSum::<T, 1, 15>::uniform().unwrap();
    let cce =
        || OnModel::<_, _, 2>::new(&model, CrossCoupledEstimator::new(x0, p0, occ, &g).unwrap());
    let adf = || OnModel::<_, _, 2>::new(&model, AssumedDensityFilter::new(x0, p0, occ).unwrap());
    let kf_io = || OnModel::<_, _, 2>::new(&model, KfIo::new(x0, p0, occ).unwrap());
    let runs = [
        ("ikf", check::<T, 3, _, 3>(ikf, &ys, &d)),
        ("cce", check::<T, 3, _, 3>(cce, &ys, &d)),
        ("adf", check::<T, 3, _, 3>(adf, &ys, &d)),
        ("kf-io", check::<T, 3, _, 3>(kf_io, &ys, &d)),
    ];
    for (name, seen) in runs {
        // 30 % late: the stream is not trivially on time, and complete often enough to compare.
        assert!(seen.folded > 40, "{name}: {seen:?}");
        assert!(seen.compared > N / 5, "{name}: {seen:?}");
        assert_eq!(seen.too_old, 0, "{name}");
    }
}

#[test]
fn seed001_estimators_late_within_the_lag_equal_on_time_f64() {
    seed001_all::<f64>();
}

#[test]
fn seed001_estimators_late_within_the_lag_equal_on_time_f32() {
    seed001_all::<f32>();
}

#[test]
fn packets_later_than_the_lag_are_dropped_as_lost() {
    let model = Seed001Example::model::<f64>().unwrap();
    let (x0, p0) = (Seed001Example::x0(), Seed001Example::p0());
    let occ = Seed001Example::occlusion().unwrap();
    let ys = seed001_stream::<f64>(N, 3);
    let d = delays(N, 1, 0.3, 6, 4);
    let adf = || OnModel::<_, _, 2>::new(&model, AssumedDensityFilter::new(x0, p0, occ).unwrap());
    let seen = check::<f64, 3, _, 2>(adf, &ys, &d);
    assert!(seen.too_old > 20 && seen.folded > 10, "{seen:?}");
    // L = 0 keeps nothing: every late part is too old, and the steps are the estimator's own.
    let seen = check::<f64, 3, _, 0>(adf, &ys, &d);
    assert_eq!(seen.folded, 0);
    assert!(seen.too_old > 50, "{seen:?}");
}

fn nn_all<T: Real>() {
    use estimator_core::filter::nn::{CoupledNoiseSystem, DifferentiableMap};
    // Seed 003's plant without noise (as tests/nn_seed003.rs runs it), a configuration whose
    // bound stays in f32's range (δ₁ < 1), and 40 instants (at k = 44 f32 cannot resolve the
    // gain system); the sensor withholds at random (the token bucket's dropouts) and the link
    // loses a few.
    const N: usize = 40;
    let sys = Seed003Example;
    let mut g = Mix(5);
    let mut x = Seed003Example::x0::<T>();
    let ys: Vec<Packet<T, 2>> = (0..N)
        .map(|k| {
            x = CoupledNoiseSystem::<T, 3, 1, 2>::a(&sys, k) * x + sys.eval(&x);
            let y = CoupledNoiseSystem::<T, 3, 1, 2>::c(&sys, k + 1) * x;
            match g.unit() {
                u if u < 0.3 => Packet::Dropped,
                u if u < 0.35 => Packet::Lost,
                _ => Packet::Delivered(y),
            }
        })
        .collect();
    let d = delays(N, 1, 0.3, 3, 6);
    let nn = || {
        let cfg = NnBoundConfig::<T>::new(
            [T::lit(0.5); 4],
            [T::lit(0.5); 12],
            [T::lit(0.05), T::lit(10.0)],
            T::lit(8.0),
            T::lit(1.8),
            T::lit(0.1),
            T::lit(0.1),
        )
        .unwrap();
        OnModel::<_, _, 2>::new(Seed003Example, Seed003Nn::<T>::seed003(cfg).unwrap())
    };
    let seen = check::<T, 3, _, 3>(nn, &ys, &d);
    assert!(seen.folded > 5 && seen.compared > N / 5, "{seen:?}");
}

#[test]
fn nn_estimator_late_within_the_lag_equals_on_time() {
    nn_all::<f64>();
    nn_all::<f32>();
}

fn oscillator<T: Real>() -> LinearModel<T, 2, 2, 2, 2> {
    let w = 0.052 * core::f64::consts::PI;
    let b = vector![0.16, 0.18];
    LinearModel::new(
        matrix![w.cos(), w.sin(); -w.sin(), w.cos()].map(T::lit),
        SMatrix::identity(),
        SMatrix::identity(),
        SMatrix::identity(),
        (b * b.transpose() * 0.05 + SMatrix::<f64, 2, 2>::identity() * 1e-6).map(T::lit),
        matrix![0.5, 0.0; 0.0, 0.5].map(T::lit),
    )
    .unwrap()
}

fn tobit_cfg<T: Real>(sigma: f64, lambda: f64) -> TobitFilterConfig<T, 2> {
    TobitFilterConfig::new(
        SVector::zeros(),
        BoundScalars::paper_example(),
        EventTriggerConfig::new_allowing_paper_violation(
            T::lit(sigma),
            T::lit(5.0),
            T::lit(lambda),
            T::lit(1.5),
        )
        .unwrap(),
        T::lit(1.5),
        T::lit(2.0),
    )
    .unwrap()
}

fn tobit_all<T: Real>() {
    let models = [oscillator::<T>(); 3];
    let fusion = || {
        let f = TobitFusion::<T, 2, 2, 3>::new(
            [
                tobit_cfg(0.1, 0.1),
                tobit_cfg(0.2, 0.2),
                tobit_cfg(0.3, 0.1),
            ],
            vector![T::lit(5.0), T::lit(0.0)],
            SMatrix::identity(),
        )
        .unwrap();
        OnModel::<_, _, 2>::new(models, f)
    };
    let m = oscillator::<f64>();
    let mut g = Mix(7);
    let mut x = vector![5.0, 0.0];
    let ys: Vec<[Packet<T, 2>; 3]> = (0..N)
        .map(|_| {
            x = m.a * x + vector![0.16, 0.18] * 0.2 * g.normal();
            core::array::from_fn(|_| match g.unit() {
                u if u < 0.3 => Packet::Dropped,
                u if u < 0.33 => Packet::Lost,
                // The sensor censors below τ = 0 (seed 004's Tobit sensor).
                _ => Packet::Delivered(
                    (x + vector![g.normal(), g.normal()] * 0.1).map(|v| T::lit(v.max(0.0))),
                ),
            })
        })
        .collect();
    let d = delays(N, 3, 0.3, 3, 8);
    let seen = check::<T, 2, _, 3>(fusion, &ys, &d);
    assert!(seen.folded > 100 && seen.compared > 10, "{seen:?}");
}

#[test]
fn tobit_fusion_late_within_the_lag_equals_on_time() {
    tobit_all::<f64>();
    tobit_all::<f32>();
}

/// A scalar running sum that refuses a step whose sum would pass `limit`: a late value can
/// make a later instant's re-step fail.
#[derive(Clone, Debug, PartialEq)]
struct Sum {
    limit: f64,
    est: Estimate<f64, 1>,
}

impl Estimator<f64, 1> for Sum {
    type Measurement = Packet<f64, 1>;
    fn step(&mut self, _k: usize, y: &Packet<f64, 1>) -> Result<()> {
        let s = self.est.state()[0] + y.delivered().map_or(0.0, |v| v[0]);
        if !s.is_finite() || s > self.limit {
            return Err(Error::Numerical {
                what: "sum over the limit",
            });
        }
        self.est = Estimate::new(vector![s], matrix![1.0]).unwrap();
        Ok(())
    }
    fn estimate(&self) -> &Estimate<f64, 1> {
        &self.est
    }
}

#[test]
fn a_refused_refold_leaves_estimator_and_history_as_they_were() {
    let sum = Sum {
        limit: 10.0,
        est: Estimate::new(vector![0.0], matrix![1.0]).unwrap(),
    };
    let mut lag = FixedLag::<Sum, Packet<f64, 1>, 4>::new(sum);
    let one = Packet::Delivered(vector![1.0]);
    for (k, y) in [one, Packet::Lost, one, one, one].iter().enumerate() {
        lag.step(k + 1, y).unwrap();
    }
    assert_eq!(lag.estimate().state()[0], 4.0);
    let before = lag.clone();
    let history = |l: &FixedLag<Sum, Packet<f64, 1>, 4>| {
        (2..=5).map(|k| l.after(k).cloned()).collect::<Vec<_>>()
    };
    // Instant 2's late value passes the limit at instant 4 of the re-step (1 + 7 + 1 + 1 = 10
    // at 4 is fine, 11 at 5 is not): refused, and everything is as it was.
    let err = lag
        .fold_in(2, &Packet::Delivered(vector![7.0]))
        .unwrap_err();
    assert!(matches!(err, Error::Numerical { .. }));
    assert_eq!(lag.estimate(), before.estimate());
    assert_eq!(history(&lag), history(&before));
    assert_eq!(lag.counts().refused, 1);
    // A NaN refused at its own instant.
    assert!(lag
        .fold_in(2, &Packet::Delivered(vector![f64::NAN]))
        .is_err());
    assert_eq!(history(&lag), history(&before));
    // A value that fits is folded in: 1 + 5 + 1 + 1 + 1.
    assert_eq!(
        lag.fold_in(2, &Packet::Delivered(vector![5.0])).unwrap(),
        Revision::Folded {
            from: 2,
            restepped: 4
        }
    );
    assert_eq!(lag.estimate().state()[0], 9.0);
    // The same part again, or a part of an instant already known: nothing new.
    assert_eq!(
        lag.fold_in(2, &Packet::Delivered(vector![5.0])).unwrap(),
        Revision::Unchanged
    );
    assert_eq!(
        lag.fold_in(3, &Packet::Delivered(vector![1.0])).unwrap(),
        Revision::Unchanged
    );
    // Not yet stepped, or older than the lag.
    assert!(matches!(
        lag.fold_in(6, &one),
        Err(Error::OutOfOrder { .. })
    ));
    assert_eq!(lag.oldest_revisable(), Some(2));
    assert_eq!(
        lag.fold_in(1, &one),
        Err(Error::TooLate { oldest: 2, got: 1 })
    );
    // A step for an instant already stepped is out of order (a late packet is folded in).
    assert!(matches!(
        lag.step(5, &one),
        Err(Error::OutOfOrder {
            expected: 6,
            got: 5
        })
    ));
}

#[test]
fn a_gap_is_stepped_as_lost_and_its_instants_can_be_revised() {
    let model = Seed001Example::model::<f64>().unwrap();
    let (x0, p0) = (Seed001Example::x0(), Seed001Example::p0());
    let ikf = || OnModel::<_, _, 2>::new(&model, IntermittentKalmanFilter::new(x0, p0).unwrap());
    let y = |v: f64| Packet::Delivered(vector![30.0 + v, 10.0 - v]);
    let mut lag = FixedLag::<_, _, 3>::new(ikf());
    lag.step(1, &y(0.0)).unwrap();
    lag.step(5, &y(1.0)).unwrap(); // 2, 3, 4 never came
    let mut on_time = ikf();
    for (k, p) in [y(0.0), Packet::Lost, Packet::Lost, y(0.5), y(1.0)]
        .iter()
        .enumerate()
    {
        on_time.step(k + 1, p).unwrap();
    }
    assert_ne!(lag.estimate(), on_time.estimate());
    assert_eq!(lag.oldest_revisable(), Some(3));
    lag.fold_in(4, &y(0.5)).unwrap();
    assert_eq!(lag.estimate(), on_time.estimate());
    assert!(matches!(
        lag.fold_in(2, &y(0.5)),
        Err(Error::TooLate { oldest: 3, got: 2 })
    ));
}
