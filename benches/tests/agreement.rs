//! The side-by-side benchmarks only mean something if both filters compute the same step:
//! our posterior must agree with `adskalman`'s (an independent implementation) on every
//! benchmark problem. No timing here.

use benches::ads::AdsProblem;
use benches::problems::{occlusion_3x2_f64, tracking_4x2_f32, KfProblem};

/// Our step against `adskalman`'s in both covariance forms the benches compare: Joseph
/// (`kf_step` against `JosephForm`) and the optimal-gain form (`kf_standard_step` against
/// `OptimalKalmanForcedSymmetric`). The tolerance is relative to the entries' magnitude
/// (floors `sx` and `sp`), the error being rounding of the same algebra in a different order
/// (`adskalman` inverts S, we solve).
fn agree<T, const NX: usize, const NY: usize>(p: &KfProblem<T, NX, NY>, rel: f64, sp: f64)
where
    T: estimator_core::Real + na35::RealField + Copy,
    na35::Const<NY>: na35::DimMin<na35::Const<NY>, Output = na35::Const<NY>>,
{
    let a = AdsProblem::from_core(p);
    for joseph in [true, false] {
        let ours = if joseph {
            p.kf_step()
        } else {
            p.kf_standard_step()
        }
        .expect("our step");
        let (x, pp) = a.posterior(joseph).expect("adskalman step");
        let dx = (ours.estimate().state() - x).amax().to_f64();
        let dp = (ours.estimate().covariance() - pp).amax().to_f64();
        let sx = x.amax().to_f64().max(1.0);
        let sp = pp.amax().to_f64().max(sp);
        assert!(
            dx < rel * sx,
            "joseph={joseph}: {} vs {}",
            ours.estimate().state(),
            x
        );
        assert!(dp < rel * sp, "joseph={joseph}: covariance off by {dp}");
        assert_eq!(
            ours.estimate().covariance(),
            &ours.estimate().covariance().transpose()
        );
    }
}

#[test]
fn ours_and_adskalman_agree_on_the_3x2_f64_problem() {
    // A few ulps of entries of magnitude ≤ ~1e2.
    agree(&occlusion_3x2_f64(), 1e-13, 1.0);
}

#[test]
fn ours_and_adskalman_agree_on_the_4x2_f32_problem() {
    // f32: relative 1e-5.
    agree(&tracking_4x2_f32(), 1e-5, 1e-3);
}

#[test]
fn the_two_forms_differ_only_by_rounding_at_the_optimal_gain() {
    // Joseph and P − K Gᵀ are equal for the optimal gain: if the benches' two forms differed
    // by more than rounding, the second comparison would not be of the same step.
    let p = occlusion_3x2_f64();
    let j = p.kf_step().unwrap();
    let s = p.kf_standard_step().unwrap();
    assert_eq!(j.estimate().state(), s.estimate().state());
    assert!((j.estimate().covariance() - s.estimate().covariance()).amax() < 1e-12);
    assert!(
        j.estimate().covariance() != s.estimate().covariance(),
        "the forms must be different code paths"
    );
}

#[test]
fn the_prior_is_converged_so_every_timed_step_does_the_same_work() {
    // One more step from the steady state barely moves the covariance.
    let p = occlusion_3x2_f64();
    let post = p.kf_step().expect("step");
    let rel = (post.estimate().covariance() - p.prior.estimate().covariance()).amax()
        / p.prior.estimate().covariance().amax();
    assert!(rel < 1e-9, "covariance still moving: {rel}");
}
