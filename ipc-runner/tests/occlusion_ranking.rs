//! Seed 001's ranking claims on the `occlusion` preset, checked with paired Monte-Carlo
//! differences (issue 4). See docs/occlusion.md for the full 5000-run numbers.
//!
//! Every estimator runs on the same simulated runs (common random numbers), so the
//! difference of two estimators' run-average squared errors has a much smaller spread than
//! either alone. A claim "a below b" is asserted as: mean of (avg_b − avg_a) over runs
//! exceeds 3 standard errors of that mean (a one-sided z-test at ≈ 0.1 %). 1500 runs,
//! seed 11, T = 100: chosen for run time, not tuned (the same claims hold at 5000 runs with
//! seed 0, docs/occlusion.md). Claims that do not hold in the project's own eval are not
//! asserted here.

use channel_sim::scenario::preset;
use ipc_runner::estimators::FACTORIES;
use ipc_runner::eval::EvalOptions;
use ipc_runner::source::build_for_scenario;

const RUNS: u64 = 1500;
const HORIZON: u32 = 100;
const SEED: u64 = 11;

/// Per estimator name, every run's mean over k = 1..=T of ‖x_k − x̂_k‖².
fn run_averages() -> Vec<(&'static str, Vec<f64>)> {
    let scenario = preset("occlusion").expect("preset");
    let options = EvalOptions {
        runs: RUNS,
        horizon: HORIZON,
        seed: SEED,
        particles: 0,
        ..EvalOptions::default()
    };
    let nx = scenario.nx();
    let mut out: Vec<(&'static str, Vec<f64>)> = Vec::new();
    for run in 0..RUNS {
        let mut sim = scenario.start(SEED, run);
        let mut ests =
            build_for_scenario(FACTORIES, &*scenario, &options, SEED, run).expect("build");
        if out.is_empty() {
            out = ests.iter().map(|e| (e.name(), Vec::new())).collect();
        }
        let mut sums = vec![0.0; ests.len()];
        let mut xhat = [0.0; 8];
        for k in 1..=HORIZON {
            let inst = sim.next_instant();
            for (e, s) in ests.iter_mut().zip(&mut sums) {
                let obs = if e.full_information() {
                    sim.raw_observations().expect("raw")
                } else {
                    &inst.obs[..]
                };
                e.step(k, obs).expect("no estimator fails on the preset");
                e.estimate(&mut xhat);
                *s += (0..nx)
                    .map(|i| (inst.truth[i] - xhat[i]).powi(2))
                    .sum::<f64>();
            }
        }
        for ((_, v), s) in out.iter_mut().zip(&sums) {
            v.push(s / HORIZON as f64);
        }
    }
    out
}

/// `(mean, standard error)` of `b − a` over runs.
fn paired(all: &[(&'static str, Vec<f64>)], a: &str, b: &str) -> (f64, f64) {
    let get = |n: &str| &all.iter().find(|(m, _)| *m == n).expect(n).1;
    let d: Vec<f64> = get(b).iter().zip(get(a)).map(|(x, y)| x - y).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn occlusion_ranking_claims() {
    let all = run_averages();
    let names: Vec<&str> = all.iter().map(|(n, _)| *n).collect();
    for n in ["ikf", "cce", "kf-io", "adf"] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
    // Paper (Fig. 7): CCE below IKF below KF-IO. Product: adf at or below cce.
    for (a, b) in [("cce", "ikf"), ("ikf", "kf-io"), ("adf", "cce")] {
        let (mean, se) = paired(&all, a, b);
        println!("{b} − {a}: {mean:.4} ± {se:.4}");
        assert!(
            mean > 3.0 * se,
            "{a} is not below {b}: {b} − {a} = {mean} ± {se}"
        );
    }
}
