//! Seed 004 audited (issue 22): every step of Algorithm 1 against a literal, term-by-term
//! transcription of the printed equation, and a full run of Algorithm 1 against an
//! independent end-to-end transcription.
//!
//! The transcriptions (`lit_*`) are plain `f64` on 2×2 arrays, the sums and products written
//! out as the paper prints them. They call nothing of estimator-core: Φ is `libm::erfc`, every
//! matrix product, inverse and Hadamard product is spelled out below. Where the paper is
//! ambiguous they take the product's documented reading (docs/design.md "Seed 004",
//! docs/tobit-fusion.md), named where it enters:
//!
//! * (R1) `λ_{m,t}√𝓡_{m,t}` is the componentwise product λ∘√R (λ of a vector is componentwise);
//! * (R2) the `K_{m,t+1}` of the κ₇ term is `K_{m,t}`;
//! * (R3) Ω₁'s `P_{t|t−1}` is the node's bound `P̄_{m,t|t−1}`;
//! * (R4) `Ξ(Ḡ)` enters as `Ξ(Ḡ) I` (a scalar bound on `E{εεᵀ}`), and the first processed
//!   instant uses `Ξ(Ḡ₀)`, `Ḡ₀ = η₀²`;
//! * (R5) `C(Υ∘Ω₁)Cᵀ` as written;
//! * (R6) Q in (29) is the node's `Q_m = α_m⁻¹Q` of (51), and `P̄_{m,0|0} = α_m⁻¹P₀`;
//! * (R7) when θ = 1 the filter runs (22) and (30) with the held `ȳ_{m,t} = ȳ_{m,t−1}` of (19)
//!   (Algorithm 1's line 12 prints `y_{m,t−1}`, which the filter never received);
//! * (R8) the reset (51) overwrites both `x̂_m` and `P̄_m`;
//! * (R9) protocol: β from the previous instant's allocation, bucket updated after all nodes,
//!   the trigger's reference changes only on a transmission, (13) uses ε after the decision.
//!
//! `alternative_readings_of_the_example` (ignored; run it with `--ignored --nocapture`) runs
//! the transcription under the plausible *other* readings and prints how far each moves the
//! example's MSE (docs/tobit-fusion.md, "Audit against the equations").

#![allow(clippy::needless_range_loop)] // (i, j) indices as the paper writes them

use estimator_core::filter::tobit::{
    federated_fuse, BoundScalars, Silence, TobitFilter, TobitFilterConfig, TobitFusion,
};
use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
use estimator_core::protocol::shared_token_bucket::{SharedTokenBucket, TriggeredBucketScheduler};
use estimator_core::protocol::tobit::{
    censor, censored_mean, paper_variance, prob_uncensored, TobitStats,
};
use nalgebra::{SMatrix, SVector};

// ---------------------------------------------------------------------------------------------
// Plain 2×2 arithmetic, written out.

type V = [f64; 2];
type M = [[f64; 2]; 2];

fn mm(a: &M, b: &M) -> M {
    let mut c = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            for k in 0..2 {
                c[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    c
}
fn mm3(a: &M, b: &M, c: &M) -> M {
    mm(&mm(a, b), c)
}
fn mv(a: &M, v: &V) -> V {
    let mut w = [0.0; 2];
    for i in 0..2 {
        for k in 0..2 {
            w[i] += a[i][k] * v[k];
        }
    }
    w
}
fn t(a: &M) -> M {
    [[a[0][0], a[1][0]], [a[0][1], a[1][1]]]
}
fn add(a: &M, b: &M) -> M {
    [
        [a[0][0] + b[0][0], a[0][1] + b[0][1]],
        [a[1][0] + b[1][0], a[1][1] + b[1][1]],
    ]
}
fn sub(a: &M, b: &M) -> M {
    add(a, &sc(-1.0, b))
}
fn sc(s: f64, a: &M) -> M {
    [[s * a[0][0], s * a[0][1]], [s * a[1][0], s * a[1][1]]]
}
fn vadd(a: &V, b: &V) -> V {
    [a[0] + b[0], a[1] + b[1]]
}
fn vsub(a: &V, b: &V) -> V {
    [a[0] - b[0], a[1] - b[1]]
}
fn outer(u: &V, v: &V) -> M {
    [[u[0] * v[0], u[0] * v[1]], [u[1] * v[0], u[1] * v[1]]]
}
fn diag(v: &V) -> M {
    [[v[0], 0.0], [0.0, v[1]]]
}
fn eye() -> M {
    diag(&[1.0, 1.0])
}
fn zero() -> M {
    [[0.0; 2]; 2]
}
/// `[A ∘ B]_ij = A_ij B_ij`.
fn hadamard(a: &M, b: &M) -> M {
    [
        [a[0][0] * b[0][0], a[0][1] * b[0][1]],
        [a[1][0] * b[1][0], a[1][1] * b[1][1]],
    ]
}
/// `A⁻¹ = adj(A)/det A`.
fn inv(a: &M) -> M {
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    [
        [a[1][1] / det, -a[0][1] / det],
        [-a[1][0] / det, a[0][0] / det],
    ]
}
fn amax(a: &M) -> f64 {
    a.iter().flatten().fold(0.0, |m, v| m.max(v.abs()))
}
fn vamax(a: &V) -> f64 {
    a[0].abs().max(a[1].abs())
}
fn trace(a: &M) -> f64 {
    a[0][0] + a[1][1]
}
/// 2-norm condition number of a symmetric positive-definite 2×2 matrix.
fn cond_spd(a: &M) -> f64 {
    let (tr, det) = (trace(a), a[0][0] * a[1][1] - a[0][1] * a[1][0]);
    let disc = ((tr * tr / 4.0) - det).max(0.0).sqrt();
    (tr / 2.0 + disc) / (tr / 2.0 - disc)
}

fn na_m(a: &M) -> SMatrix<f64, 2, 2> {
    SMatrix::from_fn(|i, j| a[i][j])
}
fn na_v(v: &V) -> SVector<f64, 2> {
    SVector::from_column_slice(v)
}
fn m_na(a: &SMatrix<f64, 2, 2>) -> M {
    [[a[(0, 0)], a[(0, 1)]], [a[(1, 0)], a[(1, 1)]]]
}
fn s1(x: f64) -> SVector<f64, 1> {
    SVector::from_column_slice(&[x])
}
fn v_na(v: &SVector<f64, 2>) -> V {
    [v[0], v[1]]
}

// ---------------------------------------------------------------------------------------------
// The standard normal, from libm's erfc only.

/// φ(x), the standard normal density.
fn pdf(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt()
}
/// Φ(x) = erfc(−x/√2)/2.
fn cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}
/// `1 − Φ(ζ)` as printed in λ, evaluated as Φ(−ζ) (the same number) because the subtraction
/// keeps no digits for ζ ≳ 8, where the example's predictions go
/// (`one_minus_cdf_is_the_printed_subtraction` checks it where the subtraction has digits).
fn one_minus_cdf(z: f64) -> f64 {
    cdf(-z)
}
/// λ(ζ) ≜ φ(ζ)/(1 − Φ(ζ)).
fn lam(z: f64) -> f64 {
    pdf(z) / one_minus_cdf(z)
}
/// φ(ζ) ≜ λ(ζ)(λ(ζ) − ζ) (the paper's second φ, of eq. 7).
fn varphi(z: f64) -> f64 {
    lam(z) * (lam(z) - z)
}

// ---------------------------------------------------------------------------------------------
// The literal equations.

/// (5): `ϱ̄^(j) = Φ(((C x̂)^(j) − τ^(j)) / √R^(j))`.
fn lit_rho(cx: f64, tau: f64, r: f64) -> f64 {
    cdf((cx - tau) / r.sqrt())
}
/// (6): `E{y^(j) | x} = Φ((Cx − τ)/√R) [Cx + √R λ((τ − Cx)/√R)] + Φ((τ − Cx)/√R) τ`.
fn lit_mean(cx: f64, tau: f64, r: f64) -> f64 {
    cdf((cx - tau) / r.sqrt()) * (cx + r.sqrt() * lam((tau - cx) / r.sqrt()))
        + cdf((tau - cx) / r.sqrt()) * tau
}
/// (7): `D{y^(j) | x} = R [1 − φ((τ − Cx)/√R)]`.
fn lit_var(cx: f64, tau: f64, r: f64) -> f64 {
    r * (1.0 - varphi((tau - cx) / r.sqrt()))
}

/// κ₁ … κ₈ of Theorem 1 from ε₁ … ε₁₄ (`e[j]` is ε_j; `e[0]` unused).
fn lit_kappa(eps: &[f64; 14]) -> [f64; 9] {
    let e = |j: usize| eps[j - 1];
    let i = |j: usize| 1.0 / eps[j - 1];
    [
        f64::NAN,
        1.0 + e(1) + e(2) + e(3) + e(4) + e(5),
        1.0 + i(1) + i(7) + i(10) + i(12) + i(13),
        1.0 + e(6),
        1.0 + e(7) + e(8) + e(9) + i(2),
        1.0 + i(3) + i(8) + e(10) + e(11),
        1.0 + i(4) + e(12),
        1.0 + i(5) + i(9) + i(11) + e(13),
        1.0 + i(6),
    ]
}

/// One node's trigger and the scalars d, e of Ξ.
#[derive(Clone, Copy, Debug)]
struct NodeParams {
    sigma: f64,
    lambda: f64,
    chi: f64,
    eta0: f64,
    d: f64,
    e: f64,
}

/// `Ξ(Ḡ) = ((1+d)(1+e)λ² + (1+χ)(1+d⁻¹)/χ²) Ḡ + ((1+d)(1+e⁻¹) + (1+d⁻¹)(1+χ⁻¹)) σ²`.
fn lit_xi(n: &NodeParams, g: f64) -> f64 {
    let (d, e, lm, chi, s) = (n.d, n.e, n.lambda, n.chi, n.sigma);
    ((1.0 + d) * (1.0 + e) * lm * lm + (1.0 + chi) * (1.0 + 1.0 / d) / (chi * chi)) * g
        + ((1.0 + d) * (1.0 + 1.0 / e) + (1.0 + 1.0 / d) * (1.0 + 1.0 / chi)) * s * s
}

/// Which reading of an ambiguous place the transcription takes. `Reading::default()` is the
/// design's (R1)-(R9); every other value is an alternative a careful independent
/// implementation could plausibly have taken.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Reading {
    /// (29) with the plant's Q instead of `Q_m = α_m⁻¹Q` (the printed (29) shows `Q_{t−1}`).
    q_unscaled: bool,
    /// `P̄_{m,0|0} = P₀` instead of `α_m⁻¹P₀` (Theorem 1: "P_{0|0} = P̄_{0|0}").
    p0_unscaled: bool,
    /// Ω₁ with `α_m P̄_{m,t|t−1} = A P^g Aᵀ + B Q Bᵀ`, the fused prediction (the printed
    /// `P_{t|t−1}` has no node index).
    omega1_fused_prior: bool,
    /// Ω₁ with (26) evaluated on the bound: `A P̄_{m,t−1|t−1} Aᵀ + B Q Bᵀ` (the true error
    /// sees the plant's Q, not α⁻¹Q).
    omega1_eq26: bool,
    /// What happens when θ = 1.
    hold: Hold,
    /// What the reset (51) overwrites.
    reset: Reset,
    /// Ξ one step ahead: the first processed instant uses `Ξ(Ξ(Ḡ₀))` (time origin at t = 0).
    xi_lead: bool,
    /// The κ₂ term as its diagonal only.
    kappa2_diagonal: bool,
    /// ϱ̄ read as the probability of being censored, `1 − Φ(…)`.
    rho_complement: bool,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum Hold {
    /// (19): `ȳ_{m,t} = ȳ_{m,t−1}`, the last received measurement, and (22), (30) run.
    #[default]
    Received,
    /// Algorithm 1 line 12 read literally: `ȳ_{m,t} = y_{m,t−1}`, the node's previous censored
    /// measurement, transmitted or not (not available to a real filter).
    PreviousMeasurement,
    /// No update at all: `x̂_{t|t} = x̂_{t|t−1}`, `P̄_{t|t} = P̄_{t|t−1}`.
    PredictOnly,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum Reset {
    /// (51): `x̂_m ← x̂^g`, `P̄_m ← α_m⁻¹ P^g`.
    #[default]
    Both,
    /// Only `x̂_m ← x̂^g`; `P̄_m` keeps its local value.
    StateOnly,
    /// Only `P̄_m ← α_m⁻¹ P^g`; `x̂_m` keeps its local value.
    BoundOnly,
    /// `P̄_m ← P^g` (the α_m⁻¹ dropped).
    BoundUnscaled,
}

/// The inputs of one local step (one node, one instant).
#[derive(Clone, Copy, Debug)]
struct LocalIn {
    a: M,
    /// B (n_w = 1) and the plant's scalar Q; the step uses `Q_m = Q/α` (R6).
    b: V,
    q: f64,
    alpha: f64,
    c: M,
    r: V,
    tau: V,
    eps: [f64; 14],
    node: NodeParams,
    /// x̂_{m,t−1|t−1}, P̄_{m,t−1|t−1}.
    x: V,
    p: M,
    /// ȳ_{m,t−1}.
    y_bar_prev: V,
    /// Ḡ_{m,t}.
    g: f64,
    /// `Some(y)` iff α_{m,t} β_{m,t} = 1.
    received: Option<V>,
}

/// Everything one literal local step computes, term by term.
#[derive(Clone, Copy, Debug)]
struct LocalTerms {
    theta: f64,
    y_bar: V,
    x_prior: V,
    p_prior: M,
    rho: V,
    lam: V,
    upsilon: M,
    omega1: M,
    omega2: M,
    omega3: M,
    xi: f64,
    kappa: [f64; 9],
    y_hat: V,
    /// The Φ terms of (37) without their κ, with their θ factor: `terms[i]` goes with κ_i
    /// (index 1 is the κ₁ term `Q̄CP̄⁻CᵀQ̄ᵀ`), and `omega3_r` is `(1−θ)² Ω₃∘R`.
    terms: [M; 9],
    omega3_r: M,
    psi: [[f64; 2]; 2],
    phi: M,
    k: M,
    x_post: V,
    p_post: M,
}

/// (30) as printed, term by term, for the gain `k` (the κ₇ term's `K_{t+1}` is `k`, R2).
fn lit_bound(lt: &LocalTerms, inp: &LocalIn, k: &M) -> M {
    let th = lt.theta;
    let kap = &lt.kappa;
    let q_bar = diag(&lt.rho);
    let c = &inp.c;
    let i_kqc = sub(&eye(), &mm3(k, &q_bar, c));
    let r_mat = diag(&inp.r);
    let lsr = [lt.lam[0] * inp.r[0].sqrt(), lt.lam[1] * inp.r[1].sqrt()];
    let tt = outer(&inp.tau, &inp.tau);
    let i_q = sub(&eye(), &q_bar);
    let kt = t(k);
    let mut p = sc(kap[1], &mm3(&i_kqc, &lt.p_prior, &t(&i_kqc)));
    p = add(
        &p,
        &sc(
            (1.0 - th).powi(2),
            &mm3(k, &hadamard(&lt.omega3, &r_mat), &kt),
        ),
    );
    p = add(
        &p,
        &sc(
            kap[2],
            &mm3(k, &mm3(&q_bar, &outer(&lsr, &lsr), &t(&q_bar)), &kt),
        ),
    );
    p = add(
        &p,
        &sc(
            (1.0 - th).powi(2) * kap[3],
            &mm3(k, &mm3(c, &hadamard(&lt.upsilon, &lt.omega1), &t(c)), &kt),
        ),
    );
    p = add(
        &p,
        &sc(
            th * th * kap[4],
            &mm3(k, &mm3(&mm(&q_bar, c), &lt.omega1, &t(&mm(&q_bar, c))), &kt),
        ),
    );
    p = add(&p, &sc(th * th * kap[5], &mm3(k, &lt.omega2, &kt)));
    p = add(&p, &sc((1.0 - th).powi(2) * kap[6] * lt.xi, &mm(k, &kt)));
    p = add(
        &p,
        &sc(th * th * kap[7], &mm3(k, &mm3(&i_q, &tt, &t(&i_q)), &kt)),
    );
    p = add(
        &p,
        &sc(
            (1.0 - th).powi(2) * kap[8],
            &mm3(k, &hadamard(&lt.upsilon, &tt), &kt),
        ),
    );
    p
}

/// One local step: (19)-(20), (21), (23), (29), (5), Ω₁-Ω₃, Υ, Ξ, (37), (22), (30).
fn lit_local(inp: &LocalIn, rd: &Reading) -> LocalTerms {
    // θ ≜ 1 − αβ; (20): ȳ_t = αβ y + (1 − αβ) ȳ_{t−1}.
    let (ab, y_new) = match inp.received {
        Some(y) => (1.0, y),
        None => (0.0, [0.0; 2]),
    };
    let theta = 1.0 - ab;
    let y_bar = [
        ab * y_new[0] + (1.0 - ab) * inp.y_bar_prev[0],
        ab * y_new[1] + (1.0 - ab) * inp.y_bar_prev[1],
    ];
    // (21), (29) with Q_m = α⁻¹Q (R6).
    let x_prior = mv(&inp.a, &inp.x);
    let q_m = if rd.q_unscaled {
        inp.q
    } else {
        inp.q / inp.alpha
    };
    let p_prior = add(
        &mm3(&inp.a, &inp.p, &t(&inp.a)),
        &sc(q_m, &outer(&inp.b, &inp.b)),
    );
    // (5) at C x̂_{t|t−1}; λ_{m,t} = λ((τ − C x̂)/√R) componentwise.
    let cx = mv(&inp.c, &x_prior);
    let mut rho = [0.0; 2];
    let mut lm = [0.0; 2];
    for j in 0..2 {
        rho[j] = lit_rho(cx[j], inp.tau[j], inp.r[j]);
        if rd.rho_complement {
            rho[j] = 1.0 - rho[j];
        }
        lm[j] = lam((inp.tau[j] - cx[j]) / inp.r[j].sqrt());
    }
    let q_bar = diag(&rho);
    // (23): ŷ = Q̄ (C x̂ + λ√R) + (I − Q̄) τ, with λ√R = λ∘√R (R1).
    let lsr = [lm[0] * inp.r[0].sqrt(), lm[1] * inp.r[1].sqrt()];
    let y_hat = vadd(
        &mv(&q_bar, &vadd(&cx, &lsr)),
        &mv(&sub(&eye(), &q_bar), &inp.tau),
    );
    // Υ, Ω₁ (R3), Ω₂ = ȳ_{t−1}ȳᵀ_{t−1}, Ω₃ = Υ + Q̄Q̄ᵀ.
    let upsilon = diag(&[rho[0] * (1.0 - rho[0]), rho[1] * (1.0 - rho[1])]);
    let e14 = inp.eps[13];
    let p_in_omega1 = if rd.omega1_fused_prior {
        sc(inp.alpha, &p_prior)
    } else if rd.omega1_eq26 {
        add(
            &mm3(&inp.a, &inp.p, &t(&inp.a)),
            &sc(inp.q, &outer(&inp.b, &inp.b)),
        )
    } else {
        p_prior
    };
    let omega1 = add(
        &sc(1.0 + e14, &p_in_omega1),
        &sc(1.0 + 1.0 / e14, &outer(&x_prior, &x_prior)),
    );
    let omega2 = outer(&inp.y_bar_prev, &inp.y_bar_prev);
    let omega3 = add(&upsilon, &mm(&q_bar, &t(&q_bar)));
    // Ξ(Ḡ_t) (R4).
    let xi = if rd.xi_lead {
        lit_xi(&inp.node, lit_xi(&inp.node, inp.g))
    } else {
        lit_xi(&inp.node, inp.g)
    };
    let kappa = lit_kappa(&inp.eps);
    // The terms of Φ (37), without κ, with θ.
    let (s, u) = ((1.0 - theta).powi(2), theta * theta);
    let c = &inp.c;
    let qc = mm(&q_bar, c);
    let r_mat = diag(&inp.r);
    let tt = outer(&inp.tau, &inp.tau);
    let i_q = sub(&eye(), &q_bar);
    let mut t2 = mm3(&q_bar, &outer(&lsr, &lsr), &t(&q_bar));
    if rd.kappa2_diagonal {
        t2 = diag(&[t2[0][0], t2[1][1]]);
    }
    let terms = [
        zero(),
        mm3(&qc, &p_prior, &t(&qc)),
        t2,
        sc(s, &mm3(c, &hadamard(&upsilon, &omega1), &t(c))),
        sc(u, &mm3(&qc, &omega1, &t(&qc))),
        sc(u, &omega2),
        sc(s * xi, &eye()),
        sc(u, &mm3(&i_q, &tt, &t(&i_q))),
        sc(s, &hadamard(&upsilon, &tt)),
    ];
    let omega3_r = sc(s, &hadamard(&omega3, &r_mat));
    // Ψ = κ₁ P̄⁻ Cᵀ Q̄ᵀ; Φ = Σ κ_i (term i) + (1−θ)² Ω₃∘R.
    let psi = sc(kappa[1], &mm3(&p_prior, &t(c), &t(&q_bar)));
    let mut phi = omega3_r;
    for i in 1..=8 {
        phi = add(&phi, &sc(kappa[i], &terms[i]));
    }
    let k = mm(&psi, &inv(&phi));
    let mut out = LocalTerms {
        theta,
        y_bar,
        x_prior,
        p_prior,
        rho,
        lam: lm,
        upsilon,
        omega1,
        omega2,
        omega3,
        xi,
        kappa,
        y_hat,
        terms,
        omega3_r,
        psi,
        phi,
        k,
        x_post: [0.0; 2],
        p_post: zero(),
    };
    if theta == 1.0 && rd.hold == Hold::PredictOnly {
        out.x_post = x_prior;
        out.p_post = p_prior;
        out.k = zero();
        return out;
    }
    // (22): x̂_{t|t} = x̂_{t|t−1} + K (ȳ_t − ŷ_{t|t−1}); (30).
    out.x_post = vadd(&x_prior, &mv(&k, &vsub(&y_bar, &y_hat)));
    out.p_post = lit_bound(&out, inp, &k);
    out
}

/// (50): `P^g = (Σ P̄_m⁻¹)⁻¹`, `x̂^g = P^g Σ P̄_m⁻¹ x̂_m`.
fn lit_fuse(xs: &[V], ps: &[M]) -> (V, M) {
    let mut info = zero();
    for p in ps {
        info = add(&info, &inv(p));
    }
    let pg = inv(&info);
    let mut s = [0.0; 2];
    for (x, p) in xs.iter().zip(ps) {
        s = vadd(&s, &mv(&inv(p), x));
    }
    (mv(&pg, &s), pg)
}

// ---------------------------------------------------------------------------------------------
// The example of section 4 and a deterministic random source.

const L: usize = 3;
const SIGMA: [f64; L] = [0.1, 0.2, 0.3];
const LAMBDA: [f64; L] = [0.1, 0.2, 0.1];
const CHI: f64 = 5.0;
const ETA0: f64 = 1.5;
const XI_D: f64 = 1.5;
const XI_E: f64 = 2.0;
const Q: f64 = 0.05;
const R: f64 = 0.5;
const B: V = [0.16, 0.18];

fn example_eps() -> [f64; 14] {
    let mut e = [0.7; 14];
    e[..5].fill(0.05);
    e[13] = 1.0;
    e
}
fn example_a() -> M {
    let w = 0.052 * std::f64::consts::PI;
    [[w.cos(), w.sin()], [-w.sin(), w.cos()]]
}
fn example_node(m: usize) -> NodeParams {
    NodeParams {
        sigma: SIGMA[m],
        lambda: LAMBDA[m],
        chi: CHI,
        eta0: ETA0,
        d: XI_D,
        e: XI_E,
    }
}

/// The product's configuration of a node with the same parameters.
fn product_cfg(n: &NodeParams, tau: &V, eps: &[f64; 14]) -> TobitFilterConfig<f64, 2> {
    let trig =
        EventTriggerConfig::new_allowing_paper_violation(n.sigma, n.chi, n.lambda, n.eta0).unwrap();
    TobitFilterConfig::new(na_v(tau), BoundScalars::new(*eps).unwrap(), trig, n.d, n.e).unwrap()
}

/// SplitMix64 with Box-Muller normals (deterministic, no dependency).
#[derive(Clone, Debug)]
struct Rng(u64);
impl Rng {
    fn new(seed: u64, run: u64) -> Self {
        let mut r = Rng(seed ^ 0x5EED_0004);
        let s = r.next_u64() ^ run.wrapping_mul(0xA24B_AED4_963E_E407);
        Rng(s)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform on (0, 1).
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    /// A random symmetric positive-definite matrix of size ≈ U(lo, hi).
    fn spd(&mut self, lo: f64, hi: f64) -> M {
        let scale = self.range(lo, hi);
        let g = [
            [self.normal(), self.normal()],
            [self.normal(), self.normal()],
        ];
        add(&sc(scale, &mm(&g, &t(&g))), &sc(0.05 * scale, &eye()))
    }
}

// ---------------------------------------------------------------------------------------------
// The protocol (11)-(20), literally (R9), and one simulated run of the example.

#[derive(Clone, Copy, Debug)]
struct LitProtocol {
    eta: [f64; L],
    y_ref: [V; L],
    /// ξ_{t−1}.
    xi: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct LitDecision {
    alpha: bool,
    beta: bool,
    eta: f64,
}

impl LitProtocol {
    fn new() -> Self {
        Self {
            eta: [ETA0; L],
            y_ref: [[0.0; 2]; L], // τ
            xi: 10.0,             // ξ₀ ("β₀")
        }
    }
    fn step(&mut self, y: &[V; L]) -> [LitDecision; L] {
        let (g, b, c) = (5.0, 30.0, [3.0; L]);
        let mut out = [LitDecision {
            alpha: false,
            beta: false,
            eta: 0.0,
        }; L];
        let xi_m = self.xi / L as f64; // (16)
        let mut spent = 0.0;
        for m in 0..L {
            let eps = vsub(&self.y_ref[m], &y[m]); // (12)
            let norm = (eps[0] * eps[0] + eps[1] * eps[1]).sqrt();
            let alpha = self.eta[m] / CHI + SIGMA[m] - norm <= 0.0; // (14), (15)
            let beta = c[m] <= xi_m; // (18)
            let sent = alpha && beta;
            out[m] = LitDecision {
                alpha,
                beta,
                eta: self.eta[m],
            };
            let norm_after = if sent { 0.0 } else { norm };
            self.eta[m] = LAMBDA[m] * self.eta[m] + SIGMA[m] - norm_after; // (13)
            if sent {
                self.y_ref[m] = y[m];
                spent += c[m];
            }
        }
        self.xi = (self.xi + g - spent).min(b); // (17)
        out
    }
}

/// One instant of a simulated run.
#[derive(Clone, Copy, Debug)]
struct Instant {
    x: V,
    /// Censored measurements y_{m,t} (2).
    y: [V; L],
    decisions: [LitDecision; L],
    level: f64,
}

/// A run of the example: `x₀ ~ N([5, 0]ᵀ, I)`, `x_t = A x_{t−1} + B ω`, `ω ~ N(0, 0.05)`,
/// `z_m = x_t + v_m`, `v_m ~ N(0, 0.5 I)`, censored at τ = 0, then the protocol.
fn simulate(seed: u64, run: u64, horizon: usize) -> Vec<Instant> {
    let mut rng = Rng::new(seed, run);
    let a = example_a();
    let mut x = [5.0 + rng.normal(), rng.normal()];
    let mut proto = LitProtocol::new();
    let mut out = Vec::with_capacity(horizon);
    for _ in 0..horizon {
        let w = Q.sqrt() * rng.normal();
        x = vadd(&mv(&a, &x), &[B[0] * w, B[1] * w]);
        let mut y = [[0.0; 2]; L];
        for ym in y.iter_mut() {
            for j in 0..2 {
                let z = x[j] + R.sqrt() * rng.normal();
                ym[j] = if z > 0.0 { z } else { 0.0 }; // (2) with τ = 0
            }
        }
        let decisions = proto.step(&y);
        out.push(Instant {
            x,
            y,
            decisions,
            level: proto.xi,
        });
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The end-to-end transcription of Algorithm 1 (estimator side: lines 14-25).

#[derive(Clone, Copy, Debug)]
struct LitFtkff {
    rd: Reading,
    alpha: [f64; L],
    /// x̂_{m,t−1|t−1}, P̄_{m,t−1|t−1} after the reset.
    x: [V; L],
    p: [M; L],
    y_bar: [V; L],
    g: [f64; L],
    y_prev: [V; L],
    /// Outputs of the last step: local (before the reset) and fused.
    x_loc: [V; L],
    p_loc: [M; L],
    xg: V,
    pg: M,
}

impl LitFtkff {
    fn new(rd: Reading) -> Self {
        let alpha = [1.0 / L as f64; L];
        let p0 = eye();
        let p = core::array::from_fn(|m| {
            if rd.p0_unscaled {
                p0
            } else {
                sc(1.0 / alpha[m], &p0)
            }
        });
        Self {
            rd,
            alpha,
            x: [[5.0, 0.0]; L],
            p,
            y_bar: [[0.0; 2]; L],
            g: [ETA0 * ETA0; L],
            y_prev: [[0.0; 2]; L],
            x_loc: [[5.0, 0.0]; L],
            p_loc: p,
            xg: [5.0, 0.0],
            pg: p0,
        }
    }

    fn step(&mut self, inst: &Instant) {
        for m in 0..L {
            let sent = inst.decisions[m].alpha && inst.decisions[m].beta;
            let y_bar_prev = match self.rd.hold {
                Hold::PreviousMeasurement => self.y_prev[m],
                _ => self.y_bar[m],
            };
            let inp = LocalIn {
                a: example_a(),
                b: B,
                q: Q,
                alpha: self.alpha[m],
                c: eye(),
                r: [R, R],
                tau: [0.0, 0.0],
                eps: example_eps(),
                node: example_node(m),
                x: self.x[m],
                p: self.p[m],
                y_bar_prev,
                g: self.g[m],
                received: sent.then_some(inst.y[m]),
            };
            let lt = lit_local(&inp, &self.rd);
            self.x_loc[m] = lt.x_post;
            self.p_loc[m] = lt.p_post;
            self.y_bar[m] = lt.y_bar;
            self.g[m] = lit_xi(&inp.node, self.g[m]);
            self.y_prev[m] = inst.y[m];
        }
        let (xg, pg) = lit_fuse(&self.x_loc, &self.p_loc);
        self.xg = xg;
        self.pg = pg;
        for m in 0..L {
            match self.rd.reset {
                Reset::Both => {
                    self.x[m] = xg;
                    self.p[m] = sc(1.0 / self.alpha[m], &pg);
                }
                Reset::StateOnly => {
                    self.x[m] = xg;
                    self.p[m] = self.p_loc[m];
                }
                Reset::BoundOnly => {
                    self.x[m] = self.x_loc[m];
                    self.p[m] = sc(1.0 / self.alpha[m], &pg);
                }
                Reset::BoundUnscaled => {
                    self.x[m] = xg;
                    self.p[m] = pg;
                }
            }
        }
    }
}

/// The product's fusion filter of the example whose local filters do `silence` at θ = 1.
fn product_fusion_with(silence: Silence) -> TobitFusion<f64, 2, 2, L> {
    let cfgs = core::array::from_fn(|m| {
        product_cfg(&example_node(m), &[0.0, 0.0], &example_eps()).with_silence(silence)
    });
    TobitFusion::new(cfgs, na_v(&[5.0, 0.0]), na_m(&eye())).unwrap()
}

fn product_step(f: &mut TobitFusion<f64, 2, 2, L>, inst: &Instant) {
    let bqb = na_m(&sc(Q, &outer(&B, &B)));
    let ys: [SVector<f64, 2>; L] = core::array::from_fn(|m| na_v(&inst.y[m]));
    let rec: [Option<&SVector<f64, 2>>; L] = core::array::from_fn(|m| {
        (inst.decisions[m].alpha && inst.decisions[m].beta).then_some(&ys[m])
    });
    f.step(
        &na_m(&example_a()),
        &bqb,
        &[SMatrix::identity(); L],
        &[na_v(&[R, R]); L],
        rec,
    )
    .unwrap();
}

// ---------------------------------------------------------------------------------------------
// Random inputs for the per-equation tests.

/// A random node step with every term of (30) active: random C, R, τ ≠ 0, a prediction
/// within a few σ of the threshold, random ȳ_{t−1} and Ḡ.
fn random_local(rng: &mut Rng, received: bool) -> LocalIn {
    let w = rng.range(0.05, 0.5);
    let s = rng.range(0.7, 1.3);
    let mut eps = [0.0; 14];
    for e in eps.iter_mut() {
        *e = rng.range(0.03, 2.0);
    }
    LocalIn {
        a: [[s * w.cos(), w.sin()], [-w.sin(), s * w.cos()]],
        b: [rng.normal(), rng.normal()],
        q: rng.range(0.01, 0.5),
        alpha: rng.range(0.1, 0.9),
        c: [
            [rng.range(0.5, 1.5), rng.range(-0.5, 0.5)],
            [rng.range(-0.5, 0.5), rng.range(0.5, 1.5)],
        ],
        r: [rng.range(0.05, 2.0), rng.range(0.05, 2.0)],
        tau: [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
        eps,
        node: NodeParams {
            sigma: rng.range(0.0, 0.5),
            lambda: rng.range(0.05, 0.5),
            chi: rng.range(1.0, 8.0),
            eta0: rng.range(0.0, 2.0),
            d: rng.range(0.5, 3.0),
            e: rng.range(0.5, 3.0),
        },
        x: [rng.range(-3.0, 3.0), rng.range(-3.0, 3.0)],
        p: rng.spd(0.1, 3.0),
        y_bar_prev: [rng.range(-1.0, 3.0), rng.range(-1.0, 3.0)],
        g: rng.range(0.0, 3.0),
        received: received.then(|| [rng.range(-1.0, 3.0), rng.range(-1.0, 3.0)]),
    }
}

/// Inputs of the example: node m, the state near the oscillator's circle of radius 5.
fn example_local(rng: &mut Rng, m: usize, received: bool) -> LocalIn {
    let phase = rng.range(0.0, 2.0 * std::f64::consts::PI);
    let rad = rng.range(3.0, 7.0);
    let x = [rad * phase.cos(), rad * phase.sin()];
    LocalIn {
        a: example_a(),
        b: B,
        q: Q,
        alpha: 1.0 / 3.0,
        c: eye(),
        r: [R, R],
        tau: [0.0, 0.0],
        eps: example_eps(),
        node: example_node(m),
        x,
        p: rng.spd(2.0, 20.0),
        y_bar_prev: [x[0].max(0.0), x[1].max(0.0)],
        g: rng.range(0.0, 2.5),
        received: received.then(|| [(x[0] + 0.3).max(0.0), (x[1] - 0.2).max(0.0)]),
    }
}

/// A product filter in the state the literal step starts from: ȳ_{t−1} and Ḡ_t are set by
/// one received step (ȳ ← y, Ḡ ← Ξ(Ḡ)), then x̂ and P̄ by the reset.
fn product_filter_at(inp: &LocalIn) -> TobitFilter<f64, 2, 2> {
    // Ḡ after that one step is Ξ(η₀²); `literal_at` starts the transcription from the same Ḡ.
    let cfg = product_cfg(&inp.node, &inp.tau, &inp.eps);
    let mut f = TobitFilter::new(cfg, na_v(&inp.x), na_m(&inp.p)).unwrap();
    let bqb = na_m(&sc(inp.q / inp.alpha, &outer(&inp.b, &inp.b)));
    f.step(
        &na_m(&inp.a),
        &bqb,
        &na_m(&inp.c),
        &na_v(&inp.r),
        Some(&na_v(&inp.y_bar_prev)),
    )
    .unwrap();
    f.reset(na_v(&inp.x), na_m(&inp.p)).unwrap();
    f
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
}

// ---------------------------------------------------------------------------------------------
// (5), (6), (7), (9), (10), (23).

/// Inputs `(Cx, τ, R)` of the scalar Tobit equations: random, and the example's (τ = 0,
/// R = 0.5, predictions on the oscillator's circle, |Cx| ≤ 7, so |ζ| ≤ 10).
fn scalar_inputs() -> Vec<(f64, f64, f64)> {
    let mut rng = Rng::new(5, 0);
    let mut v: Vec<_> = (0..2000)
        .map(|_| {
            (
                rng.range(-6.0, 6.0),
                rng.range(-2.0, 2.0),
                rng.range(0.05, 3.0),
            )
        })
        .collect();
    v.extend((0..=280).map(|i| (-7.0 + 0.05 * i as f64, 0.0, R)));
    v
}

#[test]
fn one_minus_cdf_is_the_printed_subtraction() {
    // Where 1 − Φ(ζ) ≥ 1e-3 the subtraction loses at most 3 digits: 1e-12 relative.
    for i in 0..=600 {
        let z = -6.0 + 0.01 * i as f64;
        assert!(rel(1.0 - cdf(z), one_minus_cdf(z)) < 1e-12, "ζ = {z}");
    }
}

#[test]
fn eq5_censoring_probability() {
    // Both evaluate erfc at the same point up to one rounding of x = (Cx − τ)/√R; Φ's relative
    // condition number |x φ(x)/Φ(x)| is ≤ 1 + x², so the stated tolerance is 1e-15 (1 + x²)
    // relative (≤ 1e-13 on the example's |x| ≤ 10; the random inputs reach |x| ≈ 36).
    for (cx, tau, r) in scalar_inputs() {
        let x = (cx - tau) / r.sqrt();
        let tol = 1e-15 * (1.0 + x * x);
        let lit = lit_rho(cx, tau, r);
        let got = prob_uncensored(cx, tau, r);
        let st = TobitStats::new(&s1(cx), &s1(tau), &s1(r)).unwrap();
        assert!(
            rel(lit, got) < tol,
            "(5) Cx={cx} τ={tau} R={r}: {lit} vs {got}"
        );
        assert!(rel(lit, st.rho[0]) < tol);
        // Υ = ϱ̄(1 − ϱ̄) as printed (the product forms Φ(−ζ)Φ(ζ)): the same relative error
        // plus the cancellation of 1 − ϱ̄ when ϱ̄ → 1 (absolute 2e-16 in 1 − ϱ̄).
        let ups = lit * (1.0 - lit);
        assert!(
            (ups - st.upsilon[0]).abs() <= tol * ups + 2e-16 * lit,
            "Υ Cx={cx}: {ups} vs {}",
            st.upsilon[0]
        );
    }
}

#[test]
fn eq6_eq9_eq23_expectation() {
    // λ: the product uses a continued fraction above ζ = 4 (documented 1e-13 relative), the
    // transcription φ(ζ)/Φ(−ζ), whose exp(−ζ²/2) sees the rounding of ζ²/2 (≈ ζ² eps/2
    // relative): 1e-12 + 1e-15 ζ² relative. E{y|x}: the bracket
    // Cx + √R λ cancels when the prediction is far below τ (λ ≈ ζ), so the error is relative
    // to the size of its terms: |ΔE| ≤ 1e-12 (ϱ̄ (|Cx| + √R λ) + |τ|).
    for (cx, tau, r) in scalar_inputs() {
        let z = (tau - cx) / r.sqrt();
        let st = TobitStats::new(&s1(cx), &s1(tau), &s1(r)).unwrap();
        assert!(rel(lam(z), st.lambda[0]) < 1e-12 + 1e-15 * z * z, "λ({z})");
        let lit = lit_mean(cx, tau, r);
        let scale = lit_rho(cx, tau, r) * (cx.abs() + r.sqrt() * lam(z)) + tau.abs();
        for got in [censored_mean(cx, tau, r), st.mean[0]] {
            assert!(
                (lit - got).abs() <= 1e-12 * scale,
                "(6)/(23) Cx={cx} τ={tau} R={r}: {lit} vs {got}"
            );
        }
    }
    // (9) is (6) per component, and (23) at C x̂_{t|t−1} is (9): vector case with τ ≠ 0.
    let mut rng = Rng::new(9, 0);
    for _ in 0..500 {
        let inp = random_local(&mut rng, true);
        let lt = lit_local(&inp, &Reading::default());
        let cx = mv(&inp.c, &lt.x_prior);
        let st = TobitStats::new(&na_v(&cx), &na_v(&inp.tau), &na_v(&inp.r)).unwrap();
        for j in 0..2 {
            let e6 = lit_mean(cx[j], inp.tau[j], inp.r[j]);
            let scale = 1.0 + cx[j].abs() + inp.tau[j].abs() + inp.r[j].sqrt() * lt.lam[j];
            assert!((lt.y_hat[j] - e6).abs() <= 1e-13 * scale, "(23) = (9)");
            assert!((lt.y_hat[j] - st.mean[j]).abs() <= 1e-12 * scale, "(23)");
        }
    }
}

#[test]
fn eq7_eq10_variance() {
    // (7) R[1 − λ(λ − ζ)] as printed: for ζ ≫ 1 the transcription's λ carries ≈ ζ² eps/2
    // (the rounding of ζ²/2 in φ(ζ)), and λ − ζ ≈ 1/ζ and 1 − φ ≈ 1/ζ² each amplify it by ζ²
    // (the product avoids both with a continued fraction). Stated tolerance:
    // 1e-13 + 1e-15 (1 + ζ²)³ relative (1e-9 at the example's |ζ| ≤ 10).
    for (cx, tau, r) in scalar_inputs() {
        let z = (tau - cx) / r.sqrt();
        let lit = lit_var(cx, tau, r);
        let tol = 1e-13 + 1e-15 * (1.0 + z * z).powi(3);
        assert!(
            rel(lit, paper_variance(cx, tau, r)) < tol,
            "(7) Cx={cx} τ={tau} R={r}: {lit} vs {}",
            paper_variance(cx, tau, r)
        );
        let st = TobitStats::new(&s1(cx), &s1(tau), &s1(r)).unwrap();
        assert!(rel(lit, st.paper_variance()[0]) < tol, "(10)");
    }
}

// ---------------------------------------------------------------------------------------------
// (21), (29), Ω₁, Ω₂, Ω₃, Υ, Ξ, κ and every term of Φ (37) separately.

/// The product's M (every `K(·)Kᵀ` term of (30)) for `inp` with ε replaced by `eps`.
fn product_m(
    inp: &LocalIn,
    eps: &[f64; 14],
) -> (M, estimator_core::filter::tobit::LocalStepPlan<f64, 2, 2>) {
    let mut inp2 = *inp;
    inp2.eps = *eps;
    let f = product_filter_at(&inp2);
    let bqb = na_m(&sc(inp.q / inp.alpha, &outer(&inp.b, &inp.b)));
    let rec = inp.received.map(|y| na_v(&y));
    let plan = f
        .plan(
            &na_m(&inp.a),
            &bqb,
            &na_m(&inp.c),
            &na_v(&inp.r),
            rec.as_ref(),
        )
        .unwrap();
    (m_na(&plan.problem.m), plan)
}

/// The literal step at the state the product filter is in (its Ḡ comes from one step).
fn literal_at(inp: &LocalIn, eps: &[f64; 14]) -> LocalTerms {
    let mut inp2 = *inp;
    inp2.eps = *eps;
    inp2.g = lit_xi(&inp.node, inp.node.eta0 * inp.node.eta0);
    lit_local(&inp2, &Reading::default())
}

fn check_ingredients(inp: &LocalIn, what: &str) {
    let (m_prod, plan) = product_m(inp, &inp.eps);
    let lt = literal_at(inp, &inp.eps);
    // (21), (29): one matrix product and a sum; 1e-13 relative to the largest entry.
    assert!(vamax(&vsub(&v_na(&plan.x_prior), &lt.x_prior)) <= 1e-13 * vamax(&lt.x_prior).max(1.0));
    let pp = m_na(&plan.problem.p_prior);
    assert!(
        amax(&sub(&pp, &lt.p_prior)) <= 1e-13 * amax(&lt.p_prior),
        "{what}: (29)"
    );
    // θ, ȳ_t (19)-(20).
    assert_eq!(plan.theta, lt.theta, "{what}: θ");
    assert_eq!(v_na(&plan.y_bar), lt.y_bar, "{what}: ȳ");
    // Q̄ (5), λ, Υ: as in eq5/eq6 (1e-13, 1e-12 relative).
    for j in 0..2 {
        assert!(rel(plan.stats.rho[j], lt.rho[j]) < 1e-12, "{what}: ϱ̄");
        assert!(rel(plan.stats.lambda[j], lt.lam[j]) < 1e-12, "{what}: λ");
        let u = lt.upsilon[j][j];
        assert!(
            (plan.stats.upsilon[j] - u).abs() <= 1e-12 * u + 2e-16,
            "{what}: Υ"
        );
    }
    // Ω₁, Ω₂: sums of two products; 1e-13 relative to the largest entry.
    let o1 = m_na(&plan.omega1);
    assert!(
        amax(&sub(&o1, &lt.omega1)) <= 1e-13 * amax(&lt.omega1),
        "{what}: Ω₁"
    );
    let o2 = m_na(&plan.omega2);
    assert!(
        amax(&sub(&o2, &lt.omega2)) <= 1e-15 * amax(&lt.omega2).max(1e-300),
        "{what}: Ω₂"
    );
    // Ξ(Ḡ) and κ: the same few scalar operations; 1e-14 relative.
    assert!(rel(plan.xi, lt.xi) < 1e-14, "{what}: Ξ");
    for i in 1..=8 {
        assert!(
            rel(plan.kappas.0[i - 1], lt.kappa[i]) < 1e-14,
            "{what}: κ{i}"
        );
    }
    // M as a whole: Φ − κ₁ term. Sum of ~10 terms: 1e-12 relative to the largest.
    let mut m_lit = lt.omega3_r;
    for i in 2..=8 {
        m_lit = add(&m_lit, &sc(lt.kappa[i], &lt.terms[i]));
    }
    assert!(
        amax(&sub(&m_prod, &m_lit)) <= 1e-12 * amax(&m_lit),
        "{what}: M"
    );
    // Ψ, Φ (37).
    let psi = m_na(&plan.problem.psi());
    assert!(
        amax(&sub(&psi, &lt.psi)) <= 1e-13 * amax(&lt.psi),
        "{what}: Ψ"
    );
    let phi = m_na(&plan.problem.phi());
    assert!(
        amax(&sub(&phi, &lt.phi)) <= 1e-12 * amax(&lt.phi),
        "{what}: Φ"
    );
}

/// Each κ_i term of Φ separately: changing one ε_j that enters only κ₁ (not in M) and κ_i
/// moves the product's M by exactly Δκ_i × (term i); ε₆ enters κ₃ and κ₈, so two changes of
/// ε₆ determine both terms. The residual M − Σ κ_i (term i) is the Ω₃∘R term.
fn check_terms_separately(inp: &LocalIn, what: &str) {
    let base = inp.eps;
    let (m0, _) = product_m(inp, &base);
    let lt0 = literal_at(inp, &base);
    let scale = amax(&m0);
    // The product's M carries rounding of ≈ 1e-15 × scale per evaluation; the difference of
    // two evaluations divided by Δκ (≥ 0.5 here) is accurate to 1e-13 × scale / Δκ.
    let with = |j: usize, v: f64| {
        let mut e = base;
        e[j - 1] = v;
        e
    };
    let single = |i: usize, j: usize, name: &str| {
        let alt = with(j, base[j - 1] / 4.0);
        let (m1, _) = product_m(inp, &alt);
        let lt1 = literal_at(inp, &alt);
        let dk = lt1.kappa[i] - lt0.kappa[i];
        assert!(dk.abs() > 0.4, "Δκ{i} = {dk}");
        let extracted = sc(1.0 / dk, &sub(&m1, &m0));
        let tol = 1e-13 * scale.max(amax(&m1)) / dk.abs();
        assert!(
            amax(&sub(&extracted, &lt0.terms[i])) <= tol + 1e-13 * amax(&lt0.terms[i]),
            "{what}: κ{i} term ({name}) product {extracted:?} vs literal {:?}",
            lt0.terms[i]
        );
    };
    single(2, 1, "Q̄ λ√R √Rᵀλᵀ Q̄ᵀ");
    single(4, 2, "θ² Q̄ C Ω₁ Cᵀ Q̄ᵀ");
    single(5, 3, "θ² Ω₂");
    single(6, 4, "(1−θ)² Ξ(Ḡ) I");
    single(7, 5, "θ² (I−Q̄)ττᵀ(I−Q̄)ᵀ");
    // κ₃ = 1 + ε₆, κ₈ = 1 + ε₆⁻¹: two changes, solve per entry.
    let (a, b, c) = (base[5], base[5] * 3.0, base[5] / 3.0);
    let (mb, _) = product_m(inp, &with(6, b));
    let (mc, _) = product_m(inp, &with(6, c));
    let (d1b, d8b) = (b - a, 1.0 / b - 1.0 / a);
    let (d1c, d8c) = (c - a, 1.0 / c - 1.0 / a);
    let det = d1b * d8c - d8b * d1c;
    let mut t3 = zero();
    let mut t8 = zero();
    for i in 0..2 {
        for j in 0..2 {
            let (yb, yc) = (mb[i][j] - m0[i][j], mc[i][j] - m0[i][j]);
            t3[i][j] = (yb * d8c - d8b * yc) / det;
            t8[i][j] = (d1b * yc - yb * d1c) / det;
        }
    }
    let tol = 1e-12 * scale.max(amax(&mb)).max(amax(&mc)) * (d1b.abs() + d8b.abs()) / det.abs();
    assert!(
        amax(&sub(&t3, &lt0.terms[3])) <= tol + 1e-13 * amax(&lt0.terms[3]),
        "{what}: κ₃ term (1−θ)² C(Υ∘Ω₁)Cᵀ product {t3:?} vs literal {:?}",
        lt0.terms[3]
    );
    assert!(
        amax(&sub(&t8, &lt0.terms[8])) <= tol + 1e-13 * amax(&lt0.terms[8]),
        "{what}: κ₈ term (1−θ)² Υ∘ττᵀ product {t8:?} vs literal {:?}",
        lt0.terms[8]
    );
    // What is left of the product's M is (1−θ)² Ω₃∘R.
    let mut rest = m0;
    for i in 2..=8 {
        rest = sub(&rest, &sc(lt0.kappa[i], &lt0.terms[i]));
    }
    assert!(
        amax(&sub(&rest, &lt0.omega3_r)) <= 1e-12 * scale,
        "{what}: (1−θ)² Ω₃∘R product {rest:?} vs literal {:?} (Ω₃ = {:?})",
        lt0.omega3_r,
        lt0.omega3
    );
}

#[test]
fn eq21_eq29_and_every_omega_and_kappa_term_of_eq37() {
    let mut rng = Rng::new(37, 0);
    for case in 0..300 {
        let received = case % 2 == 0;
        let inp = random_local(&mut rng, received);
        check_ingredients(
            &inp,
            &format!("random case {case} (θ = {})", !received as u8),
        );
        check_terms_separately(&inp, &format!("random case {case}"));
    }
    for case in 0..300 {
        let received = case % 2 == 0;
        let inp = example_local(&mut rng, case % L, received);
        check_ingredients(
            &inp,
            &format!("example case {case} (θ = {})", !received as u8),
        );
        check_terms_separately(&inp, &format!("example case {case}"));
    }
}

// ---------------------------------------------------------------------------------------------
// The gain (37)/(40), the estimate (22) and the bound (30).

#[test]
fn eq37_gain_eq22_estimate_eq30_bound() {
    // K = ΨΦ⁻¹ by the adjugate (transcription) vs the equilibrated Cholesky solve (product):
    // both are backward stable, so they agree to ≈ eps · cond(DΦD) where D equilibrates;
    // stated tolerance 1e-13 · (1 + cond(DΦD)) relative to the largest gain entry. (22): one
    // product and a sum on top: the same tolerance times the innovation's size. (30): a sum of
    // nine matrices, 1e-12 relative to the largest of them (the Joseph term dominates).
    let mut rng = Rng::new(30, 0);
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for case in 0..1200 {
        let received = case % 2 == 0;
        let inp = if case < 600 {
            random_local(&mut rng, received)
        } else {
            example_local(&mut rng, case % L, received)
        };
        let f = product_filter_at(&inp);
        let lt = literal_at(&inp, &inp.eps);
        let bqb = na_m(&sc(inp.q / inp.alpha, &outer(&inp.b, &inp.b)));
        let rec = inp.received.map(|y| na_v(&y));
        let plan = f
            .plan(
                &na_m(&inp.a),
                &bqb,
                &na_m(&inp.c),
                &na_v(&inp.r),
                rec.as_ref(),
            )
            .unwrap();
        let k_prod = m_na(&plan.problem.gain().unwrap());
        let dd = [1.0 / lt.phi[0][0].sqrt(), 1.0 / lt.phi[1][1].sqrt()];
        let phi_eq = mm3(&diag(&dd), &lt.phi, &diag(&dd));
        let tol_k = 1e-13 * (1.0 + cond_spd(&phi_eq));
        let dk = amax(&sub(&k_prod, &lt.k)) / amax(&lt.k);
        assert!(dk <= tol_k, "case {case}: (37) K {k_prod:?} vs {:?}", lt.k);
        worst.0 = worst.0.max(dk / tol_k);
        // (40) is (37) with Φ's terms regrouped: the same matrix.
        let mut braces = sc(lt.kappa[1], &lt.terms[1]);
        braces = add(&braces, &lt.omega3_r);
        for i in 2..=8 {
            braces = add(&braces, &sc(lt.kappa[i], &lt.terms[i]));
        }
        assert!(amax(&sub(&braces, &lt.phi)) <= 1e-14 * amax(&lt.phi));
        // (30) at the product's gain and at a perturbed gain.
        for k in [k_prod, add(&k_prod, &[[0.1, -0.2], [0.05, 0.3]])] {
            let lit = lit_bound(&lt, &inp, &k);
            let got = m_na(&plan.problem.bound(&na_m(&k)));
            let d = amax(&sub(&lit, &got)) / amax(&lit);
            assert!(d <= 1e-12, "case {case}: (30) {got:?} vs {lit:?}");
            worst.1 = worst.1.max(d / 1e-12);
        }
        // One full product step = (22) and (30) at the transcription's gain.
        let mut g = f;
        g.step(
            &na_m(&inp.a),
            &bqb,
            &na_m(&inp.c),
            &na_v(&inp.r),
            rec.as_ref(),
        )
        .unwrap();
        let innov = vamax(&vsub(&lt.y_bar, &lt.y_hat)).max(1.0);
        let dx = vamax(&vsub(&v_na(g.estimate().state()), &lt.x_post));
        assert!(
            dx <= tol_k * amax(&lt.k) * innov + 1e-13 * vamax(&lt.x_prior),
            "case {case}: (22) {:?} vs {:?}",
            g.estimate().state(),
            lt.x_post
        );
        let dp = amax(&sub(&m_na(g.estimate().covariance()), &lt.p_post)) / amax(&lt.p_post);
        let tol_p = 1e-12 + 4.0 * tol_k * amax(&lt.k) * amax(&lt.psi) / amax(&lt.p_post);
        assert!(
            dp <= tol_p,
            "case {case}: step's P̄ vs (30) at the literal K: {dp}"
        );
        worst.2 = worst.2.max(dp / tol_p);
        // Ḡ_{t+1} = Ξ(Ḡ_t).
        assert!(rel(g.g_bar(), lt.xi) < 1e-14);
    }
    eprintln!(
        "largest discrepancy / tolerance: (37) {:.2e}, (30) {:.2e}, step P̄ {:.2e}",
        worst.0, worst.1, worst.2
    );
}

// ---------------------------------------------------------------------------------------------
// (50), (51).

#[test]
fn eq50_fusion() {
    // Adjugate inverses (transcription) vs Cholesky (product): ≈ eps · cond per inverse, two
    // levels of inversion; stated 1e-13 · (cond(Σ P̄⁻¹) + max cond(P̄_m)) relative.
    let mut rng = Rng::new(50, 0);
    for case in 0..2000 {
        let ps: [M; L] = core::array::from_fn(|_| rng.spd(0.1, 30.0));
        let xs: [V; L] = core::array::from_fn(|_| [rng.range(-6.0, 6.0), rng.range(-6.0, 6.0)]);
        let (xg, pg) = lit_fuse(&xs, &ps);
        let (xg_p, pg_p) = federated_fuse(&xs.map(|x| na_v(&x)), &ps.map(|p| na_m(&p))).unwrap();
        let mut info = zero();
        for p in &ps {
            info = add(&info, &inv(p));
        }
        let conds = ps.iter().map(cond_spd).fold(cond_spd(&info), f64::max);
        let tol = 1e-13 * conds;
        assert!(
            amax(&sub(&m_na(&pg_p), &pg)) <= tol * amax(&pg),
            "case {case}: P^g"
        );
        let xs_scale = xs.iter().map(vamax).fold(0.0, f64::max);
        assert!(
            vamax(&vsub(&v_na(&xg_p), &xg)) <= tol * xs_scale,
            "case {case}: x̂^g {xg_p:?} vs {xg:?}"
        );
    }
}

#[test]
fn eq51_reset_and_information_weights() {
    // After every step: x̂_m = x̂^g and P̄_m = α_m⁻¹ P^g (exact up to one division: 1e-15
    // relative); each node's pre-reset estimate is the transcription's local step from the
    // previous reset state with Q_m = α_m⁻¹ Q (tolerances as in eq37_gain_eq22_estimate_eq30_bound,
    // 1e-10 relative covers them on these inputs). Unequal weights, so α_m matters per node.
    let alpha = [0.5, 0.3, 0.2];
    let cfgs = core::array::from_fn(|m| product_cfg(&example_node(m), &[0.0, 0.0], &example_eps()));
    let mut f = TobitFusion::with_weights(cfgs, na_v(&[5.0, 0.0]), na_m(&eye()), alpha).unwrap();
    for m in 0..L {
        let p = m_na(f.local(m).unwrap().estimate().covariance());
        assert!(
            amax(&sub(&p, &sc(1.0 / alpha[m], &eye()))) < 1e-15,
            "P̄_m,0|0 = α⁻¹P₀"
        );
    }
    let run = simulate(51, 0, 100);
    let mut x_prev = [[5.0, 0.0]; L];
    let mut p_prev: [M; L] = core::array::from_fn(|m| sc(1.0 / alpha[m], &eye()));
    let mut y_bar = [[0.0; 2]; L];
    let mut g = [ETA0 * ETA0; L];
    for (k, inst) in run.iter().enumerate() {
        product_step(&mut f, inst);
        let mut xs = [[0.0; 2]; L];
        let mut ps = [zero(); L];
        for m in 0..L {
            let sent = inst.decisions[m].alpha && inst.decisions[m].beta;
            let inp = LocalIn {
                a: example_a(),
                b: B,
                q: Q,
                alpha: alpha[m],
                c: eye(),
                r: [R, R],
                tau: [0.0, 0.0],
                eps: example_eps(),
                node: example_node(m),
                x: x_prev[m],
                p: p_prev[m],
                y_bar_prev: y_bar[m],
                g: g[m],
                received: sent.then_some(inst.y[m]),
            };
            let lt = lit_local(&inp, &Reading::default());
            y_bar[m] = lt.y_bar;
            g[m] = lit_xi(&inp.node, g[m]);
            let e = f.local_estimate(m).unwrap();
            assert!(
                vamax(&vsub(&v_na(e.state()), &lt.x_post)) <= 1e-10 * vamax(&lt.x_post).max(1.0),
                "k = {}, node {m}: local x̂",
                k + 1
            );
            assert!(
                amax(&sub(&m_na(e.covariance()), &lt.p_post)) <= 1e-10 * amax(&lt.p_post),
                "k = {}, node {m}: local P̄",
                k + 1
            );
            xs[m] = v_na(e.state());
            ps[m] = m_na(e.covariance());
        }
        let (xg, pg) = lit_fuse(&xs, &ps);
        for m in 0..L {
            let loc = f.local(m).unwrap().estimate();
            assert!(vamax(&vsub(&v_na(loc.state()), &xg)) <= 1e-12 * vamax(&xg).max(1.0));
            let want = sc(1.0 / alpha[m], &pg);
            assert!(amax(&sub(&m_na(loc.covariance()), &want)) <= 1e-12 * amax(&want));
            x_prev[m] = xg;
            p_prev[m] = want;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// (11)-(20): the protocol, literally, against the product's scheduler.

#[test]
fn eqs11_to_20_protocol_matches_the_scheduler() {
    // Same operations in the same order: decisions equal exactly, η to 1e-15 absolute.
    let (mut sent_total, mut trig_total) = ([0u32; L], [0u32; L]);
    for run in 0..50 {
        let inst = simulate(1120, run, 200);
        let nodes: [EventTrigger<f64, 2>; L] = core::array::from_fn(|m| {
            let c =
                EventTriggerConfig::new_allowing_paper_violation(SIGMA[m], CHI, LAMBDA[m], ETA0)
                    .unwrap();
            EventTrigger::new(c, SVector::zeros()).unwrap()
        });
        let bucket = SharedTokenBucket::<L>::new(10, 5, 30, [3; L]).unwrap();
        let mut s = TriggeredBucketScheduler::new(nodes, bucket);
        for (k, i) in inst.iter().enumerate() {
            let ys: [SVector<f64, 2>; L] = core::array::from_fn(|m| na_v(&i.y[m]));
            let d = s.step(&ys).unwrap();
            for m in 0..L {
                let lit = i.decisions[m];
                assert_eq!(
                    (d[m].triggered, d[m].granted, d[m].sent),
                    (lit.alpha, lit.beta, lit.alpha && lit.beta),
                    "run {run} k = {} node {m}",
                    k + 1
                );
                assert!(
                    (d[m].eta - lit.eta).abs() <= 1e-15,
                    "η run {run} k = {}",
                    k + 1
                );
                sent_total[m] += d[m].sent as u32;
                trig_total[m] += d[m].triggered as u32;
            }
            assert_eq!(
                s.bucket().level() as f64,
                i.level,
                "ξ run {run} k = {}",
                k + 1
            );
        }
        // (2): the product's censor gives the same y.
        let (y, _) = censor(&na_v(&inst[0].y[0]), &SVector::zeros()).unwrap();
        assert_eq!(v_na(&y), inst[0].y[0]);
    }
    eprintln!("triggered {trig_total:?}, sent {sent_total:?} (50 runs × 200)");
}

// ---------------------------------------------------------------------------------------------
// Algorithm 1 end to end.

/// Per-run average MSE over k = from..T of the three local estimates (before the reset) and
/// the fused one.
#[derive(Clone, Debug, Default)]
struct RunMse {
    local: [f64; L],
    fused: f64,
}

fn mse_of(run: &[Instant], from: usize, est: &mut dyn FnMut(&Instant) -> ([V; L], V)) -> RunMse {
    let mut out = RunMse::default();
    let n = (run.len() + 1 - from) as f64;
    for (k, inst) in (1..).zip(run) {
        let (xl, xg) = est(inst);
        if k < from {
            continue;
        }
        for m in 0..L {
            let e = vsub(&inst.x, &xl[m]);
            out.local[m] += (e[0] * e[0] + e[1] * e[1]) / n;
        }
        let e = vsub(&inst.x, &xg);
        out.fused += (e[0] * e[0] + e[1] * e[1]) / n;
    }
    out
}

#[test]
fn algorithm1_end_to_end_matches_the_literal_transcription() {
    // 200 runs × T = 200 of the example. The two implementations differ in rounding only
    // (summation order, adjugate vs equilibrated Cholesky); through the recursion those
    // differences stay at ≈ 1e-14 relative to the state's and the bound's scale (measured:
    // 1.1e-14). Stated tolerance 1e-11 relative: 1000× the rounding seen, and 3000× below the
    // smallest change any alternative reading of `alternative_readings_of_the_example` makes
    // at the first instant it acts (Ω₁ by (26): 3.5e-8).
    end_to_end_against_the_transcription(Reading::default(), Silence::HeldMeasurement);
}

#[test]
fn predict_on_silence_matches_the_transcriptions_predict_only_reading() {
    // The product's option `Silence::Predict` against the transcription's `Hold::PredictOnly`
    // (written independently, in this file, for the audit table), with the same tolerance
    // and for the same reason as the paper's filter above.
    let rd = Reading {
        hold: Hold::PredictOnly,
        ..Reading::default()
    };
    end_to_end_against_the_transcription(rd, Silence::Predict);
}

/// The product's fusion filter with `silence` and the transcription with `rd` on the same
/// 200 runs × T = 200 of the example: every local and fused estimate and bound within 1e-11
/// relative, and the same MSEs.
fn end_to_end_against_the_transcription(rd: Reading, silence: Silence) {
    let (runs, horizon) = (200u64, 200usize);
    let tol = 1e-11;
    let mut worst = 0.0f64;
    let mut first_divergence: Option<(u64, usize, String)> = None;
    let (mut mse_p, mut mse_l) = (RunMse::default(), RunMse::default());
    for run in 0..runs {
        let inst = simulate(2026, run, horizon);
        let mut prod = product_fusion_with(silence);
        let mut lit = LitFtkff::new(rd);
        for (k, i) in inst.iter().enumerate() {
            product_step(&mut prod, i);
            lit.step(i);
            let mut check = |name: String, d: f64| {
                worst = worst.max(d);
                if d > tol && first_divergence.is_none() {
                    first_divergence = Some((run, k + 1, format!("{name}: {d:.3e}")));
                }
            };
            for m in 0..L {
                let e = prod.local_estimate(m).unwrap();
                let xs = vamax(&lit.x_loc[m]).max(1.0);
                check(
                    format!("x̂_{}", m + 1),
                    vamax(&vsub(&v_na(e.state()), &lit.x_loc[m])) / xs,
                );
                check(
                    format!("P̄_{}", m + 1),
                    amax(&sub(&m_na(e.covariance()), &lit.p_loc[m])) / amax(&lit.p_loc[m]),
                );
            }
            check(
                "x̂^g".into(),
                vamax(&vsub(&v_na(prod.estimate().state()), &lit.xg)) / vamax(&lit.xg).max(1.0),
            );
            check(
                "P^g".into(),
                amax(&sub(&m_na(prod.estimate().covariance()), &lit.pg)) / amax(&lit.pg),
            );
        }
        // MSE of both over the same run.
        let mut prod = product_fusion_with(silence);
        let r = mse_of(&inst, 1, &mut |i| {
            product_step(&mut prod, i);
            (
                core::array::from_fn(|m| v_na(prod.local_estimate(m).unwrap().state())),
                v_na(prod.estimate().state()),
            )
        });
        let mut lit = LitFtkff::new(rd);
        let s = mse_of(&inst, 1, &mut |i| {
            lit.step(i);
            (lit.x_loc, lit.xg)
        });
        for m in 0..L {
            mse_p.local[m] += r.local[m] / runs as f64;
            mse_l.local[m] += s.local[m] / runs as f64;
        }
        mse_p.fused += r.fused / runs as f64;
        mse_l.fused += s.fused / runs as f64;
    }
    eprintln!(
        "largest relative discrepancy over {runs} runs × {horizon}: {worst:.3e}\n\
         avg MSE product {:?} fused {:.5}; transcription {:?} fused {:.5}",
        mse_p.local, mse_p.fused, mse_l.local, mse_l.fused
    );
    assert!(
        first_divergence.is_none(),
        "first divergence beyond {tol:e}: {first_divergence:?}"
    );
    for m in 0..L {
        assert!(rel(mse_p.local[m], mse_l.local[m]) < tol);
    }
    assert!(rel(mse_p.fused, mse_l.fused) < tol);
}

/// The design's reading against each alternative, on the same runs: mean over runs of the
/// per-run average MSE and the paired difference (alternative − design) with its standard
/// error. Prints a table; `cargo test -p estimator-core --release --test tobit_literal --
/// --ignored --nocapture alternative` (environment: TOBIT_AUDIT_RUNS, default 1000;
/// TOBIT_AUDIT_SEED, default 2026; TOBIT_AUDIT_FROM, the first instant averaged, default 1).
#[test]
#[ignore = "prints the audit table of docs/tobit-fusion.md (a minute in release)"]
fn alternative_readings_of_the_example() {
    let runs: u64 = std::env::var("TOBIT_AUDIT_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let horizon = 200;
    let d = Reading::default();
    let variants: Vec<(&str, Reading)> = vec![
        ("design (R1-R9)", d),
        (
            "(29) with Q, not α⁻¹Q",
            Reading {
                q_unscaled: true,
                ..d
            },
        ),
        (
            "P̄_{m,0|0} = P₀, not α⁻¹P₀",
            Reading {
                p0_unscaled: true,
                ..d
            },
        ),
        (
            "Ω₁ with the fused prediction α P̄_{m,t|t−1}",
            Reading {
                omega1_fused_prior: true,
                ..d
            },
        ),
        (
            "Ω₁ with (26) on the bound, A P̄ Aᵀ + B Q Bᵀ",
            Reading {
                omega1_eq26: true,
                ..d
            },
        ),
        (
            "Ω₁ fused prediction and Ξ one step ahead",
            Reading {
                omega1_fused_prior: true,
                xi_lead: true,
                ..d
            },
        ),
        (
            "θ = 1: ȳ = y_{m,t−1} (Alg. 1 line 12)",
            Reading {
                hold: Hold::PreviousMeasurement,
                ..d
            },
        ),
        (
            "θ = 1: predict only",
            Reading {
                hold: Hold::PredictOnly,
                ..d
            },
        ),
        (
            "(51) resets x̂ only",
            Reading {
                reset: Reset::StateOnly,
                ..d
            },
        ),
        (
            "(51) resets P̄ only",
            Reading {
                reset: Reset::BoundOnly,
                ..d
            },
        ),
        (
            "(51) P̄_m ← P^g (no α⁻¹)",
            Reading {
                reset: Reset::BoundUnscaled,
                ..d
            },
        ),
        ("Ξ one step ahead", Reading { xi_lead: true, ..d }),
        (
            "κ₂ term diagonal only",
            Reading {
                kappa2_diagonal: true,
                ..d
            },
        ),
        (
            "ϱ̄ = 1 − Φ(·) (\"censoring probability\")",
            Reading {
                rho_complement: true,
                ..d
            },
        ),
    ];
    let seed: u64 = std::env::var("TOBIT_AUDIT_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2026);
    let sims: Vec<Vec<Instant>> = (0..runs).map(|r| simulate(seed, r, horizon)).collect();
    let from: usize = std::env::var("TOBIT_AUDIT_FROM")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let per_run = |rd: Reading| -> Vec<RunMse> {
        sims.iter()
            .map(|inst| {
                let mut lit = LitFtkff::new(rd);
                mse_of(inst, from, &mut |i| {
                    lit.step(i);
                    (lit.x_loc, lit.xg)
                })
            })
            .collect()
    };
    let base = per_run(d);
    let mean_se = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, (var / n).sqrt())
    };
    println!(
        "{runs} runs × T = {horizon}, seed {seed}; avg MSE over k = {from}..{horizon}, and \
         (alternative − design) ± paired s.e."
    );
    println!("| reading | tobit-1 | tobit-2 | tobit-3 | fused | first differs (run 0) |");
    println!("|---|---|---|---|---|---|");
    for (name, rd) in &variants {
        let alt = per_run(*rd);
        let mut cells = Vec::new();
        for m in 0..=L {
            let get = |r: &RunMse| if m < L { r.local[m] } else { r.fused };
            let a: Vec<f64> = alt.iter().map(get).collect();
            let diff: Vec<f64> = alt
                .iter()
                .zip(&base)
                .map(|(a, b)| get(a) - get(b))
                .collect();
            let (ma, _) = mean_se(&a);
            let (md, sd) = mean_se(&diff);
            let mb = mean_se(&base.iter().map(get).collect::<Vec<_>>()).0;
            if *rd == d {
                cells.push(format!("{ma:.4}"));
            } else if !ma.is_finite() {
                cells.push("diverges (NaN)".into());
            } else {
                cells.push(format!(
                    "{ma:.4} ({:+.1} % ± {:.1})",
                    100.0 * md / mb,
                    100.0 * sd / mb
                ));
            }
        }
        // The first instant of run 0 where the estimates leave the design's by > 1e-9.
        let (mut a, mut b) = (LitFtkff::new(d), LitFtkff::new(*rd));
        let mut first = String::from("never");
        for (k, i) in (1..).zip(&sims[0]) {
            a.step(i);
            b.step(i);
            let dx = (0..L)
                .map(|m| vamax(&vsub(&a.x_loc[m], &b.x_loc[m])))
                .fold(vamax(&vsub(&a.xg, &b.xg)), f64::max);
            if dx.is_nan() || dx > 1e-9 * vamax(&a.xg).max(1.0) {
                first = format!("k = {k} (Δx̂ {dx:.1e})");
                break;
            }
        }
        println!("| {name} | {} | {first} |", cells.join(" | "));
    }
}

/// What the audit table says, pinned on 200 runs (seed 2026): of the alternatives, only Ω₁
/// with the fused prediction and Ξ one step ahead lower *every* MSE (the three local ones and
/// the fused one) by a few percent; the others move it by < 0.5 % or in the other direction
/// for some view. Bands are ≥ 5 paired standard errors wide.
#[test]
fn only_two_alternative_readings_lower_every_mse_by_a_few_percent() {
    let d = Reading::default();
    let sims: Vec<Vec<Instant>> = (0..200).map(|r| simulate(2026, r, 200)).collect();
    let avg = |rd: Reading| -> [f64; L + 1] {
        let mut out = [0.0; L + 1];
        for inst in &sims {
            let mut lit = LitFtkff::new(rd);
            let r = mse_of(inst, 1, &mut |i| {
                lit.step(i);
                (lit.x_loc, lit.xg)
            });
            for m in 0..L {
                out[m] += r.local[m] / sims.len() as f64;
            }
            out[L] += r.fused / sims.len() as f64;
        }
        out
    };
    let base = avg(d);
    let change = |rd: Reading| -> [f64; L + 1] {
        let a = avg(rd);
        core::array::from_fn(|i| a[i] / base[i] - 1.0)
    };
    let few_percent_lower =
        |c: &[f64; L + 1], lo: f64, hi: f64| c.iter().all(|&v| -hi < v && v < -lo);
    let omega1 = change(Reading {
        omega1_fused_prior: true,
        ..d
    });
    assert!(
        few_percent_lower(&omega1, 0.025, 0.06),
        "Ω₁ fused prediction: {omega1:?}"
    );
    let xi = change(Reading { xi_lead: true, ..d });
    assert!(
        few_percent_lower(&xi, 0.01, 0.035),
        "Ξ one step ahead: {xi:?}"
    );
    for (name, rd) in [
        (
            "(29) with Q",
            Reading {
                q_unscaled: true,
                ..d
            },
        ),
        (
            "ȳ = y_{t−1}",
            Reading {
                hold: Hold::PreviousMeasurement,
                ..d
            },
        ),
        (
            "κ₂ diagonal",
            Reading {
                kappa2_diagonal: true,
                ..d
            },
        ),
        (
            "Ω₁ by (26)",
            Reading {
                omega1_eq26: true,
                ..d
            },
        ),
    ] {
        let c = change(rd);
        assert!(c.iter().all(|v| v.abs() < 0.005), "{name}: {c:?}");
    }
    for (name, rd) in [
        (
            "P̄₀ = P₀",
            Reading {
                p0_unscaled: true,
                ..d
            },
        ),
        (
            "reset x̂ only",
            Reading {
                reset: Reset::StateOnly,
                ..d
            },
        ),
        (
            "reset P̄ only",
            Reading {
                reset: Reset::BoundOnly,
                ..d
            },
        ),
        (
            "P̄_m ← P^g",
            Reading {
                reset: Reset::BoundUnscaled,
                ..d
            },
        ),
    ] {
        let c = change(rd);
        assert!(c.iter().any(|&v| v > 0.01), "{name}: {c:?}");
    }
}
