//! MSE against transmission rate for the Kalman filter behind an event trigger: `ikf` (ignores
//! every silence), `kf-sl` and `kf-silence` (read the held trigger's silence), and the
//! full-information `kf`, on `channel-sim/scenarios/linear-triggered.toml` with the trigger's σ
//! swept (docs/tobit-fusion.md, "The linear case").
//!
//! ```text
//! cargo run --release -p ipc-runner --example silence_rate -- [RUNS] [PLOT]
//! ```
//!
//! Prints a markdown table (avg MSE, paired differences against `ikf` with their standard
//! errors) and writes the plot (default `docs/silence-rate.png`).

use std::path::{Path, PathBuf};

use channel_sim::scenario::resolve;
use ipc_runner::estimators::{ikf, kf, silence_kf, Factory};
use ipc_runner::eval::run_one;
use ipc_runner::eval::EvalOptions;
use ipc_runner::plot::rate::plot_rate;

const SIGMAS: [f64; 7] = [0.05, 0.15, 0.3, 0.5, 0.75, 1.0, 1.5];
const HORIZON: u32 = 200;
const SEED: u64 = 2026;

fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let runs: u64 = args.next().map_or(Ok(2000), |s| s.parse())?;
    let plot = args
        .next()
        .map_or_else(|| PathBuf::from("docs/silence-rate.png"), PathBuf::from);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let base = std::fs::read_to_string(root.join("channel-sim/scenarios/linear-triggered.toml"))?;
    anyhow::ensure!(
        base.contains("sigma = 0.5\n"),
        "the shipped file's sigma moved"
    );
    let dir = std::env::temp_dir().join(format!("silence-rate-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let names = ["kf", "ikf", "kf-silence", "kf-sl"];
    let factories: &[Factory] = &[kf::build, ikf::build, silence_kf::build];
    let mut series: Vec<(String, Vec<(f64, f64)>)> =
        names.iter().map(|n| (n.to_string(), Vec::new())).collect();
    println!("| σ | rate | kf | ikf | kf-sl | kf-silence | kf-sl − ikf | kf-silence − ikf |");
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    for sigma in SIGMAS {
        let file = dir.join(format!("sigma-{sigma}.toml"));
        std::fs::write(
            &file,
            base.replace("sigma = 0.5\n", &format!("sigma = {sigma}\n")),
        )?;
        let scenario = resolve("", Some(&file))?;
        let options = EvalOptions {
            runs,
            horizon: HORIZON,
            seed: SEED,
            estimators: names.iter().map(|n| n.to_string()).collect(),
            ..EvalOptions::default()
        };
        let mut avg = vec![Vec::new(); names.len()];
        let (mut delivered, mut instants) = (0u64, 0u64);
        for run in 0..runs {
            let out = run_one(&*scenario, &options, factories, run, &names)?;
            for (j, e) in out.estimators.iter().enumerate() {
                let sq = e
                    .sq_err
                    .as_ref()
                    .ok_or_else(|| anyhow::anyhow!("{} diverged", names[j]))?;
                avg[j].push(sq[2..].iter().sum::<f64>() / f64::from(HORIZON));
            }
            for c in &out.channel {
                delivered += c.delivered;
                instants += c.instants;
            }
        }
        let rate = delivered as f64 / instants as f64;
        let m: Vec<f64> = avg.iter().map(|a| mean_se(a).0).collect();
        let diff = |j: usize| {
            let d: Vec<f64> = avg[j].iter().zip(&avg[1]).map(|(a, b)| a - b).collect();
            let (d, s) = mean_se(&d);
            format!("{d:+.4} ± {s:.4} ({:+.1} %)", 100.0 * d / m[1])
        };
        println!(
            "| {sigma} | {rate:.3} | {:.4} | {:.4} | {:.4} | {:.4} | {} | {} |",
            m[0],
            m[1],
            m[3],
            m[2],
            diff(3),
            diff(2)
        );
        for j in 0..names.len() {
            series[j].1.push((rate, m[j]));
        }
    }
    std::fs::remove_dir_all(&dir)?;
    plot_rate(
        &format!("linear-triggered: MSE against transmission rate ({runs} runs, T = {HORIZON})"),
        &series,
        &plot,
    )?;
    println!("wrote {}", plot.display());
    Ok(())
}
