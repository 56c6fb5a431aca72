use super::*;
use crate::estimator::Estimator;
use crate::filter::SequentialKf;
use crate::model::LinearModel;
use crate::packet::Packet;
use crate::protocol::event_trigger::EventTriggerConfig;
use nalgebra::{matrix, vector};

type Model = LinearModel<f64, 2, 2, 2, 2>;

fn model(r: f64) -> Model {
    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let i = SMatrix::<f64, 2, 2>::identity();
    LinearModel::new(a, i, i, i, i * 0.02, i * r).unwrap()
}

fn filter(tau: f64, reads_silence: bool) -> MomentMatchedTobit<f64, 2, 2, 3> {
    let trig = EventTriggerConfig::new_allowing_paper_violation(0.1, 5.0, 0.1, 1.5).unwrap();
    let t = vector![tau, tau];
    let nodes = [TriggerKnowledge::new(trig, t).unwrap(); 3];
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
    let prior = Estimate::new(vector![5.0, 0.0], SMatrix::identity()).unwrap();
    MomentMatchedTobit::new(prior, [t; 3], nodes, bucket, reads_silence).unwrap()
}

fn packets(ys: [Option<SVector<f64, 2>>; 3]) -> TriggeredPackets<f64, 2, 3> {
    TriggeredPackets {
        packets: ys.map(|y| match y {
            Some(y) => Packet::Delivered(y),
            None => Packet::Dropped,
        }),
        level: None,
    }
}

#[test]
fn without_censoring_it_is_the_sequential_kalman_filter() {
    // τ far below every measurement: every component observed, (C1) is the Kalman update, so
    // the filter is the sequential KF of the same nodes (tolerance: rounding of 60 steps).
    let models = [model(0.5), model(0.3), model(0.8)];
    let mut f = filter(-1e3, false);
    let kf0 = KalmanFilter::new(vector![5.0, 0.0], SMatrix::identity()).unwrap();
    let mut kf = SequentialKf::new(models, 3, kf0).unwrap();
    for k in 1..=60usize {
        let s = k as f64;
        let y = |m: usize| {
            vector![
                5.0 * (0.163 * s).cos() + 0.1 * m as f64,
                -5.0 * (0.163 * s).sin()
            ]
        };
        let ys = [
            (k % 2 == 0).then(|| y(0)),
            (k % 3 != 0).then(|| y(1)),
            Some(y(2)),
        ];
        f.step_gated(&models, k, &packets(ys), &InnovationGate::off())
            .unwrap();
        let obs: [Packet<f64, 2>; 3] = ys.map(|y| y.map_or(Packet::Dropped, Packet::Delivered));
        Estimator::step(&mut kf, k, &obs).unwrap();
        assert!(
            (f.estimate().state() - kf.estimate().state()).amax() < 1e-11,
            "k {k}"
        );
        assert!((f.estimate().covariance() - kf.estimate().covariance()).amax() < 1e-11);
    }
}

#[test]
fn censored_packets_move_the_estimate_below_the_threshold() {
    // The prior says x ≈ (5, 0); three nodes report both components censored at τ = 0: the
    // estimate must move below 0 on both axes (within the posterior's spread) and shrink.
    let models = [model(0.5); 3];
    let mut f = filter(0.0, false);
    let tau = Some(vector![0.0, 0.0]);
    f.step_gated(&models, 1, &packets([tau; 3]), &InnovationGate::off())
        .unwrap();
    let (x, p) = f.estimate().into_parts();
    assert!(x[0] < 0.5 && x[1] < 0.0, "{x}");
    assert!(p[(0, 0)] < 1.0 && p[(1, 1)] < 1.0, "{p}");
}

#[test]
fn a_held_silence_is_read_only_when_asked() {
    let models = [model(0.5); 3];
    let y = vector![4.0, 0.5];
    let mut with = filter(0.0, true);
    let mut without = filter(0.0, false);
    for f in [&mut with, &mut without] {
        f.step_gated(&models, 1, &packets([Some(y); 3]), &InnovationGate::off())
            .unwrap();
    }
    // Instant 2: node 0 silent with a token (ξ = 10 − 9 + 5 = 6 ≥ 3·... the mirror decides).
    for f in [&mut with, &mut without] {
        f.step_gated(
            &models,
            2,
            &packets([None, Some(y), Some(y)]),
            &InnovationGate::off(),
        )
        .unwrap();
    }
    assert_eq!(with.counts().held + with.counts().blocked, 1);
    if with.counts().held == 1 {
        assert!(
            with.estimate().covariance().trace() < without.estimate().covariance().trace(),
            "a held silence is information"
        );
    }
    assert_eq!(without.counts().held, 0);
}

#[test]
fn bad_input_changes_nothing() {
    let models = [model(0.5); 3];
    let mut f = filter(0.0, true);
    f.step_gated(
        &models,
        1,
        &packets([Some(vector![4.0, 0.5]); 3]),
        &InnovationGate::off(),
    )
    .unwrap();
    let before = f;
    let bad = packets([Some(vector![f64::NAN, 0.5]), None, None]);
    assert!(f
        .step_gated(&models, 2, &bad, &InnovationGate::off())
        .is_err());
    assert_eq!(f, before);
    let huge = packets([Some(vector![1e308, 1e308]), None, None]);
    let _ = f.step_gated(&models, 2, &huge, &InnovationGate::off());
    assert!(f.estimate().state().iter().all(|v| v.is_finite()));
}

#[test]
fn the_gate_rejects_an_outlier_and_reads_it_as_lost() {
    let models = [model(0.5); 3];
    let gate = InnovationGate::chi2(0.99).unwrap();
    let mut f = filter(0.0, true);
    let counts = f
        .step_gated(
            &models,
            1,
            &packets([Some(vector![400.0, 0.5]), None, None]),
            &gate,
        )
        .unwrap();
    assert_eq!((counts.tested, counts.rejected), (1, 1));
    // Rejected: the node's reference is unknown, as after a loss.
    assert!(f.nodes[0].reference().is_none());
}

#[test]
fn f32_follows_f64() {
    let models = [model(0.5); 3];
    let m32: [LinearModel<f32, 2, 2, 2, 2>; 3] = models.map(|m| m.cast().unwrap());
    let mut f = filter(0.0, true);
    let trig = EventTriggerConfig::new_allowing_paper_violation(0.1f32, 5.0, 0.1, 1.5).unwrap();
    let t = vector![0.0f32, 0.0];
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
    let prior = Estimate::new(vector![5.0f32, 0.0], SMatrix::identity()).unwrap();
    let nodes = [TriggerKnowledge::new(trig, t).unwrap(); 3];
    let mut g = MomentMatchedTobit::new(prior, [t; 3], nodes, bucket, true).unwrap();
    for k in 1..=100usize {
        let s = k as f64;
        let truth = vector![5.0 * (0.163 * s).cos(), -5.0 * (0.163 * s).sin()];
        let y = truth.map(|v: f64| v.max(0.0));
        let ys = [
            (k % 2 == 0).then_some(y),
            (k % 3 == 0).then_some(y),
            (k % 5 != 0).then_some(y),
        ];
        f.step_gated(&models, k, &packets(ys), &InnovationGate::off())
            .unwrap();
        let p32 = TriggeredPackets {
            packets: ys.map(|y| y.map_or(Packet::Dropped, |y| Packet::Delivered(y.cast::<f32>()))),
            level: None,
        };
        g.step_gated(&m32, k, &p32, &InnovationGate::off()).unwrap();
    }
    // Stated tolerance: f32 rounding amplified over 100 steps, on states of size 5.
    let d = (f.estimate().state() - g.estimate().state().cast::<f64>()).amax();
    assert!(d < 1e-3, "{d}");
}
