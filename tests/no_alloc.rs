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
}
