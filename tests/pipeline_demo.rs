//! The demo over real processes and shared memory reproduces the in-process computation
//! exactly: every estimate bit for bit, hence the MSE. The IPC must not change a single
//! number. The recorded slot log replays to the same estimates.

#[path = "pipeline_common.rs"]
mod common;

use common::{csv, report, scratch, Proc};
use ipc_runner::run::select;

const SCENARIO: &str = channel_sim::publisher::selftest::NAME;
const SEED: u64 = 7;
const RUN: u64 = 3;
const STEPS: u32 = 150;

/// The same computation without processes: scenario → estimators, in order.
fn in_process(nx: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<f64>) {
    let (scenario, _) = select::scenario(SCENARIO, None).unwrap();
    let make = select::estimators(scenario.as_ref(), &[]).unwrap();
    let mut ests = make().unwrap();
    let mut sim = scenario.start(SEED, RUN);
    let (mut truth, mut est) = (Vec::new(), Vec::new());
    let mut sq = vec![0.0; ests.len()];
    for _ in 0..STEPS {
        let inst = sim.next_instant();
        truth.push(inst.truth[..nx].to_vec());
        let mut row = Vec::new();
        for (e, es) in ests.iter_mut().enumerate() {
            let _ = es.step(inst.k, &inst.obs);
            let mut x = vec![0.0; nx];
            es.estimate(&mut x);
            sq[e] += (0..nx).map(|j| (inst.truth[j] - x[j]).powi(2)).sum::<f64>();
            row.extend(x);
        }
        est.push(row);
    }
    let mse = sq.iter().map(|s| s / f64::from(STEPS)).collect();
    (truth, est, mse)
}

#[test]
fn demo_matches_the_in_process_computation_exactly_and_replays() {
    let dir = scratch("demo");
    let prefix = common::prefix("demo");
    let out = dir.join("out");
    let mut demo = Proc::start(
        &dir,
        "demo",
        &[
            "demo",
            "--scenario",
            SCENARIO,
            "--steps",
            &STEPS.to_string(),
            "--rate",
            "1000",
            "--seed",
            &SEED.to_string(),
            "--run",
            &RUN.to_string(),
            "--wait",
            "block",
            "--out",
            out.to_str().unwrap(),
            "--prefix",
            &prefix,
            "--quiet",
        ],
    );
    let status = demo.wait(120);
    assert!(status.success(), "demo failed: {status}\n{}", demo.err());
    let text = demo.out();
    for needle in ["MSE vs truth", "lost in IPC", "p99.9", "end to end"] {
        assert!(text.contains(needle), "summary lacks {needle:?}:\n{text}");
    }

    let r = report(&out.join("report.json"));
    assert_eq!(r["ending"], "completed");
    assert_eq!(r["counts"]["instants"], u64::from(STEPS));
    assert_eq!(r["counts"]["lost_in_ipc"], 0, "{r}");
    assert_eq!(r["truth_missing"], 0);

    let (scenario, _) = select::scenario(SCENARIO, None).unwrap();
    let nx = scenario.nx();
    let (truth, est, mse) = in_process(nx);
    let (head, rows) = csv(&out.join("estimates.csv"));
    assert_eq!(rows.len(), STEPS as usize);
    assert_eq!(head.len(), 2 + nx + est[0].len());
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row[1], (i + 1) as f64);
        for j in 0..nx {
            assert_eq!(
                row[2 + j].to_bits(),
                truth[i][j].to_bits(),
                "truth k={}",
                i + 1
            );
        }
        for (c, v) in est[i].iter().enumerate() {
            assert_eq!(
                row[2 + nx + c].to_bits(),
                v.to_bits(),
                "estimate k={} col {c}",
                i + 1
            );
        }
    }
    let reported = r["estimators"].as_array().unwrap();
    assert_eq!(reported.len(), mse.len());
    for (e, m) in mse.iter().enumerate() {
        assert_eq!(reported[e]["mse"].as_f64().unwrap().to_bits(), m.to_bits());
    }

    // The slot log the demo wrote replays to the same estimates.
    let replayed = dir.join("replayed.csv");
    let mut rp = Proc::start(
        &dir,
        "replay",
        &[
            "replay",
            "--input",
            out.join("slots.csv").to_str().unwrap(),
            "--scenario",
            SCENARIO,
            "--output",
            replayed.to_str().unwrap(),
        ],
    );
    assert!(rp.wait(60).success(), "{}", rp.err());
    let (_, rrows) = csv(&replayed);
    assert_eq!(rrows.len(), STEPS as usize);
    for (i, row) in rrows.iter().enumerate() {
        for (c, v) in est[i].iter().enumerate() {
            assert_eq!(
                row[1 + c].to_bits(),
                v.to_bits(),
                "replay k={} col {c}",
                i + 1
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
