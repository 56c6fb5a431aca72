//! One step of each of the papers' estimators, from a fixed state: the kernels that both the
//! criterion bench (`benches/benches/steps.rs`) and the instruction counter (`icount`) run,
//! so the host instruction counts and the criterion medians describe the same work under
//! the same names.

use estimator_core::filter::coupled_kf::{CoupledNoiseKf, Linearisation};
use estimator_core::filter::nn::{GainSolver, NnBoundConfig};
use estimator_core::filter::silence::TriggeredPackets;
use estimator_core::filter::tobit::{BoundScalars, Silence, TobitFilterConfig};
use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo, TobitFusion};
use estimator_core::filter::{MirroredFusion, MomentMatchedTobit};
use estimator_core::gsum::GaussSum;
use estimator_core::papers::Seed001Example;
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
use estimator_core::protocol::shared_token_bucket::{SharedTokenBucket, TriggeredBucketScheduler};
use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
use estimator_core::{Estimate, Estimator, OnModel, Packet, Real, Result};
use nalgebra::{matrix, vector, SMatrix, SVector};
use std::hint::black_box;

/// A step kernel: runs one step from the fixed state; `Ok` iff the step succeeded.
///
/// The estimators' kernels hold the estimator as the application does, the filter paired with
/// its model ([`OnModel`], the model owned), and step it through [`Estimator::step`]: every
/// call puts the fixed state back into the pair, the model staying in place (hence `FnMut`).
pub type StepFn = Box<dyn FnMut() -> Result<()>>;

/// Seed 001 kernels: CCE dropout step (S = 4, N = 15), ADF dropout/arrival, KF-IO dropout.
pub fn occlusion_kernels<T: Real>(tag: &str) -> Vec<(String, StepFn)> {
    let m = Seed001Example::model::<T>().expect("valid model");
    let occ = Seed001Example::occlusion::<T>().expect("valid occlusion");
    // A state whose prediction sits on the edge of region 2, the typical dropout.
    let x0: SVector<T, 3> = vector![T::lit(35.0), T::lit(1.0), T::lit(0.5)];
    let p0 = SMatrix::<T, 3, 3>::identity() * T::lit(0.5);
    let cce = CrossCoupledEstimator::<T, 3, 1, 4, 15>::new(
        x0,
        p0,
        occ,
        &GaussSum::uniform().expect("table"),
    )
    .expect("valid");
    let adf = AssumedDensityFilter::new(x0, p0, occ).expect("valid");
    let kfio = KfIo::new(x0, p0, occ).expect("valid");
    let y: SVector<T, 2> = vector![T::lit(100.0), T::lit(35.0)];
    let (mut cce_on, mut adf_on, mut kfio_on) = (
        OnModel::<_, _, 2>::new(m, cce),
        OnModel::<_, _, 2>::new(m, adf),
        OnModel::<_, _, 2>::new(m, kfio),
    );
    let mut adf_arrival_on = adf_on;
    vec![
        (
            format!("cce_dropout/s4_n15_nx3_{tag}"),
            Box::new(move || {
                cce_on.filter = black_box(cce);
                cce_on.step(1, &Packet::Dropped)?;
                black_box(&cce_on.filter);
                Ok(())
            }) as StepFn,
        ),
        (
            format!("adf_dropout/s4_nx3_{tag}"),
            Box::new(move || {
                adf_on.filter = black_box(adf);
                adf_on.step(1, &Packet::Dropped)?;
                black_box(&adf_on.filter);
                Ok(())
            }),
        ),
        (
            format!("adf_arrival/s4_nx3_{tag}"),
            Box::new(move || {
                adf_arrival_on.filter = black_box(adf);
                adf_arrival_on.step(1, &Packet::Delivered(black_box(y)))?;
                black_box(&adf_arrival_on.filter);
                Ok(())
            }),
        ),
        (
            format!("kfio_dropout/s4_nx3_{tag}"),
            Box::new(move || {
                kfio_on.filter = black_box(kfio);
                kfio_on.step(1, &Packet::Dropped)?;
                black_box(&kfio_on.filter);
                Ok(())
            }),
        ),
    ]
}

fn nn_estimator<T: Real>(solver: GainSolver) -> Seed003Nn<T> {
    let cfg = NnBoundConfig::new(
        [T::lit(0.5); 4],
        [T::lit(0.5); 12],
        [T::lit(0.05), T::lit(10.0)],
        T::lit(8.0),
        T::lit(1.8),
        T::lit(0.1),
        T::lit(0.1),
    )
    .expect("valid config");
    Seed003Nn::seed003(cfg)
        .expect("valid")
        .with_initial_measurement(SVector::<T, 2>::new(T::lit(0.3), T::lit(-0.2)))
        .expect("finite")
        .with_gain_solver(solver)
}

/// Seed 003 kernels: the NN estimator's transmitted-measurement step (gain solve included)
/// with both gain solvers, and the correlated-noise EKF baseline (f64 only).
pub fn nn_kernels<T: Real>(tag: &str) -> Vec<(String, StepFn)> {
    let mut out: Vec<(String, StepFn)> = Vec::new();
    for (name, solver) in [
        ("kron", GainSolver::Kronecker),
        ("two_sided", GainSolver::TwoSided),
    ] {
        let e = nn_estimator::<T>(solver);
        let y = SVector::<T, 2>::new(T::lit(0.3), T::lit(-0.2));
        let mut on = OnModel::<_, _, 2>::new(Seed003Example, e);
        out.push((
            format!("nn_step_{name}/3x2_{tag}"),
            Box::new(move || {
                on.filter = black_box(e);
                on.step(1, &Packet::Delivered(black_box(y)))?;
                black_box(&on.filter);
                Ok(())
            }),
        ));
    }
    out
}

/// The correlated-noise EKF of seed 003's comparison.
pub fn coupled_ekf_kernel<T: Real>(tag: &str) -> (String, StepFn) {
    let kf = CoupledNoiseKf::<T, 3, 1, 2>::new(
        Seed003Example::xhat0(),
        Seed003Example::p0(),
        SMatrix::<T, 1, 1>::new(T::lit(0.1)),
        Linearisation::PaperJacobian,
    )
    .expect("valid")
    .with_initial_measurement(SVector::<T, 2>::new(T::lit(0.3), T::lit(-0.2)))
    .expect("finite");
    let y = SVector::<T, 2>::new(T::lit(0.3), T::lit(-0.2));
    let mut on = OnModel::<_, _, 2>::new((Seed003Example, Seed003Example), kf);
    (
        format!("coupled_ekf_step/3x2_{tag}"),
        Box::new(move || {
            on.filter = black_box(kf);
            on.step(1, &Packet::Delivered(black_box(y)))?;
            black_box(&on.filter);
            Ok(())
        }),
    )
}

/// Seed 004 kernel: one federated Tobit fusion step (l = 3 local filters, n_x = n_y = 2),
/// node 2 silent, from a fixed state.
pub fn tobit_kernel<T: Real>(tag: &str) -> (String, StepFn) {
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
        TobitFilterConfig::new(tau, BoundScalars::paper_example(), t, 1.5, 2.0)
            .expect("valid")
            .cast::<T>()
            .expect("valid")
    });
    let fusion =
        TobitFusion::<T, 2, 2, 3>::new(cfgs, vector![T::lit(5.0), T::zero()], SMatrix::identity())
            .expect("valid");
    let (a, bqb) = (a.map(T::lit), bqb.map(T::lit));
    let cm = cm.map(|m| m.map(T::lit));
    let r = r.map(|v| v.map(T::lit));
    let y = [vector![4.8, 0.2], vector![5.1, 0.0], vector![4.9, 0.3]].map(|v| v.map(T::lit));
    // Explicit matrices, not the fusion filter's `OnModel` pairing: that pairing takes every
    // node's model as a `LinearSystem` and derives the variances from R at every step, work
    // this kernel (and the firmware's `tobit`, which it mirrors) does not time.
    (
        format!("tobit_fusion_step/l3_2x2_{tag}"),
        Box::new(move || {
            let mut f = black_box(fusion);
            f.step(
                black_box(&a),
                black_box(&bqb),
                black_box(&cm),
                black_box(&r),
                [Some(&y[0]), None, Some(&y[2])],
            )?;
            black_box(f);
            Ok(())
        }),
    )
}

/// The product's silence update beside the paper's step (docs/tobit-fusion.md, "Silence that
/// speaks"): the same fusion step from the same state as [`tobit_kernel`], with the bucket
/// mirror and truncated-Gaussian (`tg`) or Sijs–Lazar (`sl`) local filters; node 2 silent with
/// a token (its trigger held), so its local filter takes the silence update.
pub fn tobit_silence_kernel<T: Real>(form: Silence, tag: &str) -> (String, StepFn) {
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
        TobitFilterConfig::new(tau, BoundScalars::paper_example(), t, 1.5, 2.0)
            .expect("valid")
            .with_silence(form)
            .cast::<T>()
            .expect("valid")
    });
    let fusion =
        TobitFusion::<T, 2, 2, 3>::new(cfgs, vector![T::lit(5.0), T::zero()], SMatrix::identity())
            .expect("valid");
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).expect("valid");
    let filter = MirroredFusion::new(fusion, bucket);
    let (a, bqb) = (a.map(T::lit), bqb.map(T::lit));
    let cm = cm.map(|m| m.map(T::lit));
    let r = r.map(|v| v.map(T::lit));
    let y = [vector![4.8, 0.2], vector![5.1, 0.0], vector![4.9, 0.3]].map(|v| v.map(T::lit));
    let packets = TriggeredPackets {
        packets: [
            Packet::Delivered(y[0]),
            Packet::Dropped,
            Packet::Delivered(y[2]),
        ],
        level: None,
    };
    let name = match form {
        Silence::PseudoMeasurement => "sl",
        _ => "tg",
    };
    (
        format!("tobit_silence_step/{name}_l3_2x2_{tag}"),
        Box::new(move || {
            let mut f = black_box(filter);
            f.step_matrices(
                black_box(&a),
                black_box(&bqb),
                black_box(&cm),
                black_box(&r),
                black_box(&packets),
            )?;
            black_box(f);
            Ok(())
        }),
    )
}

/// The product's centralised filter at the information bound (docs/tobit-fusion.md, "At the
/// information bound"): one `MomentMatchedTobit` step from the fixed state of
/// [`tobit_kernel`] (x̂ = [5 0]ᵀ, P = I, the same matrices and packets: nodes 1 and 3 deliver,
/// node 2 silent with a token), reading the held silence (`silence`, `tobit-cmm-held`,
/// the firmware's `tobit-cmm`) or not (`plain`, `tobit-cmm`).
pub fn tobit_cmm_kernel<T: Real>(reads_silence: bool, tag: &str) -> (String, StepFn) {
    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()].map(T::lit);
    let b = vector![0.16, 0.18];
    let bqb = (b * b.transpose() * 0.05).map(T::lit);
    let nodes = [(
        SMatrix::<T, 2, 2>::identity(),
        vector![0.5, 0.5].map(T::lit),
    ); 3];
    let tau = SVector::<T, 2>::zeros();
    let knowledge = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)].map(|(s, l)| {
        let t = EventTriggerConfig::new_allowing_paper_violation(s, 5.0, l, 1.5)
            .and_then(|c| c.cast::<T>())
            .expect("valid");
        TriggerKnowledge::new(t, tau).expect("valid")
    });
    let prior = Estimate::new(vector![T::lit(5.0), T::zero()], SMatrix::identity()).expect("valid");
    let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).expect("valid");
    let filter =
        MomentMatchedTobit::<T, 2, 2, 3>::new(prior, [tau; 3], knowledge, bucket, reads_silence)
            .expect("valid");
    let y = [vector![4.8, 0.2], vector![4.9, 0.3]].map(|v| v.map(T::lit));
    let packets = TriggeredPackets {
        packets: [
            Packet::Delivered(y[0]),
            Packet::Dropped,
            Packet::Delivered(y[1]),
        ],
        level: None,
    };
    let name = if reads_silence { "silence" } else { "plain" };
    (
        format!("tobit_cmm_step/{name}_l3_2x2_{tag}"),
        Box::new(move || {
            let mut f = black_box(filter);
            f.step_matrices(
                black_box(&a),
                black_box(&bqb),
                black_box(&nodes),
                black_box(&packets),
            )?;
            black_box(f);
            Ok(())
        }),
    )
}

/// Seed 004's sensor side for one instant: three event triggers sharing one token bucket,
/// from a fixed state.
pub fn tobit_protocol_kernel<T: Real>(tag: &str) -> (String, StepFn) {
    let l = T::lit;
    let tau = SVector::<T, 2>::zeros();
    let trig = [(0.1, 0.1), (0.2, 0.2), (0.3, 0.1)].map(|(s, lam)| {
        EventTriggerConfig::new_allowing_paper_violation(l(s), l(5.0), l(lam), l(1.5))
            .expect("valid")
    });
    let nodes = trig.map(|t| EventTrigger::new(t, tau).expect("valid"));
    let sched = TriggeredBucketScheduler::new(
        nodes,
        SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).expect("valid"),
    );
    let y = [(4.8, 0.2), (5.1, 0.0), (4.9, 0.3)].map(|(a, b)| SVector::<T, 2>::new(l(a), l(b)));
    (
        format!("tobit_protocol_instant/l3_ny2_{tag}"),
        Box::new(move || {
            let mut s = black_box(sched);
            s.step(black_box(&y))?;
            black_box(s);
            Ok(())
        }),
    )
}

/// Every kernel above, f64 and f32 where both exist.
pub fn all_kernels() -> Vec<(String, StepFn)> {
    let mut k = occlusion_kernels::<f64>("f64");
    k.extend(occlusion_kernels::<f32>("f32"));
    k.extend(nn_kernels::<f64>("f64"));
    k.extend(nn_kernels::<f32>("f32"));
    k.push(coupled_ekf_kernel::<f64>("f64"));
    k.push(coupled_ekf_kernel::<f32>("f32"));
    k.push(tobit_kernel::<f64>("f64"));
    k.push(tobit_kernel::<f32>("f32"));
    k.push(tobit_protocol_kernel::<f64>("f64"));
    k.push(tobit_protocol_kernel::<f32>("f32"));
    for form in [Silence::TruncatedGaussian, Silence::PseudoMeasurement] {
        k.push(tobit_silence_kernel::<f64>(form, "f64"));
        k.push(tobit_silence_kernel::<f32>(form, "f32"));
    }
    for reads_silence in [true, false] {
        k.push(tobit_cmm_kernel::<f64>(reads_silence, "f64"));
        k.push(tobit_cmm_kernel::<f32>(reads_silence, "f32"));
    }
    k
}
