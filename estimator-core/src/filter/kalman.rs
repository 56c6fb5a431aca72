//! The Kalman filter: predict and update, Joseph-form covariance update, symmetrised
//! covariance after every step.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{kalman_innovation, GateCounts, GatedStep, InnovationGate};
use crate::filter::time_update::{check_predicted, predict_raw, predicted_error};
use crate::linalg::small::{self as small, SmallLdl};
use crate::linalg::{all_finite, check_finite, symmetrize};
use crate::model::LinearSystem;
use crate::{CovarianceForm, CovarianceUpdate};
use crate::{Error, Real, Result};

/// Kalman filter on `NX` states.
///
/// The measurement dimension is a parameter of each update, so one filter can take
/// measurements of different sizes.
///
/// `F` is where the covariance form is decided: by default at run time (a
/// [`CovarianceUpdate`] the filter holds, Joseph unless
/// [`KalmanFilter::with_covariance_update`] says otherwise); with [`crate::JosephForm`] or
/// [`crate::StandardForm`] ([`KalmanFilter::with_form`]) at compile time, so that the filter's
/// code contains that form only (what a microcontroller's flash wants). The same form gives
/// the same bits either way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KalmanFilter<T: Real, const NX: usize, F: CovarianceForm = CovarianceUpdate> {
    est: Estimate<T, NX>,
    form: F,
    nis: T,
}

impl<T: Real, const NX: usize> KalmanFilter<T, NX> {
    /// Starts from the estimate `x0` with covariance `p0` (finite, symmetric positive
    /// definite).
    pub fn new(x0: SVector<T, NX>, p0: SMatrix<T, NX, NX>) -> Result<Self> {
        Ok(Self {
            est: Estimate::new(x0, p0)?,
            form: CovarianceUpdate::Joseph,
            nis: T::zero(),
        })
    }

    /// Selects the covariance update form (Joseph by default).
    #[must_use]
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.form = form;
        self
    }
}

impl<T: Real, const NX: usize, F: CovarianceForm> KalmanFilter<T, NX, F> {
    /// The same filter with its covariance form decided by `form`'s type: a
    /// [`CovarianceUpdate`] (run time) or [`crate::JosephForm`] / [`crate::StandardForm`]
    /// (compile time).
    #[must_use]
    pub fn with_form<G: CovarianceForm>(self, form: G) -> KalmanFilter<T, NX, G> {
        KalmanFilter {
            est: self.est,
            form,
            nis: self.nis,
        }
    }

    /// The covariance form the updates use.
    #[inline]
    pub fn covariance_update(&self) -> CovarianceUpdate {
        self.form.form()
    }

    /// Current estimate x̂ and error covariance P.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }

    /// Normalised innovation squared `νᵀ S⁻¹ ν` of the last successful update (0 before any).
    /// Its mean is `NY` for a consistent filter.
    #[inline]
    pub fn last_nis(&self) -> T {
        self.nis
    }

    /// Overwrites estimate and covariance (validated like [`KalmanFilter::new`]).
    pub fn reset(&mut self, x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Result<()> {
        self.est = Estimate::new(x, p)?;
        self.nis = T::zero();
        Ok(())
    }

    /// Time update from instant `k` to `k + 1`: `x ← A_k x (+ G_k u_k)`,
    /// `P ← A_k P A_kᵀ + B_k Q_k B_kᵀ`.
    pub fn predict<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
    ) -> Result<()> {
        match model.input(k) {
            None => self.predict_with(&model.a(k), &model.process_cov(k)),
            Some(gu) => self.predict_with_input(&model.a(k), &model.process_cov(k), &gu),
        }
    }

    /// [`KalmanFilter::predict_with`] plus a known input term: `x ← A x + gu`.
    pub fn predict_with_input(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        q: &SMatrix<T, NX, NX>,
        gu: &SVector<T, NX>,
    ) -> Result<()> {
        let (x, p) = predict_raw(self.est.state(), self.est.covariance(), a, &symmetrize(q));
        let x = x + gu;
        check_predicted(&x, &p)?;
        self.est = Estimate::trusted(x, p);
        Ok(())
    }

    /// Time update with explicit matrices `A` and effective process covariance `Q`.
    /// `Q` is symmetrised first (the model path trusts [`LinearSystem`]'s symmetric `Q`).
    pub fn predict_with(&mut self, a: &SMatrix<T, NX, NX>, q: &SMatrix<T, NX, NX>) -> Result<()> {
        let (x, p) = predict_raw(self.est.state(), self.est.covariance(), a, &symmetrize(q));
        check_predicted(&x, &p)?;
        self.est = Estimate::trusted(x, p);
        Ok(())
    }

    /// Measurement update with `y_k` and the model's `C_k`, `D_k R_k D_kᵀ`.
    pub fn update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
    ) -> Result<()> {
        self.update_with(&model.c(k), &model.measurement_cov(k), y)
    }

    /// Measurement update with explicit `C` and effective measurement covariance `R`
    /// (symmetrised first, like `Q` in [`KalmanFilter::predict_with`]).
    pub fn update_with<const NY: usize>(
        &mut self,
        c: &SMatrix<T, NY, NX>,
        r: &SMatrix<T, NY, NY>,
        y: &SVector<T, NY>,
    ) -> Result<()> {
        check_finite(y, "measurement")?;
        let (x, p, nis) = kalman_update(
            self.est.state(),
            self.est.covariance(),
            c,
            &symmetrize(r),
            y,
            self.form.form(),
        )?;
        self.est = Estimate::trusted(x, p);
        self.nis = nis;
        Ok(())
    }

    /// One sampling instant `k ≥ 1`: predict from `k − 1`, then update with `y_k`.
    /// On error nothing changes (the prediction is rolled back too).
    pub fn step<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
    ) -> Result<()> {
        check_finite(y, "measurement")?;
        // Fast path: predict and update into locals and commit once (no saved copy, no
        // rollback). Same arithmetic as `predict` then `update`, so bit-identical results.
        // The prediction's finiteness is checked only if the update fails: a non-finite
        // prediction always makes the update fail (NaN and ∞ reach S or x⁺ through every
        // product, 0·∞ included), and the error is then the one `predict` would have given.
        let j = k.saturating_sub(1);
        // A known input: the scalar path, which adds it to the prediction (the lanes fuse
        // the prediction into the update).
        if let Some(gu) = model.input(j) {
            let (x, p, nis) = self.step_scalar(model, j, k, y, Some(&gu))?;
            self.est = Estimate::trusted(x, p);
            self.nis = nis;
            return Ok(());
        }
        // With `simd`, predict and update on lanes (the same bits as the scalar path); a
        // refusal there takes the scalar path, which names the error.
        #[cfg(simd_lanes)]
        let lanes = crate::linalg::lanes::step(
            self.est.state(),
            self.est.covariance(),
            &model.a(j),
            &model.process_cov(j),
            &model.c(k),
            &model.measurement_cov(k),
            y,
            self.form.form(),
        );
        #[cfg(not(simd_lanes))]
        let lanes = None;
        let (x, p, nis) = match lanes {
            Some(out) => out,
            None => self.step_scalar(model, j, k, y, None)?,
        };
        self.est = Estimate::trusted(x, p);
        self.nis = nis;
        Ok(())
    }

    /// [`KalmanFilter::step`] behind an innovation gate (docs/gate.md): a `y_k` whose NIS
    /// against the prediction `gate` does not admit is not used (the step is the prediction
    /// only). Returns whether `y_k` was used. An admitted step is [`KalmanFilter::step`], bit
    /// for bit; so is every step with [`InnovationGate::off`]. On error nothing changes.
    pub fn step_gated<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        if !gate.is_off() {
            check_finite(y, "measurement")?;
            let j = k.saturating_sub(1);
            let (x, p) = (self.est.state(), self.est.covariance());
            let (xp, pp) = predict_raw(x, p, &model.a(j), &model.process_cov(j));
            if !(all_finite(&xp) && all_finite(&pp)) {
                check_predicted(&xp, &pp)?;
            }
            let (nu, s) = kalman_innovation(&xp, &pp, &model.c(k), &model.measurement_cov(k), y);
            if !gate.admits(&nu, &s)? {
                self.est = Estimate::trusted(xp, pp);
                return Ok(false);
            }
        }
        self.step(model, k, y)?;
        Ok(true)
    }

    /// [`KalmanFilter::update_with`] behind an innovation gate: a `y` whose NIS against the
    /// current estimate `gate` does not admit leaves the filter as it is. Returns whether `y`
    /// was used. On error nothing changes.
    pub fn update_gated_with<const NY: usize>(
        &mut self,
        c: &SMatrix<T, NY, NX>,
        r: &SMatrix<T, NY, NY>,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        if !gate.is_off() {
            check_finite(y, "measurement")?;
            let (nu, s) = kalman_innovation(
                self.est.state(),
                self.est.covariance(),
                c,
                &symmetrize(r),
                y,
            );
            if !gate.admits(&nu, &s)? {
                return Ok(false);
            }
        }
        self.update_with(c, r, y)?;
        Ok(true)
    }

    /// `step`'s scalar path: every target without `simd`, and the exact error after the
    /// lanes refused (then out of line and cold, so that the lanes' fast path stays small).
    #[cfg_attr(simd_lanes, cold, inline(never))]
    #[cfg_attr(not(simd_lanes), inline(always))]
    #[allow(clippy::type_complexity)]
    fn step_scalar<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        j: usize,
        k: usize,
        y: &SVector<T, NY>,
        gu: Option<&SVector<T, NX>>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
        let (x, p) = (self.est.state(), self.est.covariance());
        let (mut x_pred, p_pred) = predict_raw(x, p, &model.a(j), &model.process_cov(j));
        if let Some(gu) = gu {
            x_pred += gu;
        }
        let out = kalman_update_scalar(
            &x_pred,
            &p_pred,
            &model.c(k),
            &model.measurement_cov(k),
            y,
            self.form.form(),
        );
        // The prediction's error first (see `step`); inlined, so that a caller that only asks
        // whether the step succeeded computes neither.
        match out {
            Ok(out) => Ok(out),
            Err(e) => Err(predicted_error(&x_pred, &p_pred).unwrap_or(e)),
        }
    }
}

impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>, F: CovarianceForm>
    Estimator<T, NX> for OnModel<M, KalmanFilter<T, NX, F>, NY>
{
    type Measurement = SVector<T, NY>;

    /// [`KalmanFilter::step`] on the pair's model.
    #[inline]
    fn step(&mut self, k: usize, y: &SVector<T, NY>) -> Result<()> {
        self.filter.step(&self.model, k, y)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

/// The gated step: `y_k` is used iff the gate admits it.
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>, F: CovarianceForm>
    GatedStep<T, NX> for OnModel<M, KalmanFilter<T, NX, F>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let used = self.filter.step_gated(&self.model, k, y, gate)?;
        Ok(GateCounts::one(used))
    }
}

/// The update equations on explicit arguments; returns `(x⁺, P⁺, NIS)`.
///
/// `P` must be symmetric (only products of it are formed, and `S = C P Cᵀ + R` is built on its
/// upper triangle, so `R`'s upper triangle is read). `P⁺` is exactly symmetric.
///
/// Shared by the estimators that run a Kalman update inside a larger step.
#[inline(always)]
pub fn kalman_update<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    y: &SVector<T, NY>,
    form: CovarianceUpdate,
) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
    #[cfg(simd_lanes)]
    if let Some(out) = crate::linalg::lanes::kalman_update(x, p, c, r, y, form) {
        return Ok(out); // the same bits as the scalar kernels, several entries at a time
    }
    kalman_update_scalar(x, p, c, r, y, form)
}

/// [`kalman_update`] on the scalar kernels of [`crate::linalg::small`] (every target; the
/// reference the SIMD lanes are tested against bit for bit).
#[inline(always)]
pub(crate) fn kalman_update_scalar<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    y: &SVector<T, NY>,
    form: CovarianceUpdate,
) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
    // G = P Cᵀ, S = C G + R. K = G S⁻¹ by an L D Lᵀ solve; S not PD means R or P is broken.
    // One factor serves the gain and the NIS.
    let g = small::mul_t(p, c);
    let s = small::sym_mul_add(c, &g, r);
    let chol = SmallLdl::new(&s, "innovation covariance")?;
    let k = chol.solve_right(&g);
    let nu = y - small::mul_vec(c, x);
    let x_new = x + small::mul_vec(&k, &nu);
    let p_new = match form {
        // (I − KC) P (I − KC)ᵀ + K R Kᵀ: a sum of two congruences, each PSD under rounding.
        // (I − KC) P is formed as P − K (C P) = P − K Gᵀ: the same product, associated so
        // that it costs NX²·NY multiplications instead of NX³.
        CovarianceUpdate::Joseph => {
            let i_kc = small::identity_sub_mul(&k, c);
            let i_kc_p = small::sub_mul_t(p, &k, &g);
            small::sym_mul_t_add(&i_kc_p, &i_kc, &small::congruence(&k, r))
        }
        // P − K Gᵀ (= (I − KC) P); K Gᵀ = G S⁻¹ Gᵀ is symmetric for the optimal gain.
        CovarianceUpdate::Standard => p - small::sym_mul_t(&k, &g),
    };
    // NIS = νᵀ S⁻¹ ν with the same factor. A validated factor has pivots above the
    // singularity floor, so a non-finite K or NIS can only come from non-finite inputs and is
    // caught by the checks on x⁺, P⁺ and the NIS. The error names the first that is not
    // finite, from the same three tests: a caller that only asks whether the update succeeded
    // computes no name.
    let nis = chol.mahalanobis(&nu);
    let (x_ok, p_ok) = (all_finite(&x_new), all_finite(&p_new));
    if !(x_ok && p_ok && nis.finite()) {
        let what = if !x_ok {
            "updated state"
        } else if !p_ok {
            "updated covariance"
        } else {
            "innovation"
        };
        return Err(Error::NonFinite { what });
    }
    Ok((x_new, p_new, nis))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LinearModel;
    use nalgebra::{matrix, vector};

    fn scalar_model(a: f64, q: f64, r: f64) -> LinearModel<f64, 1, 1, 1, 1> {
        LinearModel::new(
            matrix![a],
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![q],
            matrix![r],
        )
        .unwrap()
    }

    #[test]
    fn one_step_by_hand() {
        // x̂⁻ = 0.9·2 = 1.8, P⁻ = 0.81·1 + 0.5 = 1.31, K = 1.31/(1.31 + 2) = 0.395770...,
        // x̂ = 1.8 + K(3 − 1.8), P = (1 − K) 1.31.
        let m = scalar_model(0.9, 0.5, 2.0);
        let mut kf = KalmanFilter::new(vector![2.0], matrix![1.0]).unwrap();
        kf.step(&m, 1, &vector![3.0]).unwrap();
        let k = 1.31 / 3.31;
        assert!((kf.estimate().state()[0] - (1.8 + k * 1.2)).abs() < 1e-15);
        assert!((kf.estimate().covariance()[(0, 0)] - (1.0 - k) * 1.31).abs() < 1e-15);
        assert!((kf.last_nis() - 1.2 * 1.2 / 3.31).abs() < 1e-15);
    }

    #[test]
    fn converges_to_scalar_riccati_solution() {
        // Prior steady state solves P = a² P r/(P + r) + q:
        // P² + (r − a² r − q) P − q r = 0.
        let (a, q, r) = (0.95f64, 0.3f64, 1.7f64);
        let bq = r - a * a * r - q;
        let p_prior = (-bq + (bq * bq + 4.0 * q * r).sqrt()) / 2.0;
        let p_post = p_prior * r / (p_prior + r);
        let m = scalar_model(a, q, r);
        let mut kf = KalmanFilter::new(vector![0.0], matrix![100.0]).unwrap();
        for k in 1..200 {
            kf.step(&m, k, &vector![0.0]).unwrap();
        }
        assert!((kf.estimate().covariance()[(0, 0)] - p_post).abs() < 1e-12);
    }

    #[test]
    fn joseph_and_standard_forms_agree_for_optimal_gain() {
        let m = LinearModel::<f64, 3, 3, 2, 2>::new(
            matrix![1.0, 0.1, 0.0; 0.0, 1.0, 0.1; 0.0, 0.0, 0.95],
            SMatrix::identity(),
            matrix![1.0, 0.0, 0.0; 0.0, 0.0, 1.0],
            SMatrix::identity(),
            matrix![0.01, 0.0, 0.0; 0.0, 0.02, 0.0; 0.0, 0.0, 0.03],
            matrix![0.5, 0.1; 0.1, 0.4],
        )
        .unwrap();
        let p0 = matrix![2.0, 0.3, 0.0; 0.3, 1.0, 0.1; 0.0, 0.1, 0.5];
        let mut j = KalmanFilter::new(vector![0.0, 1.0, -1.0], p0).unwrap();
        let mut s = j.with_covariance_update(CovarianceUpdate::Standard);
        for k in 1..50 {
            let y = vector![(k as f64 * 0.3).sin(), (k as f64 * 0.1).cos()];
            j.step(&m, k, &y).unwrap();
            s.step(&m, k, &y).unwrap();
        }
        assert!((j.estimate().covariance() - s.estimate().covariance()).amax() < 1e-12);
        assert!((j.estimate().state() - s.estimate().state()).amax() < 1e-12);
    }

    #[test]
    fn f32_agrees_with_f64() {
        let m64 = LinearModel::<f64, 2, 2, 1, 1>::new(
            matrix![1.0, 0.1; 0.0, 0.98],
            SMatrix::identity(),
            matrix![1.0, 0.0],
            matrix![1.0],
            matrix![0.01, 0.0; 0.0, 0.04],
            matrix![0.25],
        )
        .unwrap();
        let m32 = m64.cast::<f32>().unwrap();
        let mut a = KalmanFilter::new(vector![0.0, 0.0], SMatrix::identity()).unwrap();
        let mut b = KalmanFilter::<f32, 2>::new(vector![0.0, 0.0], SMatrix::identity()).unwrap();
        for k in 1..500 {
            let y = (k as f64 * 0.05).sin() * 3.0;
            a.step(&m64, k, &vector![y]).unwrap();
            b.step(&m32, k, &vector![y as f32]).unwrap();
        }
        // f32 carries ~7 digits; a stable filter forgets rounding, so the gap stays at the
        // level of a few thousand ulps of the state's magnitude (≈3): 1e-4 absolute.
        for i in 0..2 {
            assert!((a.estimate().state()[i] - b.estimate().state()[i] as f64).abs() < 1e-4);
            for j in 0..2 {
                assert!(
                    (a.estimate().covariance()[(i, j)] - b.estimate().covariance()[(i, j)] as f64)
                        .abs()
                        < 1e-5
                );
            }
        }
    }

    #[test]
    fn fused_step_is_bit_identical_to_predict_then_update() {
        let m = crate::papers::Seed001Example::model::<f64>().unwrap();
        let mut fused =
            KalmanFilter::new(vector![5.0, 5.0, 5.0], SMatrix::identity() * 4.0).unwrap();
        let mut split = fused;
        for k in 1..100 {
            let y = vector![(k as f64 * 0.7).sin() * 10.0, (k as f64 * 0.3).cos() * 5.0];
            fused.step(&m, k, &y).unwrap();
            split.predict(&m, k - 1).unwrap();
            split.update(&m, k, &y).unwrap();
            assert_eq!(fused, split, "k = {k}");
        }
    }

    #[test]
    fn fused_step_reports_a_non_finite_prediction_like_predict() {
        // A = 1e200 is finite, but A P Aᵀ overflows to ∞: the step must fail with the
        // prediction's error (not the innovation's) and keep its state.
        let m = scalar_model(1e200, 0.5, 2.0);
        let mut kf = KalmanFilter::new(vector![0.0], matrix![1.0]).unwrap();
        let before = kf;
        let want = Err(Error::NonFinite {
            what: "predicted covariance",
        });
        assert_eq!(kf.step(&m, 1, &vector![1.0]), want);
        assert_eq!(kf, before);
        assert_eq!(kf.predict(&m, 0), want);
        assert_eq!(kf, before);
        let m = scalar_model(1e200, 1e-300, 2.0);
        let mut kf = KalmanFilter::new(vector![1e200], matrix![1e-300]).unwrap();
        let before = kf;
        assert_eq!(
            kf.step(&m, 1, &vector![1.0]),
            Err(Error::NonFinite {
                what: "predicted state"
            })
        );
        assert_eq!(kf, before);
    }

    #[test]
    fn bad_input_is_an_error_and_leaves_state_unchanged() {
        let m = scalar_model(0.9, 0.5, 2.0);
        let mut kf = KalmanFilter::new(vector![2.0], matrix![1.0]).unwrap();
        kf.step(&m, 1, &vector![3.0]).unwrap();
        let before = kf;
        assert_eq!(
            kf.step(&m, 2, &vector![f64::NAN]),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(kf, before);
        assert!(kf
            .update_with(&matrix![1.0], &matrix![-1.0], &vector![1.0])
            .is_err());
        assert_eq!(kf, before);
        assert!(kf
            .predict_with(&matrix![f64::INFINITY], &matrix![1.0])
            .is_err());
        assert_eq!(kf, before);
        assert_eq!(
            KalmanFilter::new(vector![0.0], matrix![0.0]),
            Err(Error::NotPositiveDefinite { what: "P0" })
        );
    }
}

/// The SIMD lanes of [`crate::linalg::lanes`] against the scalar kernels, bit for bit.
#[cfg(all(test, simd_lanes))]
mod lanes_tests {
    use super::kalman_update_scalar as scalar_update;
    use crate::linalg::lanes::{kalman_update, predict, step};
    use crate::linalg::small;
    use crate::{CovarianceUpdate, Real};
    use nalgebra::{SMatrix, SVector};

    /// A deterministic pseudo-random stream in [-1, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    fn spd<T: Real, const N: usize>(g: &mut Lcg, shift: f64) -> SMatrix<T, N, N> {
        let b = SMatrix::<f64, N, N>::from_fn(|_, _| g.next());
        let m = b * b.transpose() + SMatrix::identity() * shift;
        let m = (m + m.transpose()) * 0.5;
        m.map(T::lit)
    }

    /// Bit for bit (on the bits, so that −0 ≠ +0 and NaN would be caught too).
    fn same<T: Real>(a: &[T], b: &[T]) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(u, v)| u.to_f64().to_bits() == v.to_f64().to_bits())
    }

    fn case<T: Real, const NX: usize, const NY: usize>(g: &mut Lcg) {
        let x = SVector::<T, NX>::from_fn(|_, _| T::lit(g.next() * 10.0));
        let p = spd::<T, NX>(g, 0.5);
        let a = SMatrix::<T, NX, NX>::from_fn(|_, _| T::lit(g.next()));
        let q = spd::<T, NX>(g, 0.1);
        let c = SMatrix::<T, NY, NX>::from_fn(|_, _| T::lit(g.next()));
        let r = spd::<T, NY>(g, 0.2);
        let y = SVector::<T, NY>::from_fn(|_, _| T::lit(g.next() * 5.0));
        let (xs, ps) = (small::mul_vec(&a, &x), small::congruence_add(&a, &p, &q));
        let (xl, pl) = predict(&x, &p, &a, &q).expect("lanes apply");
        assert!(same(xs.as_slice(), xl.as_slice()), "predicted x, NX={NX}");
        assert!(same(ps.as_slice(), pl.as_slice()), "predicted P, NX={NX}");
        for form in [CovarianceUpdate::Joseph, CovarianceUpdate::Standard] {
            let want = scalar_update(&xs, &ps, &c, &r, &y, form).expect("valid problem");
            let got = kalman_update(&xs, &ps, &c, &r, &y, form).expect("lanes apply");
            let fused = step(&x, &p, &a, &q, &c, &r, &y, form).expect("lanes apply");
            for got in [got, fused] {
                assert!(same(want.0.as_slice(), got.0.as_slice()), "x {form:?}");
                assert!(same(want.1.as_slice(), got.1.as_slice()), "P {form:?}");
                assert!(same(&[want.2], &[got.2]), "NIS {form:?}");
            }
        }
    }

    #[test]
    fn lanes_are_bit_identical_to_the_scalar_kernels() {
        let mut g = Lcg(7);
        for _ in 0..200 {
            case::<f64, 1, 1>(&mut g);
            case::<f64, 2, 1>(&mut g);
            case::<f64, 2, 2>(&mut g);
            case::<f64, 3, 2>(&mut g);
            case::<f64, 4, 2>(&mut g);
            case::<f64, 4, 3>(&mut g);
            case::<f32, 2, 2>(&mut g);
            case::<f32, 3, 2>(&mut g);
            case::<f32, 4, 2>(&mut g);
            case::<f32, 4, 4>(&mut g);
        }
    }

    #[test]
    fn refusals_and_other_sizes_fall_back() {
        let x = SVector::<f64, 2>::new(1.0, 2.0);
        let p = SMatrix::<f64, 2, 2>::identity();
        let c = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
        let r = SMatrix::<f64, 1, 1>::new(-1.0); // S = 0: refused
        let y = SVector::<f64, 1>::new(0.5);
        assert!(kalman_update(&x, &p, &c, &r, &y, CovarianceUpdate::Joseph).is_none());
        let y = SVector::<f64, 1>::new(f64::NAN);
        let r = SMatrix::<f64, 1, 1>::new(1.0);
        assert!(kalman_update(&x, &p, &c, &r, &y, CovarianceUpdate::Joseph).is_none());
        let p5 = SMatrix::<f64, 5, 5>::identity();
        let x5 = SVector::<f64, 5>::zeros();
        assert!(predict(&x5, &p5, &p5, &p5).is_none());
    }
}
