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
            let y_opt = if k.is_multiple_of(3) { None } else { Some(&y) };
            ok &= ikf.step(&m, k, y_opt).is_ok();
            // Error paths must not allocate either.
            ok &= kf.step(&m, k, &vector![f64::NAN, 0.0]).is_err();
        }
        ok
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 KF/IKF steps");
    occlusion_section();
    nn_tbcp_section();
    tobit_fusion_section();
    silence_section();
    information_bound_section();
}

/// Seed 001 (issue 4): CCE, ADF and KF-IO steps on the paper's example, arrivals, dropouts
/// and error paths.
fn occlusion_section() {
    use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
    use estimator_core::gsum::GaussSum;
    use estimator_core::papers::Seed001Example;
    let m = Seed001Example::model::<f64>().unwrap();
    let occ = Seed001Example::occlusion::<f64>().unwrap();
    let g = GaussSum::<f64, 1, 15>::uniform().unwrap();
    let (x0, p0) = (Seed001Example::x0(), Seed001Example::p0());
    let (n, ok) = ALLOC.count(|| {
        let mut ok = true;
        // Restart every 50 steps: the example's A is unstable.
        for block in 0..200usize {
            let mut cce = CrossCoupledEstimator::new(x0, p0, occ, &g).unwrap();
            let mut adf = AssumedDensityFilter::new(x0, p0, occ).unwrap();
            let mut kfio = KfIo::new(x0, p0, occ).unwrap();
            for k in 1..=50usize {
                let t = (block * 50 + k) as f64;
                let y = vector![30.0 + (t * 0.1).sin(), 10.0 + (t * 0.3).cos()];
                let y_opt = if k.is_multiple_of(3) { None } else { Some(&y) };
                ok &= cce.step(&m, k, y_opt).is_ok();
                ok &= adf.step(&m, k, y_opt).is_ok();
                ok &= kfio.step(&m, k, y_opt).is_ok();
                ok &= cce.step(&m, k, Some(&vector![f64::NAN, 0.0])).is_err();
                ok &= adf.step(&m, k, Some(&vector![f64::NAN, 0.0])).is_err();
            }
        }
        ok
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 CCE/ADF/KF-IO steps");
}

/// Seed 003: the NN estimator (Kronecker and two-sided gain), the correlated-noise KF/EKF
/// baselines, the independent-noise KF/EKF, the token bucket and the run monitor, including
/// an error path.
fn nn_tbcp_section() {
    use estimator_core::filter::coupled_kf::{CoupledNoiseKf, Linearisation, NoNonlinearity};
    use estimator_core::filter::independent_kf::{IndependentMode, IndependentNoiseKf};
    use estimator_core::filter::nn::{GainSolver, NnBoundConfig, RunMonitor};
    use estimator_core::papers::{Seed003Example, Seed003Nn};
    use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};

    // A configuration with δ₁ < 1 so the bound stays finite over 10 000 steps.
    let cfg = NnBoundConfig::new([0.5; 4], [0.5; 12], [0.05, 10.0], 8.0, 1.8, 0.1, 0.1).unwrap();
    let new_nn =
        |solver| -> Seed003Nn<f64> { Seed003Nn::seed003(cfg).unwrap().with_gain_solver(solver) };
    let mut nn_k = new_nn(GainSolver::Kronecker);
    let mut nn_t = new_nn(GainSolver::TwoSided);
    let mut mon = RunMonitor::new(&nn_k);
    let kf = |m| {
        CoupledNoiseKf::<f64, 3, 1, 2>::new(
            Seed003Example::xhat0(),
            Seed003Example::p0(),
            matrix![0.1],
            m,
        )
        .unwrap()
    };
    let (mut kf, mut ekf) = (kf(Linearisation::None), kf(Linearisation::PaperJacobian));
    let indep = |m| {
        IndependentNoiseKf::<f64, 3, 1, 2>::new(
            Seed003Example::xhat0(),
            Seed003Example::p0(),
            matrix![0.1],
            m,
        )
        .unwrap()
    };
    let (mut kfi, mut ekfi) = (indep(IndependentMode::Kf), indep(IndependentMode::Ekf));
    let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
    let sys = Seed003Example;
    let (n, ok) = ALLOC.count(|| {
        let mut ok = true;
        for k in 1..=10_000usize {
            let y = vector![(k as f64 * 0.01).sin(), (k as f64 * 0.02).cos()];
            let sent = tb.step().transmit;
            let y_opt = sent.then_some(&y);
            // Near k ≡ 0 (mod 2π) C_k is nearly rank 1; an Err there is a valid outcome too,
            // what matters is that neither path allocates.
            let _ = nn_k.step(&sys, y_opt);
            mon.observe(&nn_k);
            let _ = nn_t.step(&sys, y_opt);
            ok &= kf.step(&sys, &NoNonlinearity, y_opt).is_ok();
            // The EKF on data that is not from the model may diverge to a (non-allocating)
            // error; only allocation is measured here.
            let _ = ekf.step(&sys, &sys, y_opt);
            let _ = kfi.step(&sys, &NoNonlinearity, y_opt);
            let _ = ekfi.step(&sys, &sys, y_opt);
            ok &= kfi
                .step(&sys, &NoNonlinearity, Some(&vector![f64::NAN, 0.0]))
                .is_err();
            ok &= nn_k.step(&sys, Some(&vector![f64::NAN, 0.0])).is_err();
        }
        ok
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 seed 003 steps");
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

/// The silence-reading estimators (docs/tobit-fusion.md, "Silence that speaks"): the bucket
/// mirror with both silence forms in the Tobit fusion, and the silence Kalman filter, over
/// 10 000 instants of the example's protocol each, error paths included.
fn silence_section() {
    use estimator_core::filter::silence::kalman::SilenceKf;
    use estimator_core::filter::silence::{SilenceForm, TriggeredPackets};
    use estimator_core::filter::tobit::{BoundScalars, Silence, TobitFilterConfig};
    use estimator_core::filter::{MirroredFusion, TobitFusion};
    use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
    use estimator_core::protocol::shared_token_bucket::{
        SharedTokenBucket, TriggeredBucketScheduler,
    };
    use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
    use estimator_core::Packet;

    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let b = vector![0.16, 0.18];
    let bqb = b * b.transpose() * 0.05;
    let c = [SMatrix::<f64, 2, 2>::identity(); 3];
    let r = [vector![0.5, 0.5]; 3];
    let tau = vector![0.0, 0.0];
    let trig = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)]
        .map(|(s, l)| EventTriggerConfig::new_allowing_paper_violation(s, 5.0, l, 1.5).unwrap());
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
    let fusion = |form: Silence| {
        let cfgs = trig.map(|t| {
            TobitFilterConfig::new(tau, BoundScalars::paper_example(), t, 1.5, 2.0)
                .unwrap()
                .with_silence(form)
        });
        let f =
            TobitFusion::<f64, 2, 2, 3>::new(cfgs, vector![5.0, 0.0], SMatrix::identity()).unwrap();
        MirroredFusion::new(f, bucket)
    };
    let mut tg = fusion(Silence::TruncatedGaussian);
    let mut sl = fusion(Silence::PseudoMeasurement);
    let model = LinearModel::<f64, 2, 1, 1, 1>::new(
        matrix![1.0, 0.1; 0.0, 1.0],
        matrix![0.005; 0.1],
        matrix![1.0, 0.0],
        matrix![1.0],
        matrix![1.0],
        matrix![0.01],
    )
    .unwrap();
    let lin_cfg = EventTriggerConfig::new(0.3, 5.0, 0.5, 0.0).unwrap();
    let lin_bucket = SharedTokenBucket::<1>::new(3, 1, 6, [3]).unwrap();
    let mut kf = SilenceKf::new(
        KalmanFilter::new(vector![0.0, 1.0], SMatrix::identity()).unwrap(),
        [TriggerKnowledge::new(lin_cfg, vector![0.0]).unwrap()],
        lin_bucket,
        SilenceForm::TruncatedGaussian,
    );
    let nodes = trig.map(|t| EventTrigger::new(t, tau).unwrap());
    let mut sched = TriggeredBucketScheduler::new(nodes, bucket);
    let mut lin_node = TriggeredBucketScheduler::new(
        [EventTrigger::new(lin_cfg, vector![0.0]).unwrap()],
        lin_bucket,
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
            let level = sched.bucket().level();
            let d = match sched.step(&ys) {
                Ok(d) => d,
                Err(_) => return false,
            };
            let packets = TriggeredPackets {
                packets: [0, 1, 2].map(|m| {
                    if d[m].sent {
                        Packet::Delivered(ys[m])
                    } else if k % 97 == 0 {
                        Packet::Lost
                    } else {
                        Packet::Dropped
                    }
                }),
                level: d.iter().any(|d| d.sent).then_some(level),
            };
            for f in [&mut tg, &mut sl] {
                ok &= f.step_matrices(&a, &bqb, &c, &r, &packets).is_ok();
                let bad = TriggeredPackets {
                    packets: [
                        Packet::Delivered(vector![f64::NAN, 0.0]),
                        Packet::Dropped,
                        Packet::Lost,
                    ],
                    level: Some(31),
                };
                ok &= f.step_matrices(&a, &bqb, &c, &r, &bad).is_err();
            }
            let y = vector![(0.05 * s).sin() * 3.0];
            let dl = match lin_node.step(&[y]) {
                Ok(d) => d[0],
                Err(_) => return false,
            };
            let p = TriggeredPackets {
                packets: [if dl.sent {
                    Packet::Delivered(y)
                } else {
                    Packet::Dropped
                }],
                level: None,
            };
            ok &= kf.step(&[model], k, &p).is_ok();
        }
        ok && tg.counts().held > 0 && kf.counts().held > 0
    });
    assert!(ok);
    assert_eq!(n, 0, "{n} heap allocations in 10 000 silence-reading steps");
}

/// The centralised filters of docs/tobit-fusion.md "At the information bound": the
/// moment-matched filter reading held silences (`tobit-cmm-held`) and the Tobit Kalman
/// filter, over 10 000 instants of the example's protocol, error paths included.
fn information_bound_section() {
    use estimator_core::filter::silence::TriggeredPackets;
    use estimator_core::filter::{GatedStep, InnovationGate, MomentMatchedTobit, TobitKf};
    use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
    use estimator_core::protocol::shared_token_bucket::{
        SharedTokenBucket, TriggeredBucketScheduler,
    };
    use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
    use estimator_core::{Estimate, OnModel, Packet};

    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let b = matrix![0.16, 0.0; 0.18, 0.0];
    let model = LinearModel::<f64, 2, 2, 2, 2>::new(
        a,
        b,
        SMatrix::identity(),
        SMatrix::identity(),
        SMatrix::identity() * 0.05,
        SMatrix::identity() * 0.5,
    )
    .unwrap();
    let tau = vector![0.0, 0.0];
    let trig = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)]
        .map(|(s, l)| EventTriggerConfig::new_allowing_paper_violation(s, 5.0, l, 1.5).unwrap());
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
    let prior = Estimate::new(vector![5.0, 0.0], SMatrix::identity()).unwrap();
    let knowledge = trig.map(|t| TriggerKnowledge::new(t, tau).unwrap());
    let mut cmm = OnModel::<_, _, 2>::new(
        [model; 3],
        MomentMatchedTobit::new(prior, [tau; 3], knowledge, bucket, true).unwrap(),
    );
    let mut tkf = OnModel::<_, _, 2>::new([model; 3], TobitKf::new(prior, [tau; 3]).unwrap());
    let gate = InnovationGate::chi2(0.99).unwrap();
    let mut sched =
        TriggeredBucketScheduler::new(trig.map(|t| EventTrigger::new(t, tau).unwrap()), bucket);
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
            let level = sched.bucket().level();
            let Ok(d) = sched.step(&ys) else {
                return false;
            };
            let packets: [Packet<f64, 2>; 3] = [0, 1, 2].map(|m| match (d[m].sent, k % 97) {
                (true, _) => Packet::Delivered(ys[m]),
                (false, 0) => Packet::Lost,
                _ => Packet::Dropped,
            });
            let triggered = TriggeredPackets {
                packets,
                level: d.iter().any(|d| d.sent).then_some(level),
            };
            ok &= cmm.step_gated(k, &triggered, &gate).is_ok();
            ok &= tkf.step_gated(k, &packets, &gate).is_ok();
            // Error paths: a NaN measurement is refused without allocating.
            let bad = [
                Packet::Delivered(vector![f64::NAN, 0.0]),
                Packet::Dropped,
                Packet::Dropped,
            ];
            let bad_triggered = TriggeredPackets {
                packets: bad,
                level: None,
            };
            ok &= cmm.step_gated(k + 1, &bad_triggered, &gate).is_err();
            ok &= tkf.step_gated(k + 1, &bad, &gate).is_err();
        }
        ok
    });
    assert!(ok);
    assert_eq!(
        n, 0,
        "{n} heap allocations in 10 000 centralised Tobit steps"
    );
}
