//! A known control input, `x_{k+1} = A x_k + B_u u_k + B w_k` (`channel-sim/scenarios/
//! controlled.toml`: a cart pushed by u_k = 5 sin(2π k / 40)): the Kalman filter that adds
//! B_u u_k in its prediction tracks the truth as its own covariance says, one that ignores the
//! input does not, and every estimator family's prediction adds the same B_u u_k.

use std::path::Path;

use channel_sim::scenario::ComposedScenario;
use channel_sim::sim::FLAG_OCCLUDED;
use channel_sim::{Observation, Scenario};
use estpipe_wire::FLAG_IPC_LOST;
use ipc_runner::estimators::FACTORIES;
use ipc_runner::eval::EvalOptions;
use ipc_runner::source::build_for_scenario;

fn scenarios() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios")
}

/// The file's text and the same text without its `[control]` table.
fn with_and_without(file: &str) -> (ComposedScenario, ComposedScenario) {
    let text = std::fs::read_to_string(scenarios().join(file)).unwrap();
    let start = text.find("[control]").expect("a [control] table");
    let end = start + text[start..].find("\n[initial]").unwrap();
    let bare = format!("{}{}", &text[..start], &text[end + 1..]);
    let parse = |t: &str| channel_sim::scenario::config::parse(t, file, "x").unwrap();
    (parse(&text), parse(&bare))
}

fn options(names: &[&str]) -> EvalOptions {
    EvalOptions {
        estimators: names.iter().map(|s| s.to_string()).collect(),
        particles: 20_000,
        ..EvalOptions::default()
    }
}

/// 400 runs of 100 instants, seed 9. `ikf` with the input: its MSE averaged over k is its
/// average tr P within 10 % (the sampling error of the MSE over 400 runs is a few percent),
/// and equal to the MSE of the same filter on the same plant without the input to 1e-9
/// relative — a linear filter that knows u has input-independent errors, so this is an
/// independent check of the whole chain (plant, TOML, the core's time update). `ikf` built
/// on the model without the input, fed the same slots, is off by more than 20× its own P.
#[test]
fn the_kalman_filter_with_the_input_tracks_and_without_it_does_not() {
    let (with, without) = with_and_without("controlled.toml");
    let (runs, horizon, seed) = (400u64, 100u32, 9u64);
    let (mut mse_u, mut mse_0, mut mse_bare, mut tr_u, mut tr_0) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut max_input = 0.0_f64;
    for run in 0..runs {
        let mut knows =
            build_for_scenario(FACTORIES, &with, &options(&["ikf"]), seed, run).unwrap();
        let mut ignores =
            build_for_scenario(FACTORIES, &without, &options(&["ikf"]), seed, run).unwrap();
        let mut bare_est =
            build_for_scenario(FACTORIES, &without, &options(&["ikf"]), seed, run).unwrap();
        let (mut sim, mut bare) = (with.start(seed, run), without.start(seed, run));
        for k in 1..=horizon {
            let (inst, binst) = (sim.next_instant(), bare.next_instant());
            // The same noise: the two truths differ by the input's response only.
            max_input = max_input.max((inst.truth[0] - binst.truth[0]).abs());
            let err = |e: &dyn ipc_runner::Estimator, truth: &[f64]| {
                let mut x = [0.0; 2];
                e.estimate(&mut x);
                (x[0] - truth[0]).powi(2) + (x[1] - truth[1]).powi(2)
            };
            let tr = |e: &dyn ipc_runner::Estimator| {
                let mut p = [0.0; 4];
                e.covariance(&mut p);
                p[0] + p[3]
            };
            knows[0].step(k, &inst.obs).unwrap();
            ignores[0].step(k, &inst.obs).unwrap();
            bare_est[0].step(k, &binst.obs).unwrap();
            mse_u += err(&*knows[0], &inst.truth);
            mse_0 += err(&*ignores[0], &inst.truth);
            mse_bare += err(&*bare_est[0], &binst.truth);
            tr_u += tr(&*knows[0]);
            tr_0 += tr(&*ignores[0]);
        }
    }
    let n = (runs * u64::from(horizon)) as f64;
    let (mse_u, mse_0, mse_bare, tr_u, tr_0) =
        (mse_u / n, mse_0 / n, mse_bare / n, tr_u / n, tr_0 / n);
    eprintln!(
        "with u: MSE {mse_u:.5}, tr P {tr_u:.5}; ignoring u: MSE {mse_0:.4}, tr P {tr_0:.5}; \
         no input at all: MSE {mse_bare:.5}; the input moves the position by up to {max_input:.2}"
    );
    assert!(
        max_input > 1.0,
        "precondition: a strong input ({max_input})"
    );
    assert!(
        (mse_u / tr_u - 1.0).abs() < 0.1,
        "MSE {mse_u} vs tr P {tr_u}"
    );
    assert!(
        (mse_u - mse_bare).abs() < 1e-9 * mse_bare,
        "{mse_u} vs {mse_bare}"
    );
    assert!(
        mse_0 > 20.0 * tr_0,
        "ignoring u: MSE {mse_0} vs its tr P {tr_0}"
    );
}

/// Every estimator of `options` stepped once with `obs` from the same prior, on the model
/// of `file` with its constant input and without it: `(name, x̂)` of each, both ways.
#[allow(clippy::type_complexity)]
fn one_step(
    file: &str,
    options: &EvalOptions,
    obs: &[Observation],
) -> (Vec<(&'static str, [f64; 2])>, Vec<(&'static str, [f64; 2])>) {
    let (with, without) = with_and_without(file);
    let step = |s: &ComposedScenario| {
        let mut ests = build_for_scenario(FACTORIES, s, options, 1, 0).unwrap();
        ests.iter_mut()
            .map(|e| {
                e.step(1, obs).unwrap();
                let mut x = [0.0; 2];
                e.estimate(&mut x);
                (e.name(), x)
            })
            .collect::<Vec<_>>()
    };
    (step(&with), step(&without))
}

/// B_u u_0 of occlusion-user-controlled.toml: control.b = [[0.0], [0.1]], u = 2.
const BU: [f64; 2] = [0.0, 0.2];

/// Every family's time update adds B_u u_k: after one prediction-only instant (a slot lost
/// in transport) from the same prior, each estimator's x̂ on the model with a constant input
/// exceeds its x̂ on the model without it by exactly B_u u_0 (the linear filters, to rounding;
/// `pf`, whose particles carry the same draws, to 1e-9 too).
#[test]
fn every_prediction_adds_the_input() {
    let names = ["kf", "ikf", "cce", "kf-io", "adf", "pf"];
    for (flags, what) in [(FLAG_IPC_LOST, "lost"), (FLAG_OCCLUDED, "dropped")] {
        let obs = [Observation::dropped(1, 0, 1, flags)];
        let (a, b) = one_step("occlusion-user-controlled.toml", &options(&names), &obs);
        assert_eq!(a.iter().map(|(n, _)| *n).collect::<Vec<_>>(), names);
        for ((name, xa), (_, xb)) in a.iter().zip(&b) {
            for j in 0..2 {
                if what == "lost" || *name == "kf" || *name == "ikf" {
                    assert!(
                        (xa[j] - xb[j] - BU[j]).abs() < 1e-9,
                        "{name} ({what}) x[{j}]: {} − {} ≠ {}",
                        xa[j],
                        xb[j],
                        BU[j]
                    );
                }
            }
        }
    }
}

/// Behind the innovation gate too (`--gate P`, docs/gate.md), every prediction adds B_u u_k:
/// after one instant whose slot was lost, from the same prior, each gated estimator's x̂ on the
/// model with the constant input exceeds its x̂ on the model without it by B_u u_0. (The gated
/// Kalman filters predicted without the input before the runner took the core's sequential
/// filter: `kf+gate` on `controlled.toml` had 200× the MSE of `kf`.)
#[test]
fn every_gated_prediction_adds_the_input() {
    let gated = EvalOptions {
        gate: Some(0.999),
        ..options(&["kf", "ikf", "cce", "kf-io", "adf"])
    };
    let obs = [Observation::dropped(1, 0, 1, FLAG_IPC_LOST)];
    let (a, b) = one_step("occlusion-user-controlled.toml", &gated, &obs);
    assert_eq!(
        a.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
        ["kf+gate", "ikf+gate", "cce+gate", "kf-io+gate", "adf+gate"]
    );
    for ((name, xa), (_, xb)) in a.iter().zip(&b) {
        for j in 0..2 {
            assert!(
                (xa[j] - xb[j] - BU[j]).abs() < 1e-9,
                "{name} x[{j}]: {} − {} ≠ {}",
                xa[j],
                xb[j],
                BU[j]
            );
        }
    }
}
