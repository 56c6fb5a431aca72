//! Every estimator through the one [`Estimator`] interface: the same results as the filters'
//! own `step(model, k, y)`, and what a [`Packet::Lost`] does — prediction only for the
//! linear-Gaussian filters of seed 001, `γ = 0` (like a withheld packet) for seed 003, and
//! for now like a dropped packet for the Tobit filters of seed 004.

use estimator_core::filter::coupled_kf::Linearisation;
use estimator_core::filter::nn::NnBoundConfig;
use estimator_core::filter::time_update::predict;
use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
use estimator_core::filter::{
    AssumedDensityFilter, CoupledNoiseKf, CrossCoupledEstimator, IntermittentKalmanFilter,
    KalmanFilter, KfIo, TobitFilter, TobitFusion,
};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearModel;
use estimator_core::papers::{Seed001Example, Seed003Example, Seed003Nn};
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::{Error, Estimate, Estimator, OnModel, Packet};
use nalgebra::{matrix, vector, SMatrix, SVector};

type Seed001Model = LinearModel<f64, 3, 3, 2, 2>;

fn seed001() -> Seed001Model {
    Seed001Example::model().unwrap()
}

/// The prediction to instant `k` alone, as the seed 001 filters form it.
fn predicted(
    m: &Seed001Model,
    k: usize,
    e: &Estimate<f64, 3>,
) -> (SVector<f64, 3>, SMatrix<f64, 3, 3>) {
    predict(m, k, e.state(), e.covariance()).unwrap()
}

/// Runs `e` over instants `1..` of `ys`.
fn run<E: Estimator<f64, NX>, const NX: usize>(e: &mut E, ys: &[E::Measurement]) {
    for (k, y) in ys.iter().enumerate() {
        e.step(k + 1, y).unwrap();
    }
}

const Y: [SVector<f64, 2>; 3] = [
    SVector::<f64, 2>::new(30.0, 10.0),
    SVector::<f64, 2>::new(31.0, 11.0),
    SVector::<f64, 2>::new(33.0, 9.0),
];

#[test]
fn kalman_filter_owned_or_borrowed_model_is_its_own_step() {
    let m = seed001();
    let kf = KalmanFilter::new(Seed001Example::x0(), Seed001Example::p0()).unwrap();
    let mut split = kf;
    let mut borrowed = OnModel::new(&m, kf);
    let mut owned = OnModel::new(m, kf);
    for (k, y) in Y.iter().enumerate() {
        split.step(&m, k + 1, y).unwrap();
        borrowed.step(k + 1, y).unwrap();
        owned.step(k + 1, y).unwrap();
    }
    assert_eq!(borrowed.estimate(), split.estimate());
    assert_eq!(owned.filter, split);
    let before = owned;
    assert!(owned.step(4, &vector![f64::NAN, 0.0]).is_err());
    assert_eq!(owned, before);
}

#[test]
fn intermittent_kf_lost_and_dropped_are_both_prediction() {
    let m = seed001();
    let ikf = IntermittentKalmanFilter::new(Seed001Example::x0(), Seed001Example::p0()).unwrap();
    let mut lost = OnModel::new(&m, ikf);
    let mut dropped = OnModel::new(&m, ikf);
    run(&mut lost, &[Packet::Delivered(Y[0]), Packet::Lost]);
    run(&mut dropped, &[Packet::Delivered(Y[0]), Packet::Dropped]);
    assert_eq!(lost.filter, dropped.filter);
    let mut kf = KalmanFilter::new(Seed001Example::x0(), Seed001Example::p0()).unwrap();
    kf.step(&m, 1, &Y[0]).unwrap();
    kf.predict(&m, 1).unwrap();
    assert_eq!(lost.estimate(), kf.estimate());
    assert_eq!(lost.filter.counts(), (1, 1));
}

#[test]
fn cce_lost_is_prediction_and_dropped_is_the_dropout_update() {
    let m = seed001();
    let gsum = GaussSum::<f64, 1, 15>::uniform().unwrap();
    let x0 = vector![18.0, 1.0, 0.5];
    let cce = CrossCoupledEstimator::new(
        x0,
        Seed001Example::p0(),
        Seed001Example::occlusion().unwrap(),
        &gsum,
    )
    .unwrap();
    let mut e = OnModel::new(&m, cce);
    e.step(1, &Packet::Dropped).unwrap();
    let mut split = cce;
    let label = split.step::<2, _>(&m, 1, None).unwrap();
    assert_eq!(e.filter, split);
    assert_eq!(e.filter.label(), label);
    assert!(label > 0);
    let before = e.filter;
    let want = predicted(&m, 2, e.estimate());
    e.step(2, &Packet::Lost).unwrap();
    assert_eq!(e.estimate().into_parts(), want);
    assert_eq!(e.filter.label(), before.label());
    assert_eq!(e.filter.region_log_weights(), before.region_log_weights());
    let mut dropped = OnModel::new(&m, before);
    dropped.step(2, &Packet::Dropped).unwrap();
    assert_ne!(dropped.estimate(), e.estimate());
}

#[test]
fn adf_lost_is_prediction() {
    let m = seed001();
    let adf = AssumedDensityFilter::new(
        vector![18.0, 1.0, 0.5],
        Seed001Example::p0(),
        Seed001Example::occlusion().unwrap(),
    )
    .unwrap();
    let mut e = OnModel::new(&m, adf);
    run(&mut e, &[Packet::Delivered(Y[0]), Packet::Dropped]);
    let mut split = adf;
    split.step(&m, 1, Some(&Y[0])).unwrap();
    split.step::<2, _>(&m, 2, None).unwrap();
    assert_eq!(e.filter, split);
    let want = predicted(&m, 3, e.estimate());
    e.step(3, &Packet::Lost).unwrap();
    assert_eq!(e.estimate().into_parts(), want);
    assert_eq!(e.filter.label(), split.label());
    assert_eq!(e.filter.region_log_probs(), split.region_log_probs());
    let mut dropped = OnModel::new(&m, split);
    dropped.step(3, &Packet::Dropped).unwrap();
    assert_ne!(dropped.estimate(), e.estimate());
}

#[test]
fn kf_io_lost_is_prediction() {
    let m = seed001();
    let f = KfIo::new(
        vector![18.0, 1.0, 0.5],
        Seed001Example::p0(),
        Seed001Example::occlusion().unwrap(),
    )
    .unwrap();
    let mut e = OnModel::new(&m, f);
    run(&mut e, &[Packet::Delivered(Y[0]), Packet::Dropped]);
    let mut split = f;
    split.step(&m, 1, Some(&Y[0])).unwrap();
    split.step::<2, _>(&m, 2, None).unwrap();
    assert_eq!(e.filter, split);
    let want = predicted(&m, 3, e.estimate());
    e.step(3, &Packet::Lost).unwrap();
    assert_eq!(e.estimate().into_parts(), want);
    assert_eq!(e.filter.arrival_prob(), split.arrival_prob());
    let mut dropped = OnModel::new(&m, split);
    dropped.step(3, &Packet::Dropped).unwrap();
    assert_ne!(dropped.estimate(), e.estimate());
}

#[test]
fn nn_estimator_lost_is_withheld_and_counts_its_instants() {
    let nn = Seed003Nn::<f64>::seed003(NnBoundConfig::seed003_example()).unwrap();
    let y = vector![0.7, -0.3];
    let mut lost = OnModel::new(Seed003Example, nn);
    let mut dropped = OnModel::new(&Seed003Example, nn);
    run(
        &mut lost,
        &[Packet::Delivered(y), Packet::Lost, Packet::Delivered(y)],
    );
    run(
        &mut dropped,
        &[Packet::Delivered(y), Packet::Dropped, Packet::Delivered(y)],
    );
    assert_eq!(lost.filter, dropped.filter);
    let mut split = nn;
    split.step(&Seed003Example, Some(&y)).unwrap();
    split.step(&Seed003Example, None).unwrap();
    split.step(&Seed003Example, Some(&y)).unwrap();
    assert_eq!(lost.filter, split);
    let before = lost;
    for k in [3, 5, 0] {
        assert_eq!(
            lost.step(k, &Packet::Lost),
            Err(Error::OutOfOrder {
                expected: 4,
                got: k
            })
        );
    }
    assert_eq!(lost, before);
    lost.step(4, &Packet::Lost).unwrap();
    assert_eq!(lost.filter.instant(), 4);
}

#[test]
fn coupled_kf_lost_is_withheld_and_counts_its_instants() {
    let kf = CoupledNoiseKf::<f64, 3, 1, 2>::new(
        Seed003Example::xhat0(),
        Seed003Example::p0(),
        matrix![0.1],
        Linearisation::Ekf,
    )
    .unwrap();
    let y = vector![0.7, -0.3];
    let mut lost = OnModel::new((Seed003Example, Seed003Example), kf);
    let mut dropped = OnModel::new((&Seed003Example, &Seed003Example), kf);
    run(
        &mut lost,
        &[Packet::Delivered(y), Packet::Lost, Packet::Delivered(y)],
    );
    run(
        &mut dropped,
        &[Packet::Delivered(y), Packet::Dropped, Packet::Delivered(y)],
    );
    assert_eq!(lost.filter, dropped.filter);
    let mut split = kf;
    split
        .step(&Seed003Example, &Seed003Example, Some(&y))
        .unwrap();
    split.step(&Seed003Example, &Seed003Example, None).unwrap();
    split
        .step(&Seed003Example, &Seed003Example, Some(&y))
        .unwrap();
    assert_eq!(lost.filter, split);
    let before = lost;
    assert_eq!(
        lost.step(3, &Packet::Delivered(y)),
        Err(Error::OutOfOrder {
            expected: 4,
            got: 3
        })
    );
    assert_eq!(lost, before);
}

type Oscillator = LinearModel<f64, 2, 2, 2, 2>;

/// Seed 004's shape: a rotation observed in both components, independent noise.
fn oscillator() -> Oscillator {
    let w = 0.052 * core::f64::consts::PI;
    let b = vector![0.16, 0.18];
    LinearModel::new(
        matrix![w.cos(), w.sin(); -w.sin(), w.cos()],
        SMatrix::identity(),
        SMatrix::identity(),
        SMatrix::identity(),
        b * b.transpose() * 0.05 + SMatrix::identity() * 1e-6,
        matrix![0.5, 0.0; 0.0, 0.5],
    )
    .unwrap()
}

fn tobit_cfg(sigma: f64, lambda: f64) -> TobitFilterConfig<f64, 2> {
    TobitFilterConfig::new(
        vector![0.0, 0.0],
        BoundScalars::paper_example(),
        EventTriggerConfig::new_allowing_paper_violation(sigma, 5.0, lambda, 1.5).unwrap(),
        1.5,
        2.0,
    )
    .unwrap()
}

#[test]
fn tobit_filter_lost_is_provisionally_dropped() {
    let m = oscillator();
    let f = TobitFilter::new(tobit_cfg(0.1, 0.1), vector![5.0, 0.0], SMatrix::identity()).unwrap();
    let y = vector![4.8, 0.2];
    let mut lost = OnModel::new(&m, f);
    let mut dropped = OnModel::new(&m, f);
    run(&mut lost, &[Packet::Delivered(y), Packet::Lost]);
    run(&mut dropped, &[Packet::Delivered(y), Packet::Dropped]);
    assert_eq!(lost.filter, dropped.filter);
    let mut split = f;
    split.step_model(&m, 1, 1.0, Some(&y)).unwrap();
    split.step_model(&m, 2, 1.0, None).unwrap();
    assert_eq!(lost.filter, split);
    assert_eq!(lost.filter.last_theta(), 1.0);
}

#[test]
fn tobit_fusion_takes_per_node_packets() {
    let models = [oscillator(); 3];
    let f = TobitFusion::<f64, 2, 2, 3>::new(
        [
            tobit_cfg(0.1, 0.1),
            tobit_cfg(0.2, 0.2),
            tobit_cfg(0.3, 0.1),
        ],
        vector![5.0, 0.0],
        SMatrix::identity(),
    )
    .unwrap();
    let y = vector![4.8, 0.2];
    let mut lost = OnModel::new(models, f);
    let mut dropped = OnModel::new(models, f);
    lost.step(
        1,
        &[Packet::Delivered(y), Packet::Lost, Packet::Delivered(y)],
    )
    .unwrap();
    dropped
        .step(
            1,
            &[Packet::Delivered(y), Packet::Dropped, Packet::Delivered(y)],
        )
        .unwrap();
    assert_eq!(lost.filter, dropped.filter);
    let mut split = f;
    split
        .step_models(&models, 1, [Some(&y), None, Some(&y)])
        .unwrap();
    assert_eq!(lost.filter, split);
    assert_eq!(lost.estimate(), split.estimate());
}
