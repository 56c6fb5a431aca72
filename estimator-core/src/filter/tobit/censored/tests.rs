use super::*;
use crate::filter::KalmanFilter;
use nalgebra::{matrix, vector};

/// Moments of x given z_j = x_j + v_j ≤ τ_j for the axes in `censored` (C = I), by a midpoint
/// grid over x weighted with the exact likelihood Π_j Φ((τ_j − x_j)/√r_j) — independent of the
/// truncated-moment kernel (Φ from libm's erfc).
fn grid(
    x: &SVector<f64, 2>,
    p: &SMatrix<f64, 2, 2>,
    r: [f64; 2],
    tau: [f64; 2],
    censored: [bool; 2],
) -> (SVector<f64, 2>, SMatrix<f64, 2, 2>) {
    let pi = p.try_inverse().unwrap();
    let phi = |t: f64| 0.5 * libm::erfc(-t / core::f64::consts::SQRT_2);
    let (n, half) = (1500, 8.0);
    let (sd0, sd1) = (p[(0, 0)].sqrt(), p[(1, 1)].sqrt());
    let (mut w, mut m, mut mm) = (
        0.0,
        SVector::<f64, 2>::zeros(),
        SMatrix::<f64, 2, 2>::zeros(),
    );
    for i in 0..n {
        for j in 0..n {
            let u = vector![
                x[0] + sd0 * half * (2.0 * (i as f64 + 0.5) / n as f64 - 1.0),
                x[1] + sd1 * half * (2.0 * (j as f64 + 0.5) / n as f64 - 1.0)
            ];
            let d = u - x;
            let mut dens = (-0.5 * d.dot(&(pi * d))).exp();
            for a in 0..2 {
                if censored[a] {
                    dens *= phi((tau[a] - u[a]) / r[a].sqrt());
                }
            }
            w += dens;
            m += u * dens;
            mm += u * u.transpose() * dens;
        }
    }
    let m = m / w;
    (m, mm / w - m * m.transpose())
}

fn run(
    x: SVector<f64, 2>,
    p: SMatrix<f64, 2, 2>,
    r: [f64; 2],
    y: SVector<f64, 2>,
    tau: SVector<f64, 2>,
) -> (SVector<f64, 2>, SMatrix<f64, 2, 2>) {
    let (mut xs, mut ps) = (x, p);
    let c = SMatrix::<f64, 2, 2>::identity();
    let rv = vector![r[0], r[1]];
    observe(&mut xs, &mut ps, &c, &rv, &y, &tau).unwrap();
    truncate_censored(&mut xs, &mut ps, &c, &rv, &y, &tau).unwrap();
    (xs, ps)
}

#[test]
fn one_censored_component_is_exact() {
    // One axis censored, the prior correlated: (C2)-(C3) are the exact moments. Tolerance
    // 1e-6: the midpoint grid's error at 1500² cells over ±8σ.
    let (x, p) = (vector![0.4, -0.3], matrix![0.9, 0.5; 0.5, 0.7]);
    let tau = vector![0.0, 0.0];
    let (xs, ps) = run(x, p, [0.5, 0.5], vector![0.0, 0.8], tau);
    // Axis 2 observed: the grid's prior is the Kalman posterior on it.
    let mut kf = KalmanFilter::new(x, p).unwrap();
    kf.update_with(
        &matrix![0.0, 1.0],
        &matrix![0.5],
        &SVector::<f64, 1>::new(0.8),
    )
    .unwrap();
    let (xk, pk) = kf.estimate().into_parts();
    let (xg, pg) = grid(&xk, &pk, [0.5, 0.5], [0.0, 0.0], [true, false]);
    assert!(
        (xs - xg).amax() < 1e-6 && (ps - pg).amax() < 1e-6,
        "{xs} {xg} {ps} {pg}"
    );
}

#[test]
fn two_censored_components_against_a_2d_quadrature() {
    // Both axes censored (the example's low phase: every sensor reads τ). The sequence is the
    // assumed-density approximation; its error against the exact posterior moments is what
    // docs/tobit-fusion.md reports. Stated bounds: 2 % of the posterior standard deviation in
    // x̂ and 8 % of P's scale, for prior correlations 0 (exact: the axes are then independent)
    // up to 0.8 (the error grows with the correlation: 0.6 % and 6.8 % at 0.8).
    for (rho, exact) in [(0.0, true), (0.3, false), (0.5, false), (0.8, false)] {
        let p = matrix![1.0, rho * 0.8; rho * 0.8, 0.64];
        let x = vector![0.3, 0.2];
        let (xs, ps) = run(x, p, [0.5, 0.5], vector![0.0, 0.0], vector![0.0, 0.0]);
        let (xg, pg) = grid(&x, &p, [0.5, 0.5], [0.0, 0.0], [true, true]);
        let sd = pg[(0, 0)].sqrt().min(pg[(1, 1)].sqrt());
        let (dx, dp) = ((xs - xg).amax() / sd, (ps - pg).amax() / pg.amax());
        std::println!("rho {rho}: x̂ off by {dx:.4} sd, P off by {dp:.4} of its scale");
        if exact {
            assert!(dx < 1e-5 && dp < 1e-5, "rho {rho}: {dx} {dp}");
        } else {
            assert!(dx < 0.02 && dp < 0.08, "rho {rho}: {dx} {dp}");
        }
    }
}

#[test]
fn observed_components_are_the_kalman_update() {
    let (x, p) = (vector![1.0, 2.0], matrix![0.9, 0.3; 0.3, 0.4]);
    let c = matrix![1.0, 0.5; -0.2, 1.0];
    let r = vector![0.3, 0.6];
    let y = vector![1.7, 1.1];
    let (mut xs, mut ps) = (x, p);
    let (nis, dof) = observe(&mut xs, &mut ps, &c, &r, &y, &vector![-10.0, -10.0]).unwrap();
    let mut kf = KalmanFilter::new(x, p).unwrap();
    kf.update_with(&c, &SMatrix::from_diagonal(&r), &y).unwrap();
    assert!((xs - kf.estimate().state()).amax() < 1e-14);
    assert!((ps - kf.estimate().covariance()).amax() < 1e-14);
    // The sequential NIS is the joint one.
    let s = c * p * c.transpose() + SMatrix::from_diagonal(&r);
    let d = y - c * x;
    assert_eq!(dof, 2);
    let joint: f64 = d.dot(&(s.try_inverse().unwrap() * d));
    assert!((nis - joint).abs() < 1e-13);
}

#[test]
fn a_far_censored_component_stays_finite_and_bad_input_changes_nothing() {
    // The prior 40 σ above τ and the component censored: the kernel's tail-accurate moments.
    let (mut x, mut p) = (vector![40.0, 0.0], SMatrix::<f64, 2, 2>::identity());
    condition(
        &mut x,
        &mut p,
        &vector![1.0, 0.0],
        0.01,
        Component::AtMost(0.0),
    )
    .unwrap();
    // By hand: E{z | z ≤ 0} = μ − √s λ(μ/√s) for z ~ N(40, 1.01), and x | z has the mean
    // 40 + (z − 40)/1.01.
    let s = 1.01f64.sqrt();
    let ez = 40.0 - s * crate::gauss::inv_mills(40.0 / s);
    assert!((x[0] - (40.0 + (ez - 40.0) / 1.01)).abs() < 1e-10, "{x}");
    assert!(p[(0, 0)] > 0.0 && p[(0, 0)] < 0.011, "{p}");
    let (x0, p0) = (x, p);
    for bad in [
        condition(
            &mut x,
            &mut p,
            &vector![1.0, 0.0],
            f64::NAN,
            Component::Observed(1.0),
        ),
        condition(
            &mut x,
            &mut p,
            &vector![1.0, 0.0],
            -5.0,
            Component::Observed(1.0),
        ),
        condition(
            &mut x,
            &mut p,
            &vector![1.0, 0.0],
            0.1,
            Component::Observed(f64::INFINITY),
        ),
    ] {
        assert!(bad.is_err());
        assert_eq!((x, p), (x0, p0));
    }
    // f32 runs the same path.
    let (mut xf, mut pf) = (vector![0.5f32, 0.0], SMatrix::<f32, 2, 2>::identity());
    condition(
        &mut xf,
        &mut pf,
        &vector![1.0, 0.0],
        0.5,
        Component::AtMost(0.0),
    )
    .unwrap();
    assert!(xf[0] < 0.5 && pf[(0, 0)] < 1.0);
}
