//! What a subscriber of `<prefix>/estimates` receives (`docs/wire.md`): a subscriber that
//! connects late gets the newest estimates at once (the service's history), and every
//! estimate carries the estimator's own covariance, bit for bit.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, scratch, Proc};
use estpipe_wire::{Estimate, COV_LEN, MAX_NX, WIRE_VERSION};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};

fn node() -> Node<ipc::Service> {
    set_log_level(LogLevel::Error);
    NodeBuilder::new().create::<ipc::Service>().unwrap()
}

fn subscriber(node: &Node<ipc::Service>, p: &str) -> Subscriber<ipc::Service, Estimate, ()> {
    estpipe_wire::estimate_service(node, p)
        .unwrap()
        .subscriber_builder()
        .create()
        .unwrap()
}

/// Everything `sub` has, in order.
fn drain(sub: &Subscriber<ipc::Service, Estimate, ()>, into: &mut Vec<Estimate>) {
    while let Some(s) = sub.receive().unwrap() {
        into.push(*s.payload());
    }
}

#[test]
fn a_late_subscriber_gets_the_newest_estimates_on_connect() {
    let dir = scratch("late");
    let p = prefix("late");
    let mut run = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "60",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    // 20 Hz: the runner idles 50 ms between instants, longer than the history takes to come.
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--rate",
            "20",
            "--steps",
            "60",
        ],
    );
    std::thread::sleep(Duration::from_millis(1200));
    let node = node();
    let sub = subscriber(&node, &p);
    let mut first = Vec::new();
    let t = Instant::now();
    while t.elapsed() < Duration::from_millis(30) {
        drain(&sub, &mut first);
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(!first.is_empty(), "nothing within 30 ms of connecting");
    assert!(first.iter().all(|e| e.version == WIRE_VERSION));
    let newest = first.iter().map(|e| e.k).max().unwrap();
    let distinct: std::collections::BTreeSet<u32> = first.iter().map(|e| e.k).collect();
    // Older instants too: this is the history, not a send that happened to come.
    assert!(distinct.len() >= 2, "{distinct:?}");
    // Every estimator's estimate of the newest instant is there.
    let n_est = first.iter().map(|e| e.estimator).max().unwrap() + 1;
    assert_eq!(
        first.iter().filter(|e| e.k == newest).count() as u32,
        n_est,
        "{first:?}"
    );
    // … and it was the newest: the next one is the instant after it.
    let mut next = Vec::new();
    let t = Instant::now();
    while !next.iter().any(|e: &Estimate| e.k > newest) {
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "no estimate after k = {newest}"
        );
        drain(&sub, &mut next);
        std::thread::sleep(Duration::from_millis(1));
    }
    let after = next.iter().find(|e| e.k > newest).unwrap();
    assert_eq!(after.k, newest + 1);
    assert!(publ.wait(30).success(), "{}", publ.err());
    assert!(run.wait(30).success(), "{}", run.err());
    eprintln!(
        "connected at k ≈ {newest}: {} estimates of {} instants at once",
        first.len(),
        distinct.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs `scenario` through the pipeline with a subscriber on the estimates from the start;
/// returns every estimate received and the slot log the runner recorded.
fn run_and_collect(
    dir: &std::path::Path,
    scenario: &str,
    estimators: &str,
    steps: u32,
) -> (Vec<Estimate>, std::path::PathBuf) {
    let p = prefix(&format!("cov-{scenario}"));
    let slots = dir.join(format!("{scenario}-slots.csv"));
    let steps_s = steps.to_string();
    let mut run = Proc::start(
        dir,
        &format!("runner-{scenario}"),
        &[
            "run",
            "--scenario",
            scenario,
            "--estimators",
            estimators,
            "--prefix",
            &p,
            "--steps",
            &steps_s,
            "--buffer",
            "4096",
            "--slots-csv",
            slots.to_str().unwrap(),
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let node = node();
    let sub = subscriber(&node, &p);
    let mut publ = Proc::start(
        dir,
        &format!("pub-{scenario}"),
        &[
            "channel-sim",
            "--scenario",
            scenario,
            "--prefix",
            &p,
            "--rate",
            "0",
            "--steps",
            &steps_s,
        ],
    );
    let mut got = Vec::new();
    while run.child.as_mut().unwrap().try_wait().unwrap().is_none() {
        drain(&sub, &mut got);
        std::thread::sleep(Duration::from_millis(1));
    }
    drain(&sub, &mut got);
    assert!(run.wait(1).success(), "{}", run.err());
    assert!(publ.wait(30).success(), "{}", publ.err());
    (got, slots)
}

/// What an estimator's covariance is (docs/design.md, The estimator API): the bound its paper
/// propagates for the NN estimator and seed 004's Tobit filters, else the error covariance (the
/// centralised Tobit filters and the particle filters' weighted sample covariance included).
fn expected_kind(name: &str) -> ipc_runner::CovarianceKind {
    use ipc_runner::CovarianceKind::*;
    match name {
        "nn" | "fused" => Bound,
        "tobit-kf" | "tobit-cmm" | "tobit-cmm-held" => Estimate,
        n if n.starts_with("tobit-") || n.starts_with("fused-") => Bound,
        _ => Estimate,
    }
}

#[test]
fn every_estimate_carries_the_estimators_covariance_bit_for_bit() {
    use ipc_runner::run::select;
    let dir = scratch("cov");
    for (scenario, estimators, steps) in [
        ("linear", "ikf", 300u32),
        ("occlusion", "ikf,cce,kf-io,adf", 100),
        ("tobit-fusion", "", 100),
        ("nn-token-bucket", "", 100),
    ] {
        let sc: std::sync::Arc<dyn channel_sim::Scenario> =
            channel_sim::scenario::preset(scenario).unwrap().into();
        let (nx, nodes, ny) = (sc.nx(), sc.nodes(), sc.ny());
        let source = std::sync::Arc::new(ipc_runner::source::Source::of_scenario(&*sc, 0, 0));
        let names: Vec<String> = estimators
            .split(',')
            .filter(|s| !s.is_empty())
            .map(str::to_string)
            .collect();
        let est_arg = if names.is_empty() {
            // Every real-time estimator of the scenario.
            let make = select::estimators(
                source.clone(),
                &[],
                select::Experiment {
                    seed: 0,
                    run: 0,
                    horizon: steps,
                },
            )
            .unwrap();
            make()
                .unwrap()
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(",")
        } else {
            estimators.to_string()
        };
        let (got, slots) = run_and_collect(&dir, scenario, &est_arg, steps);
        // The same estimators in this process over the slots the runner received.
        let instants = ipc_runner::slot_log::read_slots(&slots, nodes, ny).unwrap();
        let make = select::estimators(
            source.clone(),
            &names,
            select::Experiment {
                seed: 0,
                run: 0,
                horizon: steps,
            },
        )
        .unwrap();
        let mut ests = make().unwrap();
        let n_est = ests.len();
        assert_eq!(
            got.len(),
            instants.len() * n_est,
            "{scenario}: estimates received"
        );
        let (mut x, mut full) = ([0.0; MAX_NX], [0.0; MAX_NX * MAX_NX]);
        let mut with_cov = 0;
        for (i, (k, obs)) in instants.iter().enumerate() {
            for (e, est) in ests.iter_mut().enumerate() {
                let status = u32::from(est.step(*k, obs).is_err());
                est.estimate(&mut x[..nx]);
                let kind = est.covariance(&mut full[..nx * nx]);
                let mut p = [0.0; COV_LEN];
                Estimate::pack_covariance(nx, &full[..nx * nx], &mut p);
                let w = &got[i * n_est + e];
                let what = format!("{scenario} k = {k} {}", est.name());
                assert_eq!(
                    (w.k, w.estimator, w.name()),
                    (*k, e as u32, est.name()),
                    "{what}"
                );
                assert_eq!(w.status, status, "{what}");
                assert_eq!(w.nx as usize, nx, "{what}");
                assert_eq!(w.cov_kind, kind.wire(), "{what}");
                assert_eq!(kind, expected_kind(est.name()), "{what}");
                let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&w.x[..nx]), bits(&x[..nx]), "{what}: x̂");
                assert_eq!(bits(&w.p), bits(&p), "{what}: P");
                if kind != ipc_runner::CovarianceKind::None {
                    with_cov += 1;
                    assert!(
                        w.p[..nx * (nx + 1) / 2].iter().all(|v| v.is_finite()),
                        "{what}"
                    );
                }
            }
        }
        eprintln!(
            "{scenario}: {} estimates ({n_est} estimator(s)) equal the in-process ones; {with_cov} carry a covariance",
            got.len()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
