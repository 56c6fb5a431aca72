use super::*;
use crate::filter::tobit::config::BoundScalars;
use crate::filter::KalmanFilter;
use crate::protocol::event_trigger::EventTriggerConfig;
use nalgebra::{matrix, vector};

fn paper_cfg(lambda: f64, sigma: f64) -> TobitFilterConfig<f64, 2> {
    let trig = EventTriggerConfig::new_allowing_paper_violation(sigma, 5.0, lambda, 1.5).unwrap();
    TobitFilterConfig::new(
        vector![0.0, 0.0],
        BoundScalars::paper_example(),
        trig,
        1.5,
        2.0,
    )
    .unwrap()
}

fn oscillator() -> (SMatrix<f64, 2, 2>, SMatrix<f64, 2, 2>) {
    let w = 0.052 * core::f64::consts::PI;
    let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
    let b = vector![0.16, 0.18];
    (a, b * b.transpose() * 0.05)
}

#[test]
fn xi_recursion_by_hand() {
    // λ = 0.1, χ = 5, σ = 0.1, d = 1.5, e = 2:
    // a = 2.5·3·0.01 + 6·(1 + 1/1.5)/25 = 0.075 + 0.4 = 0.475,
    // b = (2.5·1.5 + (5/3)·1.2)·0.01 = 0.0575.
    let cfg = paper_cfg(0.1, 0.1);
    assert!((cfg.xi(2.25) - (0.475 * 2.25 + 0.0575)).abs() < 1e-14);
    let (a, bqb) = oscillator();
    let mut f = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity() * 3.0).unwrap();
    assert!((f.g_bar() - 2.25).abs() < 1e-15);
    f.step(&a, &bqb, &SMatrix::identity(), &vector![0.5, 0.5], None)
        .unwrap();
    assert!((f.g_bar() - (0.475 * 2.25 + 0.0575)).abs() < 1e-14);
}

#[test]
fn predict_on_silence_is_the_prediction_and_changes_nothing_else() {
    let (a, bqb) = oscillator();
    let c = SMatrix::<f64, 2, 2>::identity();
    let r = vector![0.5, 0.5];
    let (x0, p0) = (vector![5.0, -1.0], SMatrix::identity() * 3.0);
    let held = TobitFilter::new(paper_cfg(0.1, 0.1), x0, p0).unwrap();
    let cfg = paper_cfg(0.1, 0.1).with_silence(Silence::Predict);
    assert_eq!(cfg.cast::<f32>().unwrap().silence, Silence::Predict);
    let mut f = TobitFilter::new(cfg, x0, p0).unwrap();
    let mut paper = held;
    // An arrival: the same update bit for bit as the paper's filter.
    let y = vector![4.0, -2.0];
    f.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
    paper.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
    assert_eq!(f.estimate(), paper.estimate());
    // Silence: x̂ = A x̂, P̄ = A P̄ Aᵀ + BQBᵀ (written out here), where the paper updates.
    let (x1, p1) = f.estimate().into_parts();
    let (g1, y_held) = (f.g_bar(), *f.held_measurement());
    f.step(&a, &bqb, &c, &r, None).unwrap();
    paper.step(&a, &bqb, &c, &r, None).unwrap();
    let x_pred = a * x1;
    let p_pred = a * p1 * a.transpose() + bqb;
    assert_eq!(*f.estimate().state(), x_pred);
    assert!((f.estimate().covariance() - p_pred).abs().max() < 1e-14);
    assert_ne!(paper.estimate().state(), f.estimate().state());
    assert_eq!(f.last_theta(), 1.0);
    assert_eq!(*f.held_measurement(), y_held);
    assert_eq!(f.g_bar(), f.config().xi(g1));
    assert_eq!(f.g_bar(), paper.g_bar());
}

/// Eq. (30) assembled term by term from the plan's ingredients, written out as printed
/// (independently of `GainProblem::bound`).
fn bound_as_printed(
    plan: &LocalStepPlan<f64, 2, 2>,
    c: &SMatrix<f64, 2, 2>,
    tau: &SVector<f64, 2>,
    k: &SMatrix<f64, 2, 2>,
) -> SMatrix<f64, 2, 2> {
    let kap = |i: usize| plan.kappas.0[i - 1];
    let th = plan.theta;
    let st = &plan.stats;
    let qbar = SMatrix::<f64, 2, 2>::from_diagonal(&st.rho);
    let ups = SMatrix::<f64, 2, 2>::from_diagonal(&st.upsilon);
    let r = SMatrix::<f64, 2, 2>::from_diagonal(&st.sqrt_r.component_mul(&st.sqrt_r));
    let lam_sr = st.lambda.component_mul(&st.sqrt_r);
    let i = SMatrix::<f64, 2, 2>::identity();
    let ikqc = i - k * qbar * c;
    let p = plan.problem.p_prior;
    let omega3 = ups + qbar * qbar.transpose();
    let tt = tau * tau.transpose();
    kap(1) * ikqc * p * ikqc.transpose()
        + (1.0 - th).powi(2) * k * omega3.component_mul(&r) * k.transpose()
        + kap(2) * k * qbar * lam_sr * lam_sr.transpose() * qbar * k.transpose()
        + (1.0 - th).powi(2)
            * kap(3)
            * k
            * c
            * ups.component_mul(&plan.omega1)
            * c.transpose()
            * k.transpose()
        + th * th * kap(4) * k * qbar * c * plan.omega1 * c.transpose() * qbar * k.transpose()
        + th * th * kap(5) * k * plan.omega2 * k.transpose()
        + (1.0 - th).powi(2) * kap(6) * plan.xi * k * k.transpose()
        + th * th * kap(7) * k * (i - qbar) * tt * (i - qbar).transpose() * k.transpose()
        + (1.0 - th).powi(2) * kap(8) * k * ups.component_mul(&tt) * k.transpose()
}

#[test]
fn gain_minimises_the_trace_of_the_bound() {
    // Both θ = 0 and θ = 1, a nonzero τ and a prediction near the threshold so that every
    // term of (30) is active. At the minimiser the finite-difference gradient of tr P̄ in
    // each of the 4 gain entries must vanish: central differences with h = 1e-5 are exact
    // for a quadratic up to rounding (≈1e-16·tr/h² ≈ 1e-6 relative), so the gradient is
    // compared with the gradient scale tr P̄ / ‖K‖ at 1e-6; moving the gain must also
    // increase the trace.
    let (a, bqb) = oscillator();
    let c = matrix![1.0, 0.2; -0.3, 1.0];
    let r = vector![0.5, 0.8];
    let tau = vector![0.3, -0.4];
    let mut cfg = paper_cfg(0.2, 0.2);
    cfg.tau = tau;
    let mut f = TobitFilter::new(cfg, vector![0.4, -0.2], matrix![1.5, 0.2; 0.2, 0.9]).unwrap();
    f.step(&a, &bqb, &c, &r, Some(&vector![0.7, 0.1])).unwrap();
    for received in [Some(vector![0.9, -0.1]), None] {
        let plan = f.plan(&a, &bqb, &c, &r, received.as_ref()).unwrap();
        let k = plan.problem.gain().unwrap();
        let tr = |k: &SMatrix<f64, 2, 2>| bound_as_printed(&plan, &c, &tau, k).trace();
        // The implementation's (30) equals the printed one.
        assert!((plan.problem.bound(&k) - bound_as_printed(&plan, &c, &tau, &k)).amax() < 1e-12);
        let h = 1e-5;
        let scale = tr(&k) / k.norm();
        for idx in 0..4 {
            let mut kp = k;
            kp[idx] += h;
            let mut km = k;
            km[idx] -= h;
            let grad = (tr(&kp) - tr(&km)) / (2.0 * h);
            assert!(
                grad.abs() < 1e-6 * scale,
                "∂tr/∂K[{idx}] = {grad} (θ = {})",
                plan.theta
            );
            assert!(tr(&kp) > tr(&k) && tr(&km) > tr(&k));
        }
    }
}

#[test]
fn reduces_to_kalman_without_censoring_and_with_every_measurement() {
    // τ far below every measurement → ϱ̄ = 1, λ = 0, Υ = 0 exactly; σ = η₀ = 0 → Ξ = 0;
    // ε₁…ε₅ = 1e-12 → κ₁ = 1 + 5e-12. (30) and (37) then are the Kalman equations up to
    // κ₁ − 1 = 5e-12 relative per step; over 100 steps of a stable filter the gap stays
    // below 1e-9 (stated tolerance).
    let trig = EventTriggerConfig::new(0.0, 5.0, 0.5, 0.0).unwrap();
    let mut eps = [0.7; 14];
    for e in eps.iter_mut().take(5) {
        *e = 1e-12;
    }
    let cfg = TobitFilterConfig::new(
        vector![-1e3, -1e3],
        BoundScalars::new(eps).unwrap(),
        trig,
        1.5,
        2.0,
    )
    .unwrap();
    let (a, bqb) = oscillator();
    let c = matrix![1.0, 0.0; 0.3, 1.0];
    let r = vector![0.5, 0.4];
    let x0 = vector![5.0, 0.0];
    let mut tf = TobitFilter::new(cfg, x0, SMatrix::identity()).unwrap();
    let mut kf = KalmanFilter::new(x0, SMatrix::identity()).unwrap();
    for t in 1..=100 {
        let s = t as f64;
        let y = vector![
            5.0 * (0.16 * s).cos() + 0.3 * (2.1 * s).sin(),
            -4.0 * (0.16 * s).sin()
        ];
        tf.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
        kf.predict_with(&a, &bqb).unwrap();
        kf.update_with(&c, &SMatrix::from_diagonal(&r), &y).unwrap();
        assert!(
            (tf.estimate().state() - kf.estimate().state()).amax() < 1e-9,
            "t = {t}"
        );
        assert!(
            (tf.estimate().covariance() - kf.estimate().covariance()).amax() < 1e-9,
            "t = {t}"
        );
    }
}

#[test]
fn placements_agree_when_c_is_diagonal_and_differ_otherwise() {
    let (a, bqb) = oscillator();
    let r = vector![0.5, 0.5];
    let base = paper_cfg(0.1, 0.1);
    let f1 = TobitFilter::new(base, vector![0.2, -0.1], SMatrix::identity()).unwrap();
    let f2 = TobitFilter::new(
        base.with_placement(UpsilonPlacement::OutsideC),
        vector![0.2, -0.1],
        SMatrix::identity(),
    )
    .unwrap();
    let eye = SMatrix::<f64, 2, 2>::identity();
    let y = vector![0.3, 0.2];
    let p1 = f1.plan(&a, &bqb, &eye, &r, Some(&y)).unwrap();
    let p2 = f2.plan(&a, &bqb, &eye, &r, Some(&y)).unwrap();
    assert!((p1.problem.m - p2.problem.m).amax() < 1e-14);
    let c = matrix![1.0, 0.5; 0.5, 1.0];
    let p1 = f1.plan(&a, &bqb, &c, &r, Some(&y)).unwrap();
    let p2 = f2.plan(&a, &bqb, &c, &r, Some(&y)).unwrap();
    assert!((p1.problem.m - p2.problem.m).amax() > 1e-3);
    // As written needs n_x = n_y.
    let cfg1 = TobitFilterConfig::new(
        vector![0.0],
        BoundScalars::paper_example(),
        base.trigger,
        1.5,
        2.0,
    )
    .unwrap();
    assert!(matches!(
        TobitFilter::<f64, 2, 1>::new(cfg1, vector![0.0, 0.0], SMatrix::identity()),
        Err(Error::InvalidConfig {
            field: "placement",
            ..
        })
    ));
    assert!(TobitFilter::<f64, 2, 1>::new(
        cfg1.with_placement(UpsilonPlacement::OutsideC),
        vector![0.0, 0.0],
        SMatrix::identity()
    )
    .is_ok());
}

#[test]
fn far_censored_component_gets_no_gain_and_f32_runs() {
    // Prediction 40 σ below the threshold in component 2: ϱ̄₂ underflows (f32) or is
    // ~1e-350 → 0 (f64); the step must still succeed and the estimate stay finite.
    let (a, bqb) = oscillator();
    let cfg = paper_cfg(0.1, 0.1);
    let mut f = TobitFilter::new(cfg, vector![3.0, -30.0], SMatrix::identity()).unwrap();
    let c = SMatrix::<f64, 2, 2>::identity();
    for t in 0..5 {
        let rec = (t % 2 == 0).then_some(vector![3.0, 0.0]);
        f.step(&a, &bqb, &c, &vector![0.5, 0.5], rec.as_ref())
            .unwrap();
        assert!(f.estimate().state().iter().all(|v| v.is_finite()));
    }
    let cfg32 = cfg.cast::<f32>().unwrap();
    let mut g =
        TobitFilter::<f32, 2, 2>::new(cfg32, vector![5.0, 0.0], SMatrix::identity()).unwrap();
    let mut h = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity()).unwrap();
    for t in 1..=50 {
        let s = t as f64;
        let y = vector![
            (5.0 * (0.16 * s).cos()).max(0.0),
            (-5.0 * (0.16 * s).sin()).max(0.0)
        ];
        let rec = (t % 3 != 0).then_some(y);
        h.step(&a, &bqb, &c, &vector![0.5, 0.5], rec.as_ref())
            .unwrap();
        g.step(
            &a.cast(),
            &bqb.cast(),
            &c.cast(),
            &vector![0.5f32, 0.5],
            rec.map(|y| y.cast()).as_ref(),
        )
        .unwrap();
    }
    // f32 vs f64 of a stable recursion: 1e-3 relative to the state's scale (5).
    assert!((h.estimate().state() - g.estimate().state().cast::<f64>()).amax() < 5e-3);
}

#[test]
fn bad_inputs_rejected_and_state_unchanged() {
    let (a, bqb) = oscillator();
    let c = SMatrix::<f64, 2, 2>::identity();
    let r = vector![0.5, 0.5];
    let cfg = paper_cfg(0.1, 0.1);
    let mut f = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity()).unwrap();
    f.step(&a, &bqb, &c, &r, Some(&vector![4.0, 0.0])).unwrap();
    let before = f;
    assert!(f
        .step(&a, &bqb, &c, &r, Some(&vector![f64::NAN, 0.0]))
        .is_err());
    assert!(f.step(&a, &bqb, &c, &vector![0.5, -1.0], None).is_err());
    assert!(f.step(&(a * f64::INFINITY), &bqb, &c, &r, None).is_err());
    assert!(f
        .reset(vector![0.0, 0.0], matrix![1.0, 2.0; 2.0, 1.0])
        .is_err());
    assert_eq!(f, before);
    assert!(BoundScalars::new([0.0; 14]).is_err());
    assert!(BoundScalars::new([f64::NAN; 14]).is_err());
    assert!(TobitFilterConfig::new(
        vector![0.0],
        BoundScalars::paper_example(),
        cfg.trigger,
        -1.0,
        2.0
    )
    .is_err());
    assert!(TobitFilter::new(cfg, vector![0.0, 0.0], SMatrix::zeros()).is_err());
    assert!(diagonal_variances(&matrix![1.0, 0.3; 0.3, 1.0]).is_err());
}
