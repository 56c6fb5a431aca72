//! A loss is not a dropout (issue 19, docs/occlusion.md "Losses"): 20 % of the `occlusion`
//! preset's slots lost at random in a transport stage after the channel
//! (`EvalOptions::transport_loss`, its own random stream: the plant, the channel and the slots
//! lost are the same in both settings below).
//!
//! * **Marked** (`FLAG_IPC_LOST`: the estimators receive `Packet::Lost` and predict only):
//!   `cce` and `adf` below `ikf`, and below themselves reading the same losses as occlusion
//!   dropouts (the **unmarked** setting: the lost slots reach them as plain dropouts).
//! * **Unmarked** with the known loss rate (`loss_rate = 0.2`, the `-mix` estimators): printed,
//!   with `cce`, `adf` (reading the losses as occlusion) and `ikf`; `cce-mix` and `adf-mix`
//!   are also asserted below `cce` and `adf` of the same setting.
//!
//! Each claim "a below b" is asserted on the paired per-run differences of the run-average
//! squared errors (common random numbers): mean of (avg_b − avg_a) > 3 standard errors of
//! that mean, a one-sided z-test at ≈ 0.1 % (the run averages are independent across runs, and
//! with 3000 runs the mean of their differences is close to normal even with `ikf`'s heavy
//! right tail). 3000 runs, seed 19, T = 100: the `ikf − cce` gap is the tightest claim (its
//! spread comes from `ikf`'s runs that predict open-loop through an unstable A); at 3000 runs
//! it clears 3 s.e. with a margin (docs/occlusion.md gives the numbers, and the same claims at
//! 200 000 runs with seed 0). The count was chosen before the margin was known to be comfortable,
//! not tuned to a passing seed.

use channel_sim::scenario::preset;
use ipc_runner::estimators::FACTORIES;
use ipc_runner::eval::run_one;
use ipc_runner::eval::EvalOptions;
use ipc_runner::source::build_for_scenario;
use rayon::prelude::*;

const RUNS: u64 = 3000;
const HORIZON: u32 = 100;
const SEED: u64 = 19;
const LOSS: f64 = 0.2;

/// Per estimator name, every run's mean over k = 1..=T of ‖x_k − x̂_k‖².
type Averages = Vec<(&'static str, Vec<f64>)>;

fn run_averages(unmarked: bool, runs: u64, seed: u64) -> Averages {
    let scenario = preset("occlusion").expect("preset");
    let options = EvalOptions {
        runs,
        horizon: HORIZON,
        seed,
        particles: 0,
        loss_rate: LOSS,
        transport_loss: LOSS,
        transport_loss_unmarked: unmarked,
        ..EvalOptions::default()
    };
    let nx = scenario.nx();
    let names: Vec<&'static str> = build_for_scenario(FACTORIES, &*scenario, &options, seed, 0)
        .expect("build")
        .iter()
        .map(|e| e.name())
        .collect();
    let per_run: Vec<Vec<f64>> = (0..runs)
        .into_par_iter()
        .map(|run| {
            let out = run_one(&*scenario, &options, FACTORIES, run, &names).expect("run");
            out.estimators
                .iter()
                .zip(&names)
                .map(|(e, n)| {
                    let sq = e
                        .sq_err
                        .as_ref()
                        .unwrap_or_else(|| panic!("{n} diverged in run {run}: {:?}", e.error));
                    sq[nx..].iter().sum::<f64>() / f64::from(HORIZON)
                })
                .collect()
        })
        .collect();
    names
        .iter()
        .enumerate()
        .map(|(i, n)| (*n, per_run.iter().map(|r| r[i]).collect()))
        .collect()
}

fn get<'a>(all: &'a Averages, name: &str) -> &'a [f64] {
    &all.iter().find(|(n, _)| *n == name).expect(name).1
}

/// `(mean, standard error)` of `b − a` over runs.
fn paired(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d: Vec<f64> = b.iter().zip(a).map(|(x, y)| x - y).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

fn mean_se(v: &[f64]) -> (f64, f64) {
    paired(&vec![0.0; v.len()], v)
}

fn below(what: &str, a: &[f64], b: &[f64]) {
    let (mean, se) = paired(a, b);
    println!("{what}: {mean:.4} ± {se:.4} ({:.1} s.e.)", mean / se);
    assert!(mean > 3.0 * se, "{what}: {mean} ± {se}");
}

#[test]
fn losses_handled_as_losses_beat_ikf_and_losses_read_as_occlusion() {
    let runs = std::env::var("LOSSES_RUNS").map_or(RUNS, |v| v.parse().unwrap());
    let seed = std::env::var("LOSSES_SEED").map_or(SEED, |v| v.parse().unwrap());
    let marked = run_averages(false, runs, seed);
    let unmarked = run_averages(true, runs, seed);
    println!("{runs} runs, seed {seed}, T = {HORIZON}, transport loss {LOSS}");
    for (setting, all) in [("marked", &marked), ("unmarked", &unmarked)] {
        for (n, v) in all.iter() {
            let (m, se) = mean_se(v);
            println!("{setting:>8} {n:<10} {m:>10.4} ± {se:.4}");
        }
    }
    // ikf predicts on a dropout and on a loss alike: the same numbers in both settings.
    assert_eq!(get(&marked, "ikf"), get(&unmarked, "ikf"));
    for est in ["cce", "adf"] {
        below(
            &format!("ikf − {est} (losses marked)"),
            get(&marked, est),
            get(&marked, "ikf"),
        );
        below(
            &format!("{est} reading losses as occlusion − {est} (losses marked)"),
            get(&marked, est),
            get(&unmarked, est),
        );
        let mix = format!("{est}-mix");
        below(
            &format!("{est} − {mix} (losses unmarked)"),
            get(&unmarked, &mix),
            get(&unmarked, est),
        );
    }
    // Reported, not asserted: the mixture against ikf, and what the mark is worth.
    for est in ["cce", "adf", "kf-io"] {
        let mix = format!("{est}-mix");
        let (m, se) = paired(get(&unmarked, &mix), get(&unmarked, "ikf"));
        println!("ikf − {mix} (losses unmarked): {m:.4} ± {se:.4}");
        let (m, se) = paired(get(&marked, est), get(&unmarked, &mix));
        println!("{mix} (unmarked) − {est} (marked): {m:.4} ± {se:.4}");
    }
}
