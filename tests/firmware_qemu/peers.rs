//! The core's Kalman filter side by side with its Rust peers (the firmware's `peers` module):
//! every peer's estimates (and those of our optimal-gain form, the `kfs` binaries) agree with
//! ours on the same stream, and every implementation in `f32` agrees with ours in `f64`. The QEMU check (`firmware_on_qemu_is_bit_exact_with_host`)
//! shows the host runs are the Cortex-M4's bit for bit, so this holds on the target too.
//!
//! Tolerance: at every instant k, `max_i |a_i − b_i| / max_i |b_i|` over x̂_k, and over the
//! entries of P_k, at most [`TOL`] = 10⁻⁴. A norm-wise relative measure because P_k has exact
//! zeros (the tracker's two axes are uncoupled) and x̂_k entries that cross zero, where an
//! entry-wise relative error means nothing. 10⁻⁴ is about 840 f32 units of round-off
//! (ε = 1.19·10⁻⁷): the implementations differ only in the order of their operations (and in
//! `minikalman`'s case in the covariance form, P − K H P instead of the Joseph form, and no
//! symmetrisation), over 100 steps of an f32 filter whose tracker amplifies the rounding of the
//! measured positions by 1/dt = 100 into the velocities. The runs are deterministic, so the
//! printed deviations are the same every time; the largest is about 4·10⁻⁵ (`minikalman`'s
//! tracker state, also against the f64 run, where ours and the Joseph-form peers stay within
//! 3·10⁻⁶).

use estimator_core::filter::KalmanFilter;
use estimator_core::model::LinearModel;
use nalgebra::Vector2;

use super::peers::{mk3x2, mk4x2, problem_3x2, problem_4x2, Ads, KfStep, Ours, Problem, Tk};
use super::run;

/// Norm-wise relative deviation allowed between any two implementations at any instant.
const TOL: f64 = 1e-4;

/// x̂_k and P_k (column-major) of one implementation at every instant k = 1..T.
type Trace = Vec<(Vec<f64>, Vec<f64>)>;

fn measurements() -> Vec<Vector2<f32>> {
    let s = run::OCCLUSION.stream().expect("embedded vectors are valid");
    s.records().map(|r| Vector2::from(r.y)).collect()
}

fn trace<const NX: usize>(name: &str, mut e: impl KfStep<NX>, ys: &[Vector2<f32>]) -> Trace {
    ys.iter()
        .enumerate()
        .map(|(i, y)| {
            assert!(e.step(i + 1, y), "{name} refused instant {}", i + 1);
            let x = (0..NX).map(|r| f64::from(e.x(r))).collect();
            let p = (0..NX * NX)
                .map(|j| f64::from(e.p(j % NX, j / NX)))
                .collect();
            (x, p)
        })
        .collect()
}

/// Ours in f64 on the same model and prior (the f32 values widened exactly).
fn trace_f64<const NX: usize>(p: &Problem<NX>, ys: &[Vector2<f32>]) -> Trace {
    let model: LinearModel<f64, NX, NX, 2, 2> = p.model.cast::<f64>().expect("valid model");
    let mut kf = KalmanFilter::new(p.x0.cast::<f64>(), p.p0.cast::<f64>()).expect("valid prior");
    ys.iter()
        .enumerate()
        .map(|(i, y)| {
            kf.step(&model, i + 1, &y.cast::<f64>()).expect("f64 step");
            let e = kf.estimate();
            (
                e.state().iter().copied().collect(),
                e.covariance().iter().copied().collect(),
            )
        })
        .collect()
}

/// The largest norm-wise relative deviation of `a` from `b` over the instants: (x̂, P).
fn deviation(a: &Trace, b: &Trace) -> (f64, f64) {
    let rel = |u: &[f64], v: &[f64]| {
        let scale = v.iter().fold(0f64, |m, w| m.max(w.abs()));
        u.iter()
            .zip(v)
            .fold(0f64, |m, (s, t)| m.max((s - t).abs() / scale))
    };
    a.iter().zip(b).fold((0f64, 0f64), |(dx, dp), (ea, eb)| {
        (dx.max(rel(&ea.0, &eb.0)), dp.max(rel(&ea.1, &eb.1)))
    })
}

fn check<const NX: usize>(
    problem: &str,
    p: &Problem<NX>,
    peers: Vec<(&str, Trace)>,
    ys: &[Vector2<f32>],
    failures: &mut Vec<String>,
) {
    let ours = trace("ours", Ours::new(p).expect("valid problem"), ys);
    let exact = trace_f64(p, ys);
    let (dx, dp) = deviation(&ours, &exact);
    println!("{problem:<4} ours (f32)    vs ours in f64: x̂ {dx:.1e}  P {dp:.1e}");
    if dx > TOL || dp > TOL {
        failures.push(format!("{problem} ours vs f64: x̂ {dx:.1e} P {dp:.1e}"));
    }
    for (name, t) in &peers {
        let (dx, dp) = deviation(t, &ours);
        let (fx, fp) = deviation(t, &exact);
        println!(
            "{problem:<4} {name:<13} vs ours: x̂ {dx:.1e}  P {dp:.1e}    vs ours in f64: x̂ {fx:.1e}  P {fp:.1e}"
        );
        for (what, d) in [("vs ours", (dx, dp)), ("vs f64", (fx, fp))] {
            if d.0 > TOL || d.1 > TOL {
                failures.push(format!(
                    "{problem} {name} {what}: x̂ {:.1e} P {:.1e}",
                    d.0, d.1
                ));
            }
        }
    }
}

#[test]
fn kf_peers_agree_with_ours_on_the_stream() {
    let ys = measurements();
    assert_eq!(ys.len(), 100);
    let mut failures = Vec::new();
    let p3 = problem_3x2().expect("valid 3x2 problem");
    let peers3 = vec![
        ("adskalman", trace("ads", Ads::new(&p3), &ys)),
        ("typed-kalman", trace("tk", Tk::new(&p3), &ys)),
        ("minikalman", trace("mk", mk3x2(&p3), &ys)),
        (
            "ours P − K Gᵀ",
            trace("kfs", Ours::new(&p3).expect("valid").standard(), &ys),
        ),
    ];
    check("3x2", &p3, peers3, &ys, &mut failures);
    let p4 = problem_4x2().expect("valid 4x2 problem");
    let peers4 = vec![
        ("adskalman", trace("ads", Ads::new(&p4), &ys)),
        ("typed-kalman", trace("tk", Tk::new(&p4), &ys)),
        ("minikalman", trace("mk", mk4x2(&p4), &ys)),
        (
            "ours P − K Gᵀ",
            trace("kfs", Ours::new(&p4).expect("valid").standard(), &ys),
        ),
    ];
    check("4x2", &p4, peers4, &ys, &mut failures);
    assert!(
        failures.is_empty(),
        "deviations over {TOL:e}:\n{}",
        failures.join("\n")
    );
}
