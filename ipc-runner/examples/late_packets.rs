//! Late packets measured (docs/pipeline.md, "Late packets"): on the `occlusion` and
//! `tobit-fusion` presets, the MSE of every estimator (a) with every slot on time, (b) with
//! 30 % of the slots 1-3 instants late and lost (no lag: today's receiver), (c) the same delays
//! with `--lag 3`, as `eval` computes them, with paired standard errors (the three evaluations
//! share the seed, so run r has the same plant, channel and delays in each).
//!
//! ```sh
//! cargo run --release -p ipc-runner --example late_packets -- 2000
//! ```

use std::collections::BTreeMap;

use ipc_runner::estimators::FACTORIES;

use ipc_runner::eval::delay::Delay;
use ipc_runner::eval::EvalOptions;
use ipc_runner::eval::{evaluate, EstimatorResult, EvalResult, RunConfig};

/// Mean and standard error of the paired differences `x_r − y_r` over the runs valid in both.
fn paired(x: &[(u64, f64)], y: &[(u64, f64)]) -> (f64, f64, usize) {
    let y: BTreeMap<u64, f64> = y.iter().copied().collect();
    let d: Vec<f64> = x
        .iter()
        .filter_map(|(r, v)| y.get(r).map(|w| v - w))
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt(), d.len())
}

fn main() -> anyhow::Result<()> {
    let runs: u64 = std::env::args().nth(1).map_or(Ok(2000), |s| s.parse())?;
    let delay: Delay = "mix:0.3:3".parse().map_err(anyhow::Error::msg)?;
    for preset in ["occlusion", "tobit-fusion"] {
        let scenario = channel_sim::scenario::preset(preset)?;
        let base = EvalOptions {
            runs,
            seed: 1,
            particles: 0,
            ..EvalOptions::default()
        };
        let eval =
            |options: EvalOptions| evaluate(&*scenario, &options, FACTORIES, &RunConfig::default());
        let on_time = eval(base.clone())?;
        let lost = eval(EvalOptions {
            transport_delay: Some(delay),
            ..base.clone()
        })?;
        let lag = eval(EvalOptions {
            transport_delay: Some(delay),
            lag: 3,
            ..base.clone()
        })?;
        println!(
            "\n{preset}: {runs} runs, horizon {}, seed {}; delays {delay}",
            base.horizon, base.seed
        );
        println!(
            "| estimator | (a) on time | (b) late = lost | (c) --lag 3 | (b) − (a) | (c) − (a) | valid runs |"
        );
        println!("|---|---|---|---|---|---|---|");
        for (name, a) in &on_time.estimators {
            let (Some(b), Some(c)) = (find(&lost, name), find(&lag, name)) else {
                continue;
            };
            let (db, sb, _) = paired(&b.run_averages, &a.run_averages);
            let (dc, sc, n) = paired(&c.run_averages, &a.run_averages);
            let pct = |d: f64, s: f64| {
                format!(
                    "{:+.1} % ± {:.1}",
                    100.0 * d / a.avg_mse,
                    100.0 * s / a.avg_mse
                )
            };
            println!(
                "| {name} | {:.4} | {:.4} | {:.4} | {} | {} | {n} |",
                a.avg_mse,
                b.avg_mse,
                c.avg_mse,
                pct(db, sb),
                pct(dc, sc)
            );
        }
    }
    Ok(())
}

/// The result of estimator `name` in `r`.
fn find<'a>(r: &'a EvalResult, name: &str) -> Option<&'a EstimatorResult> {
    r.estimators.iter().find(|(n, _)| n == name).map(|(_, e)| e)
}
