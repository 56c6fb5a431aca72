//! The estimator step path must not touch the heap: zero allocations over 10 000 steps.
//!
//! One test function per binary section, run sequentially inside one `#[test]` so that the
//! test harness's own threads do not allocate while a count is armed.

use e2e_tests::CountingAllocator;
use estimator_core::filter::{IntermittentKalmanFilter, KalmanFilter};
use estimator_core::model::LinearModel;
use nalgebra::{matrix, vector, SMatrix};

#[global_allocator]
static ALLOC: CountingAllocator = CountingAllocator::new();

#[test]
fn estimator_steps_do_not_allocate() {
    let m = LinearModel::<f64, 3, 3, 2, 2>::new(
        matrix![1.0, 0.1, 0.0; 0.0, 1.0, 0.1; 0.0, 0.0, 0.95],
        SMatrix::identity(),
        matrix![1.0, 0.0, 0.0; 0.0, 0.0, 1.0],
        SMatrix::identity(),
        SMatrix::identity() * 0.01,
        SMatrix::identity() * 0.5,
    )
    .unwrap();
    let mut kf = KalmanFilter::new(vector![0.0, 0.0, 0.0], SMatrix::identity()).unwrap();
    let mut ikf =
        IntermittentKalmanFilter::new(vector![0.0, 0.0, 0.0], SMatrix::identity()).unwrap();
    let (n, ok) = ALLOC.count(|| {
        let mut ok = true;
        for k in 1..=10_000usize {
            let y = vector![(k as f64 * 0.01).sin(), (k as f64 * 0.02).cos()];
            ok &= kf.step(&m, k, &y).is_ok();
            let y_opt = if k % 3 == 0 { None } else { Some(&y) };
            ok &= ikf.step(&m, k, y_opt).is_ok();
            // Error paths must not allocate either.
            ok &= kf.step(&m, k, &vector![f64::NAN, 0.0]).is_err();
        }
        ok
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 KF/IKF steps");

    tobit_fusion_section();
}

/// Seed 004: the sensor-side protocol (triggers + shared bucket) and the estimator-side
/// federated Tobit fusion step (3 local filters, fusion, reset), including error paths.
fn tobit_fusion_section() {
    use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
    use estimator_core::filter::TobitFusion;
    use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
    use estimator_core::protocol::shared_token_bucket::{
        SharedTokenBucket, TriggeredBucketScheduler,
    };

    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let b = vector![0.16, 0.18];
    let bqb = b * b.transpose() * 0.05;
    let c = [SMatrix::<f64, 2, 2>::identity(); 3];
    let r = [vector![0.5, 0.5]; 3];
    let tau = vector![0.0, 0.0];
    let trig = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)]
        .map(|(s, l)| EventTriggerConfig::new_allowing_paper_violation(s, 5.0, l, 1.5).unwrap());
    let cfgs = trig
        .map(|t| TobitFilterConfig::new(tau, BoundScalars::paper_example(), t, 1.5, 2.0).unwrap());
    let mut fusion =
        TobitFusion::<f64, 2, 2, 3>::new(cfgs, vector![5.0, 0.0], SMatrix::identity()).unwrap();
    let nodes = trig.map(|t| EventTrigger::new(t, tau).unwrap());
    let mut sched = TriggeredBucketScheduler::new(
        nodes,
        SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap(),
    );
    let (n, ok) = ALLOC.count(|| {
        let mut ok = true;
        let mut x = vector![5.0, 0.0];
        for k in 1..=10_000usize {
            x = a * x;
            let s = k as f64;
            let ys = [0.3, 0.7, 1.1].map(|p| {
                vector![
                    (x[0] + (p * s).sin() * 0.3).max(0.0),
                    (x[1] + (p * s).cos() * 0.3).max(0.0)
                ]
            });
            let d = match sched.step(&ys) {
                Ok(d) => d,
                Err(_) => return false,
            };
            let rec = [0, 1, 2].map(|m| d[m].sent.then_some(&ys[m]));
            ok &= fusion.step(&a, &bqb, &c, &r, rec).is_ok();
            // Error path: a NaN measurement is refused without allocating.
            let bad = vector![f64::NAN, 0.0];
            ok &= fusion
                .step(&a, &bqb, &c, &r, [Some(&bad), None, None])
                .is_err();
        }
        ok
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 Tobit fusion steps");
}
