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
    occlusion_section();
}

/// Seed 001 (issue 4): CCE, ADF and KF-IO steps on the paper's example, arrivals, dropouts
/// and error paths.
fn occlusion_section() {
    use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
    use estimator_core::gsum::GaussSum;
    use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
    let m = LinearModel::<f64, 3, 3, 2, 2>::new(
        matrix![1.01, 0.1, 0.0; 0.0, 1.01, 0.1; 0.0, 0.0, -1.02],
        SMatrix::identity(),
        matrix![2.0, 3.0, 1.0; 1.0, 0.0, 0.98],
        SMatrix::identity(),
        SMatrix::identity() * 0.3,
        SMatrix::identity() * 0.2,
    )
    .unwrap();
    let occ = Occlusion::new(
        matrix![1.0, 0.0, 0.0],
        matrix![0.1],
        OcclusionRegions::new(
            [vector![20.0], vector![40.0], vector![60.0], vector![80.0]],
            [5.0; 4],
        )
        .unwrap(),
    )
    .unwrap();
    let g = GaussSum::<f64, 1, 15>::uniform().unwrap();
    let x0 = vector![5.0, 5.0, 5.0];
    let p0 = SMatrix::<f64, 3, 3>::identity() * 4.0;
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
                let y_opt = if k % 3 == 0 { None } else { Some(&y) };
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
