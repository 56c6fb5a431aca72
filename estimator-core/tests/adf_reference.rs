//! The ADF step (`filter::occlusion::adf`) against a literal copy of the step it replaced
//! (issue 23: the same mathematics, evaluated faster). [`reference`] below is that step as it
//! was, verbatim apart from the state being held in plain fields instead of an `Estimate` (and
//! an opt-in two-pass summation of its mixture, the accuracy reference): every interval of the
//! mixture evaluated in index order, each with its own `erfc`/`exp`/`ln` calls, and the
//! covariance formed as full matrices. Over random states that put the predicted `u` far
//! inside a region, far outside all of them, straddling an edge, with tiny and huge
//! covariances, general `E` and regions in any order, on dropouts and arrivals, the new step
//! must give the same label, region probabilities and errors (failing exactly where it failed,
//! state untouched), and x̂, P̂ within 1e-12 (f64, `rel_diff`) of the old step's — or, where it
//! is farther than that, closer than the old step to the two-pass sums: the old one-pass sum
//! loses digits when a negligible far interval comes before the dominant one (`compare`).

use estimator_core::filter::kalman::kalman_update;
use estimator_core::filter::time_update::predict;
use estimator_core::filter::AssumedDensityFilter;
use estimator_core::model::{LinearModel, LinearSystem};
use estimator_core::papers::Seed001Example;
use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use estimator_core::{CovarianceUpdate, Real};
use nalgebra::{matrix, vector, SMatrix, SVector};

/// The ADF step before issue 23, verbatim.
mod reference {
    use estimator_core::filter::kalman::kalman_update;
    use estimator_core::filter::time_update::predict;
    use estimator_core::gauss::{cdf, inv_mills, inv_mills_delta, ln_sf, pdf, sf};
    use estimator_core::linalg::{check_finite, symmetrize};
    use estimator_core::model::LinearSystem;
    use estimator_core::protocol::occlusion::Occlusion;
    use estimator_core::CovarianceUpdate;
    use estimator_core::{Error, Real, Result};
    use nalgebra::{SMatrix, SVector};

    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct AssumedDensityFilter<T: Real, const NX: usize, const S: usize> {
        pub x: SVector<T, NX>,
        pub p: SMatrix<T, NX, NX>,
        occ: Occlusion<T, NX, 1, S>,
        /// Regions as sorted intervals `(lower, upper, index)`.
        sorted: [(T, T, usize); S],
        pub label: usize,
        pub region_log_probs: [T; S],
        truncate_on_arrival: bool,
        form: CovarianceUpdate,
        /// Not in the old step: sum the mixture in two passes, every weight relative to the
        /// largest (an accuracy reference for both steps; see `compare`).
        two_pass: bool,
    }

    impl<T: Real, const NX: usize, const S: usize> AssumedDensityFilter<T, NX, S> {
        pub fn new(
            x0: SVector<T, NX>,
            p0: SMatrix<T, NX, NX>,
            occ: Occlusion<T, NX, 1, S>,
        ) -> Self {
            Self {
                x: x0,
                p: p0,
                sorted: occ.regions.sorted_intervals(),
                occ,
                label: 0,
                region_log_probs: [T::zero(); S],
                truncate_on_arrival: true,
                form: CovarianceUpdate::Joseph,
                two_pass: false,
            }
        }

        pub fn two_pass(mut self) -> Self {
            self.two_pass = true;
            self
        }

        pub fn with_arrival_truncation(mut self, on: bool) -> Self {
            self.truncate_on_arrival = on;
            self
        }

        pub fn step<const NY: usize, M: LinearSystem<T, NX, NY>>(
            &mut self,
            model: &M,
            k: usize,
            y: Option<&SVector<T, NY>>,
        ) -> Result<usize> {
            if let Some(y) = y {
                check_finite(y, "measurement")?;
            }
            let (xp, pp) = predict(model, k, &self.x, &self.p)?;
            let inf = T::one() / T::zero();
            match y {
                Some(y) => {
                    let (x1, p1, _) = kalman_update(
                        &xp,
                        &pp,
                        &model.c(k),
                        &model.measurement_cov(k),
                        y,
                        self.form,
                    )?;
                    let (x, p) = if self.truncate_on_arrival {
                        // The gaps between the sorted regions, half-lines included.
                        let gap = |j: usize| {
                            let lo = if j == 0 { -inf } else { self.sorted[j - 1].1 };
                            let hi = if j == S { inf } else { self.sorted[j].0 };
                            (lo, hi)
                        };
                        let (x, p, _) = self.truncate(&x1, &p1, S + 1, gap, |_, _| {})?;
                        (x, p)
                    } else {
                        (x1, p1)
                    };
                    (self.x, self.p) = (x, p);
                    self.label = 0;
                }
                None => {
                    let region = |i: usize| {
                        let c = self.occ.regions.centre(i)[0];
                        let r = self.occ.regions.radius(i);
                        (c - r, c + r)
                    };
                    let mut lp = [-inf; S];
                    let (x, p, best) = self.truncate(&xp, &pp, S, region, |i, l| lp[i] = l)?;
                    (self.x, self.p) = (x, p);
                    self.label = best + 1;
                    self.region_log_probs = lp;
                }
            }
            Ok(self.label)
        }

        fn truncate(
            &self,
            mx: &SVector<T, NX>,
            p: &SMatrix<T, NX, NX>,
            n: usize,
            interval: impl Fn(usize) -> (T, T),
            mut ln_z: impl FnMut(usize, T),
        ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, usize)> {
            let e = &self.occ.e;
            let pet = p * e.transpose();
            let s2 = (e * pet)[(0, 0)] + self.occ.psi[(0, 0)];
            if !s2.finite() || s2 <= T::zero() {
                return Err(Error::NotPositiveDefinite {
                    what: "E P Eᵀ + Ψ"
                });
            }
            let s = s2.sqrt();
            let m = (e * mx)[0];
            let mut mix = Mixture::new();
            let (mut best, mut best_lz) = (0usize, -T::one() / T::zero());
            for j in 0..n {
                let (lo, hi) = interval(j);
                let (l, mj, vj) = truncated_std_normal((lo - m) / s, (hi - m) / s);
                ln_z(j, l);
                mix.push(l, mj, vj);
                if l > best_lz {
                    (best, best_lz) = (j, l);
                }
            }
            if !mix.ln_total().finite() {
                return Err(Error::Numerical {
                    what: "occlusion event has zero probability under the prior",
                });
            }
            // In standard units u = m + s·z: E[z] = mbar, Var[z] = vbar.
            let (mbar, vbar) = if self.two_pass {
                two_pass_moments(n, |j| {
                    let (lo, hi) = interval(j);
                    truncated_std_normal((lo - m) / s, (hi - m) / s)
                })
            } else {
                (mix.mean, mix.variance())
            };
            let x = mx + pet * (mbar / s);
            let pe_ep = pet * pet.transpose() / s2;
            let p_new = symmetrize(&((p - pe_ep) + pe_ep * vbar));
            check_finite(&x, "updated state")?;
            check_finite(&p_new, "updated covariance")?;
            Ok((x, p_new, best))
        }
    }

    struct Mixture<T: Real> {
        top: T,
        w: T,
        mean: T,
        m2: T,
    }

    impl<T: Real> Mixture<T> {
        fn new() -> Self {
            Self {
                top: -T::one() / T::zero(),
                w: T::zero(),
                mean: T::zero(),
                m2: T::zero(),
            }
        }

        fn push(&mut self, l: T, mu: T, var: T) {
            if l == -T::one() / T::zero() {
                return;
            }
            if l > self.top {
                let r = (self.top - l).exp();
                self.w *= r;
                self.m2 *= r;
                self.top = l;
            }
            let wj = (l - self.top).exp();
            if wj == T::zero() {
                return;
            }
            let w_new = self.w + wj;
            let d = mu - self.mean;
            let mean_new = self.mean + d * (wj / w_new);
            self.m2 += wj * var + wj * d * (mu - mean_new);
            self.mean = mean_new;
            self.w = w_new;
        }

        fn ln_total(&self) -> T {
            self.top + self.w.ln()
        }

        fn variance(&self) -> T {
            (self.m2 / self.w).max(T::zero())
        }
    }

    /// Mean and variance of the mixture of `component(0..n)` = (ln Z, mean, variance), the
    /// weights taken relative to the largest, means and variances summed after the weights.
    fn two_pass_moments<T: Real>(n: usize, component: impl Fn(usize) -> (T, T, T)) -> (T, T) {
        let c: Vec<(T, T, T)> = (0..n).map(component).collect();
        let top = c
            .iter()
            .fold(-T::one() / T::zero(), |t, c| if c.0 > t { c.0 } else { t });
        let w: Vec<T> = c.iter().map(|c| (c.0 - top).exp()).collect();
        let wt = w.iter().fold(T::zero(), |a, &b| a + b);
        let mean = c.iter().zip(&w).fold(T::zero(), |a, (c, &w)| a + w * c.1) / wt;
        let var = c.iter().zip(&w).fold(T::zero(), |a, (c, &w)| {
            a + w * (c.2 + (c.1 - mean) * (c.1 - mean))
        }) / wt;
        (mean, var)
    }

    fn x_pdf<T: Real>(x: T) -> T {
        if x.finite() {
            x * pdf(x)
        } else {
            T::zero()
        }
    }

    pub fn truncated_std_normal<T: Real>(a: T, b: T) -> (T, T, T) {
        let neg_inf = -T::one() / T::zero();
        if a.partial_cmp(&b) != Some(core::cmp::Ordering::Less) {
            return (neg_inf, T::zero(), T::zero());
        }
        if a + b < T::zero() {
            let (l, m, v) = truncated_std_normal(-b, -a);
            return (l, -m, v);
        }
        if a <= T::zero() {
            let z = if a.finite() {
                cdf(b) - cdf(a)
            } else {
                T::one() - sf(b)
            };
            let (pa, pb) = (
                if a.finite() { pdf(a) } else { T::zero() },
                if b.finite() { pdf(b) } else { T::zero() },
            );
            let mean = (pa - pb) / z;
            let var = T::one() + (x_pdf(a) - x_pdf(b)) / z - mean * mean;
            return (z.ln(), mean, var.max(T::zero()));
        }
        let la = inv_mills(a);
        let ln_sa = ln_sf(a);
        if !b.finite() {
            return (ln_sa, la, (T::one() - inv_mills_delta(a)).max(T::zero()));
        }
        let q = (ln_sf(b) - ln_sa).exp();
        let one_q = T::one() - q;
        let lnz = ln_sa + (-q).ln_1p();
        let lb = inv_mills(b);
        let lam_a = la / one_q;
        let lam_b = lb * q / one_q;
        let mean = lam_a - lam_b;
        let var = if q * b * b * (a * a + T::one()) < T::EPS {
            T::one() - inv_mills_delta(a)
        } else {
            T::one() + a * lam_a - b * lam_b - mean * mean
        };
        (lnz, mean, var.max(T::zero()))
    }
}

/// A deterministic pseudo-random stream.
struct Lcg(u64);

impl Lcg {
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.unit().max(1e-300), self.unit());
        (-2.0 * u.ln()).sqrt() * (2.0 * core::f64::consts::PI * v).cos()
    }
    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[(self.unit() * xs.len() as f64) as usize % xs.len()]
    }
}

/// The worst disagreement seen, and where.
#[derive(Default)]
struct Worst {
    x: f64,
    p: f64,
    lp: f64,
    /// Largest difference of the new and of the old step from the two-pass reference.
    exact_new: f64,
    exact_old: f64,
    /// Cases where the new step is more than the tolerance from the old one (and closer to
    /// the two-pass sums).
    old_off: usize,
    at: String,
}

fn report(w: &Worst) {
    println!(
        "new vs old: worst relative difference x {:e}, P {:e}, ln P(R_i) {:e} ({}); \
         vs two-pass sums: new {:e}, old {:e}; {} cases beyond the tolerance from the old \
         step, all closer to the two-pass sums",
        w.x, w.p, w.lp, w.at, w.exact_new, w.exact_old, w.old_off
    );
}

/// Relative difference of the new step's (x̂, P̂) from the reference's: entrywise against the
/// entry's own magnitude, with a floor for entries that are 0 up to rounding — the entry's
/// posterior standard deviation (x̂), `√(P̂_ii P̂_jj)` (P̂) — and for both the rounding of the
/// Gaussian `N(m, P)` the truncation starts from, `EPS |m_i|` and `EPS √(P_ii P_jj)` scaled to
/// the tolerance (`/1e-12`): where the truncation pins `u` far from `m`, `x̂ = m + K s μ̄` and
/// `P̂ = (P − PEᵀEP/s²) + v̄ PEᵀEP/s²` are formed by cancellation (`|x̂| ≪ |m|`, `P̂ ≪ P`), and
/// neither step has more than `EPS·|m|`, `EPS·P` of absolute accuracy there.
fn rel_diff<const NX: usize>(
    x: &SVector<f64, NX>,
    p: &SMatrix<f64, NX, NX>,
    xr: &SVector<f64, NX>,
    pr: &SMatrix<f64, NX, NX>,
    (m_start, p_start): &(SVector<f64, NX>, SMatrix<f64, NX, NX>),
) -> (f64, f64) {
    let (mut dx, mut dp) = (0.0f64, 0.0f64);
    for i in 0..NX {
        let scale = xr[i]
            .abs()
            .max(pr[(i, i)].sqrt())
            .max(f64::EPSILON / 1e-12 * m_start[i].abs());
        dx = dx.max((x[i] - xr[i]).abs() / scale);
        for j in 0..NX {
            let scale = pr[(i, j)]
                .abs()
                .max((pr[(i, i)] * pr[(j, j)]).sqrt())
                .max(f64::EPSILON / 1e-12 * (p_start[(i, i)] * p_start[(j, j)]).sqrt());
            dp = dp.max((p[(i, j)] - pr[(i, j)]).abs() / scale);
        }
    }
    (dx, dp)
}

/// The Gaussian the truncation of a step from (x, P) starts from: the prediction, and on an
/// arrival the Kalman update of it (as both steps form them).
fn truncation_start<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>>(
    model: &M,
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    y: Option<&SVector<T, NY>>,
) -> (SVector<f64, NX>, SMatrix<f64, NX, NX>) {
    let Ok((xp, pp)) = predict(model, 1, x, p) else {
        return (SVector::zeros(), SMatrix::zeros());
    };
    let (x1, p1) = match y {
        Some(y) => kalman_update(
            &xp,
            &pp,
            &model.c(1),
            &model.measurement_cov(1),
            y,
            CovarianceUpdate::Joseph,
        )
        .map_or((xp, pp), |(x1, p1, _)| (x1, p1)),
        None => (xp, pp),
    };
    (x1.map(T::to_f64), p1.map(T::to_f64))
}

fn spd<const NX: usize>(g: &mut Lcg, scale: f64, cond: f64) -> SMatrix<f64, NX, NX> {
    // L D Lᵀ: L unit lower triangular with random entries, D spread over `cond` decades.
    let mut l = SMatrix::<f64, NX, NX>::identity();
    for i in 0..NX {
        for j in 0..i {
            l[(i, j)] = g.normal();
        }
    }
    let d = SMatrix::<f64, NX, NX>::from_diagonal(&SVector::from_fn(|_, _| {
        scale * 10f64.powf(-cond * g.unit())
    }));
    let p = l * d * l.transpose();
    (p + p.transpose()) * 0.5
}

/// One step of both filters from the same (x, P); compares results, labels, region
/// probabilities and errors. `tol`: the largest relative difference allowed from the old step
/// (`rel_diff`); the differences from the two-pass reference are recorded in `worst`.
#[allow(clippy::too_many_arguments)]
fn compare<T: Real, const NX: usize, const NY: usize, const S: usize, M>(
    model: &M,
    occ: Occlusion<T, NX, 1, S>,
    x: SVector<T, NX>,
    p: SMatrix<T, NX, NX>,
    y: Option<SVector<T, NY>>,
    truncate: bool,
    tol: f64,
    worst: &mut Worst,
    tag: &str,
) -> bool
where
    M: LinearSystem<T, NX, NY>,
{
    let Ok(new) = AssumedDensityFilter::new(x, p, occ) else {
        return false; // P not SPD enough for the constructor: no case
    };
    let mut new = new.with_arrival_truncation(truncate);
    let mut old = reference::AssumedDensityFilter::new(x, p, occ).with_arrival_truncation(truncate);
    let mut exact = old.two_pass();
    let before = new;
    let got = new.step(model, 1, y.as_ref());
    let want = old.step(model, 1, y.as_ref());
    let exact_ok = exact.step(model, 1, y.as_ref()).is_ok();
    match (got, want) {
        (Ok(a), Ok(b)) => assert_eq!(a, b, "label, {tag}"),
        (Err(a), Err(b)) => {
            assert_eq!(a, b, "error, {tag}");
            // (Debug, not ==: the state may hold a NaN E.)
            assert_eq!(
                format!("{new:?}"),
                format!("{before:?}"),
                "state changed on error, {tag}"
            );
            return true;
        }
        (a, b) => panic!("{tag}: new {a:?}, reference {b:?}"),
    }
    let wide = |x: &SVector<T, NX>, p: &SMatrix<T, NX, NX>| (x.map(T::to_f64), p.map(T::to_f64));
    let (xn, pn) = wide(new.estimate().state(), new.estimate().covariance());
    let (xo, po) = wide(&old.x, &old.p);
    let p_start = truncation_start(model, &x, &p, y.as_ref());
    let (dx, dp) = rel_diff(&xn, &pn, &xo, &po, &p_start);
    assert_eq!(pn, pn.transpose(), "P̂ symmetric, {tag}");
    // Both against the two-pass sums (the old one-pass sum loses digits when a negligible
    // far interval precedes the dominant one: the mean is then formed as μ_far + (μ − μ_far);
    // the new step sums the nearest interval first and skips the negligible ones).
    let (ex, ep, ox, op) = if exact_ok {
        let (xe, pe) = wide(&exact.x, &exact.p);
        let (ex, ep) = rel_diff(&xn, &pn, &xe, &pe, &p_start);
        let (ox, op) = rel_diff(&xo, &po, &xe, &pe, &p_start);
        worst.exact_new = worst.exact_new.max(ex.max(ep));
        worst.exact_old = worst.exact_old.max(ox.max(op));
        (ex, ep, ox, op)
    } else {
        (f64::NAN, f64::NAN, f64::NAN, f64::NAN)
    };
    // Within `tol` of the old step; where not, because the old step is that far from the
    // two-pass sums and the new one is closer to them (and within `tol` of them).
    let close = dx <= tol && dp <= tol;
    assert!(
        close || (ex.max(ep) <= tol && ex.max(ep) <= ox.max(op)),
        "{tag}: x {dx:e}, P {dp:e} from the old step; from the two-pass sums new {ex:e} {ep:e}, \
         old {ox:e} {op:e}\nnew {:?}\nold {:?} {:?}",
        new.estimate(),
        old.x,
        old.p
    );
    if !close {
        worst.old_off += 1;
    }
    if y.is_none() {
        let lp = new.region_log_probs();
        for i in 0..S {
            let (a, b) = (lp[i].to_f64(), old.region_log_probs[i].to_f64());
            if a != b {
                let d = (a - b).abs() / b.abs().max(1.0);
                assert!(d <= tol, "{tag}: ln P(R_{i}) {a} vs {b}");
                worst.lp = worst.lp.max(d);
            }
        }
    }
    if dx.max(dp) > worst.x.max(worst.p) {
        worst.at = tag.to_string();
    }
    worst.x = worst.x.max(dx);
    worst.p = worst.p.max(dp);
    true
}

/// Where the predicted `u` is put relative to the regions (`ζ_i ± r_i`, sorted `bounds`).
fn u_position(g: &mut Lcg, bounds: &[(f64, f64)]) -> f64 {
    let (lo, hi) = (bounds[0].0, bounds[bounds.len() - 1].1);
    let (a, b) = g.pick(bounds);
    let w = b - a;
    match (g.unit() * 9.0) as usize {
        0 => g.range(lo - 20.0, hi + 20.0),      // anywhere near
        1 => 0.5 * (a + b) + g.range(-0.1, 0.1), // deep inside a region
        2 => a + g.range(-1e-3, 1e-3) * w,       // straddling an edge
        3 => b + g.range(-0.3, 0.3),             // near an edge
        4 => hi + 10f64.powf(g.range(0.0, 6.0)), // far above every region
        5 => lo - 10f64.powf(g.range(0.0, 6.0)), // far below every region
        6 => b + g.range(0.0, 1.0) * 0.5 * w,    // in a gap
        7 => 0.5 * (lo + hi) + g.normal() * 1e3, // wide
        _ => g.pick(&[a, b]),                    // exactly on an edge
    }
}

/// A random case around the seed-001 model: x̂ with the predicted `u` at `u`, P of a random
/// scale, a dropout or an arrival with a measurement near or far from C x̂⁻.
fn paper_cases(seed: u64, n: usize, truncate: bool) -> Worst {
    let m = Seed001Example::model::<f64>().unwrap();
    let occ = Seed001Example::occlusion::<f64>().unwrap();
    let bounds = [(15.0, 25.0), (35.0, 45.0), (55.0, 65.0), (75.0, 85.0)];
    let mut g = Lcg(seed);
    let mut worst = Worst::default();
    let mut done = 0;
    while done < n {
        let u = u_position(&mut g, &bounds);
        let scale = 10f64.powf(g.range(-8.0, 8.0));
        let cond = g.range(0.0, 6.0);
        let p = spd::<3>(&mut g, scale, cond);
        // x̂ such that x̂⁻₁ = (A x̂)₁ ≈ u.
        let mut x = vector![u, g.normal() * 3.0, g.normal() * 3.0];
        x[0] = (u - 0.1 * x[1]) / 1.01;
        let y = if g.unit() < 0.5 {
            None
        } else {
            let xp = m.a(0) * x;
            let sd = (m.c(1) * p * m.c(1).transpose()).diagonal().map(f64::sqrt);
            let far = if g.unit() < 0.2 { 1e3 } else { 1.0 };
            Some(m.c(1) * xp + vector![g.normal() * sd[0] * far, g.normal() * sd[1] * far])
        };
        let tag = format!("seed {seed} case {done}: u {u}, scale {scale:e}, y {y:?}");
        if compare(&m, occ, x, p, y, truncate, 1e-12, &mut worst, &tag) {
            done += 1;
        }
    }
    worst
}

#[test]
fn paper_model_dropouts_and_arrivals_agree_with_the_reference() {
    let mut worst = Worst::default();
    for (seed, truncate) in [(1u64, true), (2, true), (3, true), (4, false)] {
        let w = paper_cases(seed, 5000, truncate);
        if w.x.max(w.p) > worst.x.max(worst.p) {
            worst.at = w.at;
        }
        worst.x = worst.x.max(w.x);
        worst.p = worst.p.max(w.p);
        worst.lp = worst.lp.max(w.lp);
        worst.exact_new = worst.exact_new.max(w.exact_new);
        worst.exact_old = worst.exact_old.max(w.exact_old);
        worst.old_off += w.old_off;
    }
    report(&worst);
}

#[test]
fn general_e_unsorted_and_touching_regions_agree_with_the_reference() {
    // E mixes the states, the regions are given out of order, two of them touch, one is
    // narrow; NX = 2, NY = 1.
    let m = LinearModel::<f64, 2, 2, 1, 1>::new(
        matrix![0.98, 0.2; -0.1, 0.95],
        SMatrix::identity(),
        matrix![0.4, 1.0],
        matrix![1.0],
        matrix![0.3, 0.05; 0.05, 0.2],
        matrix![0.5],
    )
    .unwrap();
    let regions = OcclusionRegions::new(
        [
            vector![3.0],
            vector![-10.0],
            vector![5.0],
            vector![30.0],
            vector![-4.0],
        ],
        [1.0, 2.0, 1.0, 0.01, 3.0],
    )
    .unwrap();
    let occ = Occlusion::new(matrix![0.7, -0.3], matrix![0.05], regions).unwrap();
    let mut bounds = [
        (2.0, 4.0),
        (-12.0, -8.0),
        (4.0, 6.0),
        (29.99, 30.01),
        (-7.0, -1.0),
    ];
    bounds.sort_by(|a: &(f64, f64), b| a.0.total_cmp(&b.0));
    let mut g = Lcg(99);
    let mut worst = Worst::default();
    let mut done = 0;
    while done < 20_000 {
        let u = u_position(&mut g, &bounds);
        let (scale, cond) = (10f64.powf(g.range(-8.0, 8.0)), g.range(0.0, 5.0));
        let p = spd::<2>(&mut g, scale, cond);
        // Any x̂ whose prediction has E x̂⁻ = u: solve along E's direction.
        let x0 = vector![g.normal() * 5.0, g.normal() * 5.0];
        let ex = (occ.e * m.a(0) * x0)[0];
        let dir = (occ.e * m.a(0)).transpose();
        let x = x0 + m.a(0).try_inverse().unwrap() * dir * ((u - ex) / dir.norm_squared());
        let y = (g.unit() < 0.5).then(|| vector![g.normal() * 3.0 + (m.c(1) * m.a(0) * x)[0]]);
        let truncate = g.unit() < 0.9;
        let tag = format!("general case {done}: u {u}, y {y:?}");
        if compare(&m, occ, x, p, y, truncate, 1e-12, &mut worst, &tag) {
            done += 1;
        }
    }
    report(&worst);
}

#[test]
fn trajectories_agree_with_the_reference() {
    // 200 runs of 100 steps of the seed-001 system, dropouts by the occlusion rule: the two
    // filters run side by side from the paper's prior; differences must not grow.
    let m = Seed001Example::model::<f64>().unwrap();
    let occ = Seed001Example::occlusion::<f64>().unwrap();
    let mut g = Lcg(2024);
    let (mut wx, mut wp) = (0.0f64, 0.0f64);
    for run in 0..200 {
        let mut x = vector![
            g.normal() * 2.0 + 5.0,
            g.normal() * 2.0 + 5.0,
            g.normal() * 2.0 + 5.0
        ];
        let mut new =
            AssumedDensityFilter::new(Seed001Example::x0(), Seed001Example::p0(), occ).unwrap();
        let mut old =
            reference::AssumedDensityFilter::new(Seed001Example::x0(), Seed001Example::p0(), occ);
        for k in 1..=100 {
            let w = vector![g.normal(), g.normal(), g.normal()] * 0.3f64.sqrt();
            x = m.a(k - 1) * x + w;
            let u = x[0] + g.normal() * 0.1f64.sqrt();
            let y = (!occ.regions.drops(&vector![u]))
                .then(|| m.c(k) * x + vector![g.normal(), g.normal()] * 0.2f64.sqrt());
            let a = new.step(&m, k, y.as_ref());
            let b = old.step(&m, k, y.as_ref());
            assert_eq!(a, b, "run {run} k {k}");
            let (dx, dp) = rel_diff(
                new.estimate().state(),
                new.estimate().covariance(),
                &old.x,
                &old.p,
                &(SVector::zeros(), SMatrix::zeros()), // no floor: the plain relative difference
            );
            assert!(
                dx <= 1e-12 && dp <= 1e-12,
                "run {run} k {k}: x {dx:e} P {dp:e}"
            );
            wx = wx.max(dx);
            wp = wp.max(dp);
        }
    }
    println!("trajectories: worst relative difference x {wx:e}, P {wp:e}");
}

#[test]
fn errors_agree_with_the_reference() {
    let m = Seed001Example::model::<f64>().unwrap();
    let occ = Seed001Example::occlusion::<f64>().unwrap();
    let p = SMatrix::<f64, 3, 3>::identity();
    let mut w = Worst::default();
    // NaN / ∞ measurements, a prediction that overflows, priors so far away (and so certain)
    // that every region has probability 0 in f64, a huge P.
    for y in [
        Some(vector![f64::NAN, 0.0]),
        Some(vector![f64::INFINITY, 1.0]),
        Some(vector![1e308, -1e308]),
        Some(vector![70.0, 30.0]),
        None,
    ] {
        for (x, p) in [
            (vector![30.0, 0.0, 0.0], p),
            (vector![1e308, 1e308, 0.0], p),
            (vector![1e6, 0.0, 0.0], p * 1e-12),
            (vector![-1e300, 0.0, 0.0], p * 1e-200),
            (vector![35.0, 0.0, 0.0], p * 1e300),
            (vector![35.0, 0.0, 0.0], p * 1e150),
        ] {
            let tag = format!("x {x:?} P {:e} y {y:?}", p[(0, 0)]);
            assert!(compare(&m, occ, x, p, y, true, 1e-12, &mut w, &tag));
        }
    }
    // A NaN E, a zero-variance marginal (Ψ = 0 is refused by Occlusion::new: E = 0 instead).
    for e in [matrix![f64::NAN, 0.0, 0.0], matrix![0.0, 0.0, 0.0]] {
        let mut bad = occ;
        bad.e = e;
        for y in [None, Some(vector![1.0, 2.0])] {
            let tag = format!("E {e:?} y {y:?}");
            assert!(compare(
                &m,
                bad,
                vector![30.0, 0.0, 0.0],
                p,
                y,
                true,
                1e-12,
                &mut w,
                &tag
            ));
        }
    }
    report(&w);
}

#[test]
fn f32_agrees_with_the_reference() {
    // No bit-identity in f32 either (a region below EPS/2 of the rest is no longer summed);
    // the old one-pass sum's rounding is larger in f32, so the bound is in f32 ulps.
    let m = Seed001Example::model::<f32>().unwrap();
    let occ = Seed001Example::occlusion::<f32>().unwrap();
    let bounds = [(15.0, 25.0), (35.0, 45.0), (55.0, 65.0), (75.0, 85.0)];
    let mut g = Lcg(5);
    let mut worst = Worst::default();
    let mut done = 0;
    while done < 20_000 {
        let u = u_position(&mut g, &bounds);
        if u.abs() > 1e4 {
            continue; // f32 has no digits left for x̂ there
        }
        let scale = 10f64.powf(g.range(-3.0, 3.0));
        let p = spd::<3>(&mut g, scale, 2.0).map(|v| v as f32);
        let x = vector![u / 1.01, 0.0, 0.0].map(|v| v as f32);
        let y = (done % 2 == 0).then(|| m.c(1) * m.a(0) * x);
        let tag = format!("f32 case {done}: u {u}, scale {scale:e}, y {y:?}");
        if compare(&m, occ, x, p, y, true, 1e-3, &mut worst, &tag) {
            done += 1;
        }
    }
    report(&worst);
}
