use channel_sim::scenario::{config, preset};
use channel_sim::{Observation, Scenario};
use nalgebra::{dmatrix, DMatrix};

use super::*;
use crate::estimators::RunStart;
use crate::estimators::FACTORIES;
use crate::eval::EvalOptions;
use crate::Estimator;

fn options(runs: u64, horizon: u32, seed: u64) -> EvalOptions {
    EvalOptions {
        runs,
        horizon,
        seed,
        ..EvalOptions::default()
    }
}

fn eval_with(
    scenario: &dyn Scenario,
    o: &EvalOptions,
    factories: &[Factory],
    threads: usize,
) -> EvalResult {
    let config = RunConfig {
        threads: Some(threads),
        progress: false,
    };
    evaluate(scenario, o, factories, &config).unwrap()
}

fn estimator<'a>(r: &'a EvalResult, name: &str) -> &'a EstimatorResult {
    &r.estimators.iter().find(|(n, _)| n == name).unwrap().1
}

/// 300 runs cross the 256-run chunk boundary; the JSON must not depend on the thread count.
#[test]
fn same_seed_gives_identical_json_whatever_the_thread_count() {
    let s = preset("linear").unwrap();
    let o = options(300, 30, 11);
    let one = eval_with(&*s, &o, FACTORIES, 1).to_json();
    for threads in [2, 3] {
        assert_eq!(one, eval_with(&*s, &o, FACTORIES, threads).to_json());
    }
    assert_ne!(
        one,
        eval_with(&*s, &options(300, 30, 12), FACTORIES, 2).to_json()
    );
}

/// The table's role column reads what an estimator is fed: the full-information `kf` of a
/// linear spec is the oracle, while seed 003's `kf` (the paper's KF on the channel's output)
/// stays a baseline. The JSON's entries carry the same role.
#[test]
fn the_full_information_kf_is_the_oracle_and_seed_003s_kf_a_baseline() {
    let role_of = |summary: &str, name: &str| -> String {
        let line = (summary.lines())
            .find(|l| l.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("{name} not in\n{summary}"));
        line.split_whitespace().nth(1).unwrap().to_owned()
    };
    for scenario in ["linear", "tobit-fusion"] {
        let s = preset(scenario).unwrap();
        let r = eval_with(&*s, &options(4, 10, 5), FACTORIES, 2);
        let table = r.summary();
        assert_eq!(role_of(&table, "kf"), "oracle", "{scenario}");
        assert_eq!(role_of(&table, "ikf"), "baseline", "{scenario}");
        assert_eq!(estimator(&r, "kf").role, Role::Oracle);
        let v: serde_json::Value = serde_json::from_str(&r.to_json()).unwrap();
        assert_eq!(v["estimators"]["kf"]["role"], "oracle", "{scenario}");
    }
    let s = preset("nn-token-bucket").unwrap();
    let table = eval_with(&*s, &options(2, 10, 5), FACTORIES, 2).summary();
    assert_eq!(role_of(&table, "kf"), "baseline");
    assert_eq!(role_of(&table, "nn"), "paper");
    assert!(table.contains("or an oracle fed what no receiver has"));
}

#[test]
fn json_has_the_documented_shape() {
    let s = preset("linear").unwrap();
    let (runs, t) = (20, 15);
    let r = eval_with(&*s, &options(runs, t, 3), FACTORIES, 2);
    let json = r.to_json();
    // Estimators appear in registry order (serde_json::Value would sort the keys).
    assert!(json.find("\"kf\": {").unwrap() < json.find("\"ikf\": {").unwrap());
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["scenario"], "linear");
    assert_eq!(v["runs"], runs);
    assert_eq!(v["horizon"], t);
    assert_eq!(v["seed"], 3);
    let names: Vec<&String> = v["estimators"].as_object().unwrap().keys().collect();
    assert_eq!(names, ["ikf", "kf"]);
    for name in names {
        let e = &v["estimators"][name];
        assert_eq!(e["mse"].as_array().unwrap().len(), t as usize + 1);
        assert!(e["avg_mse"].as_f64().unwrap() > 0.0);
        assert!(e["avg_mse_se"].as_f64().unwrap() > 0.0);
        assert!(e["median_run_avg"].as_f64().unwrap() > 0.0);
        assert_eq!(e["diverged_runs"], 0);
        assert_eq!(e["valid_runs"], runs);
        let per_state = e["mse_per_state"].as_array().unwrap();
        assert_eq!(per_state.len(), 2);
        assert_eq!(per_state[0].as_array().unwrap().len(), t as usize + 1);
        assert_eq!(e["trace_p"].as_array().unwrap().len(), t as usize + 1);
        // MSE(k) is the sum of the per-state MSEs.
        for k in 0..=t as usize {
            let sum = per_state[0][k].as_f64().unwrap() + per_state[1][k].as_f64().unwrap();
            assert!((sum - e["mse"][k].as_f64().unwrap()).abs() < 1e-12);
        }
        // avg_mse is the mean of MSE(1..=T).
        let mse: Vec<f64> = e["mse"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let avg = mse[1..].iter().sum::<f64>() / t as f64;
        assert!((avg - e["avg_mse"].as_f64().unwrap()).abs() < 1e-12);
    }
    let node = &v["channel"]["nodes"][0];
    for key in [
        "node",
        "instants",
        "delivered",
        "dropped",
        "sent",
        "triggered",
        "blocked",
        "censored",
        "random_loss",
        "occluded",
    ] {
        assert!(node[key].is_u64(), "channel.nodes[0].{key}");
    }
    assert_eq!(node["instants"], runs * t as u64);
    assert_eq!(
        node["delivered"].as_u64().unwrap() + node["dropped"].as_u64().unwrap(),
        runs * t as u64
    );
    assert_eq!(node["dropped"], node["random_loss"]);
    let csv = r.to_csv();
    assert_eq!(csv.lines().count(), t as usize + 2);
    assert!(csv.starts_with("k,kf,ikf\n0,"));
}

/// The `linear` preset's model, written out here independently of channel-sim.
fn riccati_traces(horizon: usize) -> Vec<f64> {
    let a = dmatrix![0.95, 0.10; -0.10, 0.95];
    let q = dmatrix![0.01, 0.0; 0.0, 0.04];
    let c = dmatrix![1.0, 0.0];
    let r = 0.25;
    let mut p = DMatrix::<f64>::identity(2, 2);
    let mut traces = vec![p.trace()];
    for _ in 1..=horizon {
        let prior = &a * &p * a.transpose() + &q;
        let s = (&c * &prior * c.transpose())[(0, 0)] + r;
        let k = &prior * c.transpose() / s;
        p = (DMatrix::identity(2, 2) - &k * &c) * &prior;
        traces.push(p.trace());
    }
    traces
}

/// The full-information KF is the MMSE estimator of a linear-Gaussian plant with a correctly
/// specified prior, so E‖x_k − x̂_k‖² = tr P_k from the Riccati recursion. MSE(k) averages n
/// i.i.d. squared norms of e ~ N(0, P_k), whose variance is 2 tr(P_k²) ≤ 2 tr(P_k)²: each k is
/// checked within 5 such standard errors. IKF loses 20 % of the measurements, so its MSE is
/// larger on average and in median, and its mean covariance trace is never below the KF's.
#[test]
fn kf_matches_riccati_trace_and_ikf_is_worse_under_loss() {
    let s = preset("linear").unwrap();
    let (runs, t) = (4000u64, 40usize);
    let r = eval_with(&*s, &options(runs, t as u32, 2024), FACTORIES, 2);
    let traces = riccati_traces(t);
    let kf = estimator(&r, "kf");
    let ikf = estimator(&r, "ikf");
    for k in 0..=t {
        let se = (2.0 / runs as f64).sqrt() * traces[k];
        assert!(
            (kf.mse[k] - traces[k]).abs() < 5.0 * se,
            "k = {k}: MSE {} vs tr P {}",
            kf.mse[k],
            traces[k]
        );
        // The filter's own covariance follows the same recursion (diagnostic path).
        assert!((kf.diagnostics[0].1[k] - traces[k]).abs() < 1e-9);
    }
    assert!(ikf.avg_mse > kf.avg_mse);
    assert!(ikf.median_run_avg > kf.median_run_avg);
    // On a dropout the IKF's P grows, so its mean trace exceeds the KF's from k = 1 on.
    for k in 1..=t {
        assert!(ikf.diagnostics[0].1[k] >= kf.diagnostics[0].1[k] - 1e-12);
    }
    let delivered = r.channel.nodes[0].delivery_rate;
    // Binomial: n = runs·T packets, p = 0.8; 5 standard deviations.
    let n = (runs * t as u64) as f64;
    assert!((delivered - 0.8).abs() < 5.0 * (0.8 * 0.2 / n).sqrt());
}

/// Without channel stages `ikf` receives every measurement, so it is the same filter on the
/// same data as `kf`: identical numbers, also with two nodes (sequential updates).
#[test]
fn without_a_channel_ikf_equals_kf_with_two_nodes() {
    let text = include_str!("../../../channel-sim/scenarios/example.toml");
    let cut = text.find("[[stages]]").unwrap();
    let s = config::parse(&text[..cut], "inline", "two-nodes").unwrap();
    assert_eq!(s.nodes(), 2);
    let r = eval_with(&s, &options(50, 20, 1), FACTORIES, 2);
    let (kf, ikf) = (estimator(&r, "kf"), estimator(&r, "ikf"));
    assert_eq!(kf.mse, ikf.mse);
    assert_eq!(r.channel.delivery_rate, 1.0);
}

/// An estimator that predicts 0 and fails on purpose: a non-finite estimate on runs ≡ 1 mod 4
/// (at k = 5) and a step error on runs ≡ 2 mod 4 (at k = 7).
struct Faulty {
    run: u64,
    nx: usize,
    k: u32,
}

impl Estimator for Faulty {
    fn name(&self) -> &'static str {
        "faulty"
    }
    fn step(&mut self, k: u32, _obs: &[Observation]) -> Result<(), estimator_core::Error> {
        if self.run % 4 == 2 && k == 7 {
            return Err(estimator_core::Error::Numerical { what: "test" });
        }
        self.k = k;
        Ok(())
    }
    fn estimate(&self, out: &mut [f64]) {
        let v = if self.run % 4 == 1 && self.k >= 5 {
            f64::NAN
        } else {
            0.0
        };
        out[..self.nx].fill(v);
    }
}

fn faulty(
    s: &std::sync::Arc<estpipe_spec::EstimatorSpec>,
    _o: &crate::estimators::BuildOptions,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(vec![Box::new(Faulty {
        run: start.run,
        nx: s.nx(),
        k: 0,
    })])
}

#[test]
fn diverged_runs_are_counted_and_excluded_never_a_crash() {
    let s = preset("linear").unwrap();
    let factories: &[Factory] = &[crate::estimators::kf::build, faulty];
    let r = eval_with(&*s, &options(40, 10, 5), factories, 2);
    let f = estimator(&r, "faulty");
    assert_eq!(f.diverged_runs, 20);
    assert_eq!(f.valid_runs, 20);
    assert_eq!(
        f.first_error.as_deref(),
        Some("run 1: k = 5: non-finite estimate")
    );
    assert!(f.mse.iter().all(|v| v.is_finite()));
    assert_eq!(estimator(&r, "kf").diverged_runs, 0);
    // The trajectory of a non-diverged run is recorded; the JSON stays valid.
    let v: serde_json::Value = serde_json::from_str(&r.to_json()).unwrap();
    assert_eq!(v["estimators"]["faulty"]["diverged_runs"], 20);
}

/// The transport stage after the channel: it loses about `p` of the slots (binomial, within
/// 5 standard deviations), leaves the channel's counts and `ikf` (a dropout and a loss are the
/// same to it) as they were, and the occlusion estimators see a marked loss differently from an
/// unmarked one. Without it (`p = 0`) the JSON is that of an eval without the stage.
#[test]
fn transport_losses_come_after_the_channel() {
    let s = preset("occlusion").unwrap();
    let base = options(40, 50, 5);
    let with = |p: f64, unmarked: bool| {
        let o = EvalOptions {
            particles: 0,
            transport_loss: p,
            transport_loss_unmarked: unmarked,
            ..base.clone()
        };
        eval_with(&*s, &o, FACTORIES, 2)
    };
    let none = with(0.0, false);
    assert_eq!(
        none.to_json(),
        eval_with(
            &*s,
            &EvalOptions {
                particles: 0,
                ..base.clone()
            },
            FACTORIES,
            2
        )
        .to_json()
    );
    let (marked, unmarked) = (with(0.2, false), with(0.2, true));
    let (c0, c1) = (&none.channel.nodes[0], &marked.channel.nodes[0]);
    assert_eq!((c0.delivered, c0.occluded), (c1.delivered, c1.occluded));
    let n = c1.instants as f64;
    let lost = c1.transport_lost as f64;
    assert!(
        (lost - 0.2 * n).abs() < 5.0 * (n * 0.2 * 0.8).sqrt(),
        "{lost} of {n}"
    );
    assert_eq!(c1.transport_lost, unmarked.channel.nodes[0].transport_lost);
    assert!(marked.to_json().contains("\"transport_lost\""));
    assert!(!none.to_json().contains("transport"));
    let ikf = |r: &EvalResult| estimator(r, "ikf").mse.clone();
    assert_eq!(ikf(&marked), ikf(&unmarked));
    assert_ne!(ikf(&marked), ikf(&none));
    for e in ["cce", "adf"] {
        assert_ne!(
            estimator(&marked, e).mse,
            estimator(&unmarked, e).mse,
            "{e}"
        );
    }
    // The same slots are lost whatever the loss rate's other uses: a slot lost at p is lost at
    // every larger p.
    for seq in 0..1000 {
        if transport_lost(5, 3, seq, 0.1) {
            assert!(transport_lost(5, 3, seq, 0.2));
        }
    }
}

/// `inner` with the truth of instant `k` NaN in the even runs (what an overflowing plant or
/// a bad TOML plant would give); the estimators see the same observations.
#[derive(Debug)]
struct NanTruthAt {
    inner: Box<dyn Scenario>,
    k: u32,
}

struct NanTruthSim {
    inner: Box<dyn channel_sim::Simulation>,
    k: Option<u32>,
}

impl channel_sim::Simulation for NanTruthSim {
    fn initial_truth(&self) -> [f64; MAX_NX] {
        self.inner.initial_truth()
    }
    fn initial_observations(&self) -> Option<&[Observation]> {
        self.inner.initial_observations()
    }
    fn next_instant(&mut self) -> channel_sim::sim::Instant {
        let mut i = self.inner.next_instant();
        if Some(i.k) == self.k {
            i.truth[1] = f64::NAN;
        }
        i
    }
    fn raw_observations(&self) -> Option<&[Observation]> {
        self.inner.raw_observations()
    }
}

impl Scenario for NanTruthAt {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn nx(&self) -> usize {
        self.inner.nx()
    }
    fn ny(&self) -> usize {
        self.inner.ny()
    }
    fn nodes(&self) -> usize {
        self.inner.nodes()
    }
    fn estimator_spec(&self) -> std::sync::Arc<estpipe_spec::EstimatorSpec> {
        self.inner.estimator_spec()
    }
    fn start(&self, seed: u64, run: u64) -> Box<dyn channel_sim::Simulation> {
        Box::new(NanTruthSim {
            inner: self.inner.start(seed, run),
            k: run.is_multiple_of(2).then_some(self.k),
        })
    }
    fn as_any(&self) -> &dyn std::any::Any {
        // The factories read the inner scenario's parameters.
        self.inner.as_any()
    }
}

/// Issue #20: a non-finite truth sample is counted and left out of the MSE at its k, never
/// a `null` in the report; every other number is the plain evaluation's, bit for bit, and
/// MSE(k) at that k is the mean over the runs with a finite truth there (computed here from
/// the runs' own records, not by the reduction).
#[test]
fn non_finite_truth_is_counted_and_left_out_of_every_mse() {
    let plain = preset("linear").unwrap();
    let nan = NanTruthAt {
        inner: preset("linear").unwrap(),
        k: 3,
    };
    let o = options(40, 8, 3);
    let a = eval_with(&*plain, &o, FACTORIES, 2);
    let b = eval_with(&nan, &o, FACTORIES, 2);
    assert_eq!(a.truth_nonfinite, 0);
    assert_eq!(b.truth_nonfinite, 20);
    let json: serde_json::Value = serde_json::from_str(&b.to_json()).unwrap();
    for (name, e) in json["estimators"].as_object().unwrap() {
        for field in ["mse", "avg_mse", "avg_mse_se", "median_run_avg"] {
            let v = &e[field];
            let numbers = match v.as_array() {
                Some(a) => a.iter().all(serde_json::Value::is_f64),
                None => v.is_f64(),
            };
            assert!(numbers, "{name}.{field}: {v}");
        }
    }
    assert!(b
        .summary()
        .contains("truth not finite at 20 (run, k) instant(s)"));
    let names: Vec<&'static str> = a
        .estimators
        .iter()
        .map(|(n, _)| {
            build_all(
                FACTORIES,
                &plain.estimator_spec(),
                &o,
                &RunStart {
                    seed: 3,
                    ..Default::default()
                },
            )
            .unwrap()
            .iter()
            .map(|e| e.name())
            .find(|m| m == n)
            .unwrap()
        })
        .collect();
    for (j, ((name, ra), (_, rb))) in a.estimators.iter().zip(&b.estimators).enumerate() {
        assert_eq!(ra.valid_runs, rb.valid_runs, "{name}");
        for k in (0..=8).filter(|&k| k != 3) {
            assert_eq!(ra.mse[k].to_bits(), rb.mse[k].to_bits(), "{name} k = {k}");
        }
        // The odd runs' squared errors at k = 3, from run_one.
        let nx = plain.nx();
        let (mut sum, mut n) = (0.0, 0u32);
        for run in (1..40).step_by(2) {
            let out = run_one(&*plain, &o, FACTORIES, run, &names).unwrap();
            if let Some(sq) = &out.estimators[j].sq_err {
                sum += sq[3 * nx..][..nx].iter().sum::<f64>();
                n += 1;
            }
        }
        let expect = sum / f64::from(n);
        assert!(
            (rb.mse[3] - expect).abs() <= 1e-12 * expect,
            "{name}: {} vs {expect}",
            rb.mse[3]
        );
        assert!(
            rb.avg_mse.is_finite() && rb.median_run_avg.is_finite(),
            "{name}"
        );
    }
}

/// A stop request keeps the runs done before it: the result is that of an evaluation of
/// just those runs (same numbers, bit for bit), marked interrupted with the runs asked for.
#[test]
fn a_stopped_evaluation_is_the_evaluation_of_the_runs_done() {
    let s = preset("linear").unwrap();
    let polls = std::sync::atomic::AtomicU64::new(0);
    // One thread: the workers poll once per run, in run order; the 14th poll stops.
    let stop = || polls.fetch_add(1, std::sync::atomic::Ordering::SeqCst) >= 13;
    let control = Control {
        stop: Some(&stop),
        ..Control::default()
    };
    let config = RunConfig {
        threads: Some(1),
        progress: false,
    };
    let r = evaluate_with(&*s, &options(300, 12, 9), FACTORIES, &config, &control).unwrap();
    assert_eq!(r.ending, EvalEnding::Interrupted);
    assert_eq!((r.runs, r.runs_requested), (13, Some(300)));
    let done = eval_with(&*s, &options(13, 12, 9), FACTORIES, 1);
    assert_eq!(done.ending, EvalEnding::Completed);
    let (mut a, b): (serde_json::Value, serde_json::Value) = (
        serde_json::from_str(&r.to_json()).unwrap(),
        serde_json::from_str(&done.to_json()).unwrap(),
    );
    assert_eq!(a["ending"], "interrupted");
    a["ending"] = "completed".into();
    a.as_object_mut().unwrap().remove("runs_requested");
    assert_eq!(a, b);
}

/// The budget refuses before any run, naming the flags; within it, a smaller budget only
/// shrinks the chunks (the numbers stay the same).
#[test]
fn the_memory_budget_refuses_or_shrinks_chunks_never_changes_results() {
    let s = preset("linear").unwrap();
    let config = RunConfig {
        threads: Some(2),
        progress: false,
    };
    let tight = Control {
        budget: Budget::mib(1),
        ..Control::default()
    };
    let huge = EvalOptions {
        particles: 0,
        ..options(300, 100_000, 1)
    };
    let e = evaluate_with(&*s, &huge, FACTORIES, &config, &tight)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("--runs 300 --steps 100000 (") && e.contains("budget is 1.0 MiB"),
        "{e}"
    );
    // 300 runs of T = 300 in 1 MiB: chunks of a few dozen runs instead of 256.
    let o = EvalOptions {
        particles: 0,
        ..options(300, 300, 4)
    };
    let (fixed, per_run) = memory_need(s.nx(), 1, 300, 300);
    assert!(
        fixed + 256 * per_run > tight.budget.bytes,
        "the budget must bind the chunks"
    );
    let small = evaluate_with(&*s, &o, FACTORIES, &config, &tight).unwrap();
    assert_eq!(small.to_json(), eval_with(&*s, &o, FACTORIES, 2).to_json());
}
