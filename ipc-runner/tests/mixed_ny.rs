//! Sensors of different ny in one scenario (`channel-sim/scenarios/two-sensors.toml`: node 0
//! measures position and velocity, node 1 position only): the stream announces each node's
//! ny, the Kalman filters update node by node with each node's own C and R, and that equals
//! the textbook Kalman filter on the stacked measurement of the nodes that delivered,
//! computed here by hand.

use std::path::{Path, PathBuf};
use std::process::Command;

use channel_sim::Scenario;
use ipc_runner::estimators::FACTORIES;
use ipc_runner::eval::EvalOptions;
use ipc_runner::source::build_for_scenario;
use nalgebra::{DMatrix, DVector};

fn file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios/two-sensors.toml")
}

/// The Kalman filter on the stacked measurement (textbook form, dynamic matrices):
/// predict, then one update with `[C_m]` and `blockdiag(R_m)` of the nodes in `ys`.
struct Stacked {
    x: DVector<f64>,
    p: DMatrix<f64>,
}

impl Stacked {
    fn step(
        &mut self,
        a: &DMatrix<f64>,
        q: &DMatrix<f64>,
        ys: &[(DMatrix<f64>, DMatrix<f64>, Vec<f64>)],
    ) {
        self.x = a * &self.x;
        self.p = a * &self.p * a.transpose() + q;
        let n: usize = ys.iter().map(|(c, _, _)| c.nrows()).sum();
        if n == 0 {
            return;
        }
        let nx = self.x.len();
        let (mut c, mut r, mut y) = (
            DMatrix::zeros(n, nx),
            DMatrix::zeros(n, n),
            DVector::zeros(n),
        );
        let mut row = 0;
        for (cm, rm, ym) in ys {
            let k = cm.nrows();
            c.view_mut((row, 0), (k, nx)).copy_from(cm);
            r.view_mut((row, row), (k, k)).copy_from(rm);
            y.rows_mut(row, k).copy_from_slice(ym);
            row += k;
        }
        let s = &c * &self.p * c.transpose() + r;
        let gain = &self.p * c.transpose() * s.try_inverse().unwrap();
        self.x = &self.x + &gain * (y - &c * &self.x);
        self.p = (DMatrix::identity(nx, nx) - &gain * &c) * &self.p;
    }
}

#[test]
fn node_by_node_kalman_equals_the_stacked_kalman_filter() {
    let scenario = channel_sim::scenario::config::load(&file()).unwrap();
    assert_eq!(
        (scenario.nodes(), scenario.node_ny(0), scenario.node_ny(1)),
        (2, 2, 1)
    );
    assert_eq!(scenario.ny(), 2);
    let header = channel_sim::wire::stream_header(&scenario);
    assert_eq!(header.ny_per_node(), &[2, 1]);

    let options = EvalOptions {
        estimators: vec!["kf".into(), "ikf".into()],
        ..EvalOptions::default()
    };
    let plant = scenario.plant().linear().unwrap();
    let (a, q) = (plant.a().clone(), plant.process_cov().clone());
    let node = |m: usize| (plant.c(m).clone(), plant.measurement_cov(m).clone());
    let init = scenario.initial();
    let (mut only_one, mut both) = (0, 0);
    for run in 0..5 {
        let mut ests = build_for_scenario(FACTORIES, &scenario, &options, 4, run).unwrap();
        assert_eq!(
            ests.iter().map(|e| e.name()).collect::<Vec<_>>(),
            ["kf", "ikf"]
        );
        let mut by_hand = [0, 1].map(|_| Stacked {
            x: init.estimator_mean.clone(),
            p: init.estimator_cov.clone(),
        });
        let mut sim = scenario.start(4, run);
        for k in 1..=200u32 {
            let inst = sim.next_instant();
            let raw = sim.raw_observations().unwrap().to_vec();
            for (i, obs) in [&raw[..], &inst.obs[..]].into_iter().enumerate() {
                let ys: Vec<_> = obs
                    .iter()
                    .filter_map(|o| {
                        let y = o.measurement()?;
                        assert_eq!(y.len(), scenario.node_ny(o.node.into()));
                        let (c, r) = node(o.node.into());
                        Some((c, r, y.to_vec()))
                    })
                    .collect();
                if i == 1 {
                    match ys.len() {
                        1 => only_one += 1,
                        2 => both += 1,
                        _ => {}
                    }
                }
                by_hand[i].step(&a, &q, &ys);
                ests[i].step(k, obs).unwrap();
                let (mut x, mut p) = ([0.0; 2], [0.0; 4]);
                ests[i].estimate(&mut x);
                ests[i].covariance(&mut p);
                let h = &by_hand[i];
                for j in 0..2 {
                    let tol = 1e-9 * (1.0 + h.x[j].abs());
                    assert!(
                        (x[j] - h.x[j]).abs() < tol,
                        "{} k={k} x[{j}]: {} vs {}",
                        ests[i].name(),
                        x[j],
                        h.x[j]
                    );
                }
                for j in 0..4 {
                    let want = h.p[(j / 2, j % 2)];
                    assert!(
                        (p[j] - want).abs() < 1e-9 * h.p.amax(),
                        "{} k={k} P[{j}]: {} vs {want}",
                        ests[i].name(),
                        p[j]
                    );
                }
            }
        }
    }
    // The channel exercised every case: one node delivered, both delivered.
    assert!(only_one > 100 && both > 100, "{only_one} {both}");
}

/// `eval --config` over the file: both nodes counted, kf and ikf evaluated, ikf between the
/// full-information kf and what a position-only filter could do.
#[test]
fn eval_runs_sensors_of_different_ny() {
    let dir = std::env::temp_dir().join(format!("ipc-runner-mixed-ny-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("e.json");
    let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args([
            "eval",
            "--config",
            file().to_str().unwrap(),
            "--runs",
            "200",
            "--seed",
            "2",
        ])
        .args(["--quiet", "--json", json.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let nodes = r["channel"]["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 2);
    for n in nodes {
        assert_eq!(n["instants"], 200 * 100);
    }
    let avg = |n: &str| r["estimators"][n]["avg_mse"].as_f64().unwrap();
    assert!(
        avg("kf") < avg("ikf"),
        "kf {} ikf {}",
        avg("kf"),
        avg("ikf")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The Tobit fusion filters need one ny for every node: a Tobit-fusion scenario whose
/// sensors differ is refused with one line saying so, nothing panics.
#[test]
fn tobit_fusion_refuses_sensors_of_different_ny() {
    let dir =
        std::env::temp_dir().join(format!("ipc-runner-mixed-ny-tobit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tobit-mixed.toml");
    let text = std::fs::read_to_string(file()).unwrap().replace(
        "[[stages]]\nkind = \"bernoulli\"\np_loss = 0.3\n",
        "[[stages]]\nkind = \"tobit\"\nthresholds = [[0.0, 0.0], [0.0]]\n\n\
         [[stages]]\nkind = \"event-trigger\"\ninitial_tokens = 3\nrate = 2\ncapacity = 6\n\
         [[stages.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = 0.5\neta0 = 1.0\n\
         reference = [0.0, 0.0]\ncost = 1\n\
         [[stages.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = 0.5\neta0 = 1.0\n\
         reference = [0.0]\ncost = 1\n",
    );
    assert!(text.contains("event-trigger"));
    std::fs::write(&path, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args([
            "eval",
            "--config",
            path.to_str().unwrap(),
            "--runs",
            "2",
            "--quiet",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("same n_y at every node"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
