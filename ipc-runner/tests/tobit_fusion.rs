//! The seed 004 example (`tobit-fusion`, T = 200) over 400 runs with a fixed seed: what holds,
//! with tolerances from the Monte-Carlo standard errors (3 s.e. unless stated).
//!
//! Findings asserted (docs/tobit-fusion.md has the 2000-run numbers):
//! * no view diverges;
//! * Theorem 5 holds in the mean: E{eᵀ(P^g)⁻¹e} ≤ n_x = 2 at every k (mean + 3 s.e. < 2),
//!   and MSE(k) < tr P^g(k);
//! * the fused bound is tighter than every local bound (tr P^g < tr P̄_m, every k);
//! * fused beats node 1's local estimate (paired difference, 3 s.e.);
//! * fused is *not* significantly better than nodes 2 and 3 (the paper's "the fused MSE is
//!   smaller than the local ones" is not reproduced): fused − tobit-m > −3 s.e. (paired);
//! * the protocol's accounting: sent ≤ triggered, blocked = triggered − sent, and the bucket
//!   never lets more than ξ₀ + g T tokens be spent (3 · sends ≤ 10 + 5 · 200 per run);
//! * the product's `Silence::Predict` views (`*-predict`, prediction only at θ = 1) beat the
//!   paper's same view, every one, by more than 10 paired s.e. (docs/tobit-fusion.md measures
//!   −30 to −45 %, about 50 s.e. at 400 runs), and their bound still holds in the mean
//!   (the same NEES and MSE < tr P checks as the paper's fused view); and with them the
//!   paper's claim holds: `fused-predict` beats every `tobit-m-predict` (paired, 3 s.e.).
//!
//! And the centralised filters of docs/tobit-fusion.md "At the information bound" (issue 46),
//! whose assertions are listed on their tests below.

use std::path::Path;

use channel_sim::scenario::{preset, resolve};
use channel_sim::Scenario;
use ipc_runner::estimators::{tobit, tobit_central};
use ipc_runner::eval::run_one;
use ipc_runner::eval::EvalOptions;

/// Runs (override with `TOBIT_RUNS=2000` for the documented numbers).
fn runs() -> u64 {
    std::env::var("TOBIT_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(400)
}
const T: u32 = 200;
const SEED: u64 = 4004;

fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

#[test]
fn paper_example_what_holds() {
    let runs = runs();
    let scenario = preset("tobit-fusion").unwrap();
    let factories: &[ipc_runner::estimators::Factory] = &[tobit::build];
    // The paper's views, then the same with `Silence::Predict` (the order `tobit::build` has;
    // `run_one` checks it). The silence-reading views are tests/tobit_silence.rs'.
    let (l, p) = (&tobit::LOCAL_NAMES, &tobit::LOCAL_PREDICT_NAMES);
    let names = [
        l[0],
        l[1],
        l[2],
        tobit::FUSED_NAME,
        p[0],
        p[1],
        p[2],
        tobit::FUSED_PREDICT_NAME,
    ];
    let options = EvalOptions {
        runs,
        horizon: T,
        seed: SEED,
        estimators: names.iter().map(|n| n.to_string()).collect(),
        ..EvalOptions::default()
    };
    let t = T as usize;
    let mut run_avg = vec![Vec::new(); 8];
    let mut nees = vec![Vec::new(); t + 1];
    let mut nees_predict = vec![Vec::new(); t + 1];
    let mut mse_fused = vec![0.0; t + 1];
    let mut tr_fused = vec![0.0; t + 1];
    let mut mse_predict = vec![0.0; t + 1];
    let mut tr_predict = vec![0.0; t + 1];
    let mut tr_local = vec![[0.0; 3]; t + 1];
    for run in 0..runs {
        let out = run_one(&*scenario, &options, factories, run, &names).unwrap();
        for (j, e) in out.estimators.iter().enumerate() {
            let sq = e
                .sq_err
                .as_ref()
                .unwrap_or_else(|| panic!("{} diverged in run {run}: {:?}", names[j], e.error));
            run_avg[j].push(sq[2..].iter().sum::<f64>() / T as f64);
            let diag = |n: &str| &e.diagnostics.iter().find(|(d, _)| *d == n).unwrap().1;
            for k in 1..=t {
                let mse = (sq[2 * k] + sq[2 * k + 1]) / runs as f64;
                let tr = diag("trace_p")[k] / runs as f64;
                match j {
                    3 => {
                        nees[k].push(diag("nees")[k]);
                        mse_fused[k] += mse;
                        tr_fused[k] += tr;
                    }
                    7 => {
                        nees_predict[k].push(diag("nees")[k]);
                        mse_predict[k] += mse;
                        tr_predict[k] += tr;
                    }
                    0..3 => tr_local[k][j] += tr,
                    _ => {}
                }
            }
        }
        let mut spent = 0;
        for c in &out.channel {
            assert!(c.sent <= c.triggered);
            assert_eq!(c.blocked, c.triggered - c.sent, "node {}", c.node);
            spent += 3 * c.sent;
        }
        assert!(
            spent <= 10 + 5 * T as u64,
            "run {run}: {spent} tokens spent"
        );
    }

    // The λχ ≤ 1 violation in numbers: the share of instants with η < 0 per node (first 200
    // runs, replayed by plot::tokens). The paper's claim η ≥ 0 needs λχ > 1; here it fails.
    let mut neg = [0usize; 3];
    let replayed = runs.min(200);
    for run in 0..replayed {
        let tr = ipc_runner::plot::tokens::trace(&*scenario, SEED, run, T)
            .unwrap()
            .unwrap();
        for m in 0..3 {
            neg[m] += tr.eta[m].iter().filter(|&&e| e < 0.0).count();
        }
    }
    let share = neg.map(|n| n as f64 / (replayed as f64 * T as f64));
    println!("share of instants with eta < 0 per node: {share:.3?}");
    assert!(share.iter().all(|&s| s > 0.05), "{share:?}");

    for k in 1..=t {
        let (m, se) = mean_se(&nees[k]);
        assert!(m + 3.0 * se < 2.0, "k = {k}: mean NEES {m} ± {se}");
        assert!(mse_fused[k] < tr_fused[k], "k = {k}");
        let (m, se) = mean_se(&nees_predict[k]);
        assert!(
            m + 3.0 * se < 2.0,
            "k = {k}: fused-predict mean NEES {m} ± {se}"
        );
        assert!(mse_predict[k] < tr_predict[k], "k = {k}: fused-predict");
        for j in 0..3 {
            assert!(tr_fused[k] < tr_local[k][j], "k = {k}, node {}", j + 1);
        }
    }

    let paired_with = |a: usize, b: usize| {
        let d: Vec<f64> = run_avg[a]
            .iter()
            .zip(&run_avg[b])
            .map(|(f, l)| f - l)
            .collect();
        mean_se(&d)
    };
    let paired = |j: usize| paired_with(3, j);
    for j in 0..8 {
        let (m, s) = mean_se(&run_avg[j]);
        println!(
            "{}: avg MSE {m:.5} ± {s:.5} ({runs} runs, seed {SEED})",
            names[j]
        );
    }
    let (d1, s1) = paired(0);
    println!("fused − tobit-1 = {d1:.5} ± {s1:.5} (paired)");
    assert!(d1 + 3.0 * s1 < 0.0, "fused − tobit-1 = {d1} ± {s1}");
    for j in [1, 2] {
        let (d, s) = paired(j);
        println!("fused − tobit-{} = {d:.5} ± {s:.5} (paired)", j + 1);
        assert!(d + 3.0 * s > 0.0, "fused − tobit-{} = {d} ± {s}", j + 1);
    }
    // The product's option against the paper's, view by view (paired over runs).
    for j in 0..4 {
        let (d, s) = paired_with(j + 4, j);
        let rel = d / mean_se(&run_avg[j]).0;
        println!(
            "{} − {} = {d:.5} ± {s:.5} (paired, {:+.1} %)",
            names[j + 4],
            names[j],
            100.0 * rel
        );
        assert!(
            d + 10.0 * s < 0.0,
            "{} − {} = {d} ± {s}",
            names[j + 4],
            names[j]
        );
    }
    for j in 4..7 {
        let (d, s) = paired_with(7, j);
        println!("fused-predict − {} = {d:.5} ± {s:.5} (paired)", names[j]);
        // Here the paper's claim holds: the fused estimate beats every local one.
        assert!(
            d + 3.0 * s < 0.0,
            "fused-predict − {} = {d} ± {s}",
            names[j]
        );
    }
}

/// Per-run average MSE, NEES and fraction inside the 95 % ellipse of each of `names`, built
/// by `tobit::build` (`fused-predict`) and `tobit_central::build` (the centralised filters).
struct Central {
    run_avg: Vec<Vec<f64>>,
    nees: Vec<Vec<f64>>,
    inside: Vec<Vec<f64>>,
}

const CENTRAL: [&str; 4] = [
    tobit::FUSED_PREDICT_NAME,
    tobit_central::TOBIT_KF_NAME,
    tobit_central::CMM_NAME,
    tobit_central::CMM_SILENCE_NAME,
];

fn central(scenario: &dyn Scenario, runs: u64, transport_loss: f64) -> Central {
    let options = EvalOptions {
        runs,
        horizon: T,
        seed: SEED,
        transport_loss,
        estimators: CENTRAL.iter().map(|n| n.to_string()).collect(),
        ..EvalOptions::default()
    };
    let factories: &[ipc_runner::estimators::Factory] = &[tobit::build, tobit_central::build];
    let n = CENTRAL.len();
    let mut c = Central {
        run_avg: vec![Vec::new(); n],
        nees: vec![Vec::new(); n],
        inside: vec![Vec::new(); n],
    };
    for run in 0..runs {
        let out = run_one(scenario, &options, factories, run, &CENTRAL).unwrap();
        for (j, e) in out.estimators.iter().enumerate() {
            let sq = e
                .sq_err
                .as_ref()
                .unwrap_or_else(|| panic!("{} diverged in run {run}: {:?}", CENTRAL[j], e.error));
            c.run_avg[j].push(sq[2..].iter().sum::<f64>() / f64::from(T));
            let diag = |d: &str| &e.diagnostics.iter().find(|(n, _)| *n == d).unwrap().1;
            let per_run = |d: &str| diag(d)[1..].iter().sum::<f64>() / f64::from(T);
            c.nees[j].push(per_run("nees"));
            c.inside[j].push(per_run("inside_95"));
        }
    }
    for (j, name) in CENTRAL.iter().enumerate() {
        let (m, s) = mean_se(&c.run_avg[j]);
        let (a, sa) = mean_se(&c.nees[j]);
        let (i, si) = mean_se(&c.inside[j]);
        println!(
            "{name}: avg MSE {m:.5} ± {s:.5}, ANEES {a:.3} ± {sa:.3}, inside 95 % {i:.4} ± {si:.4}"
        );
    }
    c
}

impl Central {
    fn paired(&self, a: usize, b: usize) -> (f64, f64) {
        let d: Vec<f64> = self.run_avg[a]
            .iter()
            .zip(&self.run_avg[b])
            .map(|(x, y)| x - y)
            .collect();
        mean_se(&d)
    }
}

/// Issue 46 on the paper's example (400 runs, seed 4004; 3 s.e. unless stated):
/// * the moment-matched filter reading the silences reaches the information bound's region:
///   avg MSE ≤ 0.080 (the figure for 2000 runs) within 3 s.e.;
/// * reading the silence is worth something: `tobit-cmm-held` < `tobit-cmm` (paired);
/// * exact moment matching beats the practitioner's Tobit KF: `tobit-cmm` < `tobit-kf`;
/// * the Tobit KF beats the product's best federated view by more than 10 paired s.e.;
/// * `tobit-cmm-held` is consistent: ANEES in [1.8, 2.2] and the fraction of run-instants
///   inside its 95 % ellipse not below 94 %, each within 3 s.e. of the per-run values.
#[test]
fn centralised_filters_at_the_information_bound() {
    let c = central(&*preset("tobit-fusion").unwrap(), runs(), 0.0);
    let (m, s) = mean_se(&c.run_avg[3]);
    assert!(m - 3.0 * s <= 0.080, "tobit-cmm-held: {m} ± {s}");
    for (a, b) in [(3, 2), (2, 1)] {
        let (d, s) = c.paired(a, b);
        println!("{} − {} = {d:.5} ± {s:.5} (paired)", CENTRAL[a], CENTRAL[b]);
        assert!(
            d + 3.0 * s < 0.0,
            "{} − {} = {d} ± {s}",
            CENTRAL[a],
            CENTRAL[b]
        );
    }
    let (d, s) = c.paired(1, 0);
    assert!(d + 10.0 * s < 0.0, "tobit-kf − fused-predict = {d} ± {s}");
    let (a, sa) = mean_se(&c.nees[3]);
    assert!(
        a + 3.0 * sa >= 1.8 && a - 3.0 * sa <= 2.2,
        "ANEES {a} ± {sa}"
    );
    let (i, si) = mean_se(&c.inside[3]);
    assert!(i + 3.0 * si >= 0.94, "inside 95 %: {i} ± {si}");
}

/// Issue 46 off the example: on the starved bucket and with 5 % of the slots lost in
/// transport, `tobit-cmm-held` stays consistent (ANEES in [1.8, 2.2] within 3 s.e.) and
/// is no worse than the same filter predicting on every silence (`tobit-cmm`; paired,
/// 3 s.e.). 200 runs each.
#[test]
fn the_silence_reading_filter_off_the_example() {
    let starved = resolve(
        "",
        Some(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../channel-sim/scenarios/tobit-fusion-starved.toml"),
        ),
    )
    .unwrap();
    let runs = runs().min(200);
    for (what, scenario, loss) in [
        ("starved bucket", starved, 0.0),
        ("5 % transport loss", preset("tobit-fusion").unwrap(), 0.05),
    ] {
        println!("{what}:");
        let c = central(&*scenario, runs, loss);
        let (d, s) = c.paired(3, 2);
        println!("tobit-cmm-held − tobit-cmm = {d:.5} ± {s:.5} (paired)");
        assert!(d - 3.0 * s <= 0.0, "{what}: {d} ± {s}");
        let (a, sa) = mean_se(&c.nees[3]);
        assert!(
            a + 3.0 * sa >= 1.8 && a - 3.0 * sa <= 2.2,
            "{what}: ANEES {a} ± {sa}"
        );
    }
}
