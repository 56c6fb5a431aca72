//! One full federated Tobit fusion step of seed 004 (l = 3 local filters, n_x = 2, n_y = 2):
//! three local Tobit filter steps (21)-(23), (37), (30), the fusion (50) and the reset (51);
//! and the sensor-side protocol instant (three triggers and the shared bucket).

use criterion::{criterion_group, criterion_main, Criterion};
use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
use estimator_core::filter::TobitFusion;
use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
use estimator_core::protocol::shared_token_bucket::{SharedTokenBucket, TriggeredBucketScheduler};
use nalgebra::{matrix, vector, SMatrix};
use std::hint::black_box;

fn tobit_fusion_step(c: &mut Criterion) {
    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let b = vector![0.16, 0.18];
    let bqb = b * b.transpose() * 0.05;
    let cm = [SMatrix::<f64, 2, 2>::identity(); 3];
    let r = [vector![0.5, 0.5]; 3];
    let tau = vector![0.0, 0.0];
    let trig = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)].map(|(s, l)| {
        EventTriggerConfig::new_allowing_paper_violation(s, 5.0, l, 1.5).expect("valid")
    });
    let cfgs = trig.map(|t| {
        TobitFilterConfig::new(tau, BoundScalars::paper_example(), t, 1.5, 2.0).expect("valid")
    });
    let fusion0 = TobitFusion::<f64, 2, 2, 3>::new(cfgs, vector![5.0, 0.0], SMatrix::identity())
        .expect("valid");
    let y = [vector![4.8, 0.2], vector![5.1, 0.0], vector![4.9, 0.3]];

    // Mixed arrivals as in the example (one node blocked / not triggered).
    let mut fusion = fusion0;
    c.bench_function("tobit_fusion_step_l3_2x2_f64", |bch| {
        bch.iter(|| {
            fusion
                .step(
                    black_box(&a),
                    black_box(&bqb),
                    black_box(&cm),
                    black_box(&r),
                    [Some(&y[0]), None, Some(&y[2])],
                )
                .expect("step")
        })
    });

    let cfgs32 = cfgs.map(|c| c.cast::<f32>().expect("valid"));
    let mut f32_fusion =
        TobitFusion::<f32, 2, 2, 3>::new(cfgs32, vector![5.0, 0.0], SMatrix::identity())
            .expect("valid");
    let (a32, bqb32) = (a.cast::<f32>(), bqb.cast::<f32>());
    let (c32, r32, y32) = (
        cm.map(|m| m.cast()),
        r.map(|v| v.cast()),
        y.map(|v| v.cast()),
    );
    c.bench_function("tobit_fusion_step_l3_2x2_f32", |bch| {
        bch.iter(|| {
            f32_fusion
                .step(
                    black_box(&a32),
                    black_box(&bqb32),
                    black_box(&c32),
                    black_box(&r32),
                    [Some(&y32[0]), None, Some(&y32[2])],
                )
                .expect("step")
        })
    });

    let nodes = trig.map(|t| EventTrigger::new(t, tau).expect("valid"));
    let mut sched = TriggeredBucketScheduler::new(
        nodes,
        SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).expect("valid"),
    );
    c.bench_function("tobit_protocol_instant_l3_ny2_f64", |bch| {
        bch.iter(|| sched.step(black_box(&y)).expect("step"))
    });
}

criterion_group!(benches, tobit_fusion_step);
criterion_main!(benches);
