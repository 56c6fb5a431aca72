//! TOML scenarios that use what the presets use: occlusion regions (seed 001) on a user's own
//! model, through `ipc-runner eval --config` as a user runs it.

use std::path::{Path, PathBuf};
use std::process::Command;

fn ipc_runner(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args(args)
        .output()
        .expect("start ipc-runner")
}

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios")
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "ipc-runner-toml-scenarios-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `eval` with `args` and `--json` into `dir/name.json`: the parsed report.
fn eval_json(dir: &Path, name: &str, args: &[&str]) -> serde_json::Value {
    let json = dir.join(format!("{name}.json"));
    let mut all = vec!["eval", "--json", json.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = ipc_runner(&all);
    assert!(
        out.status.success(),
        "eval {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
}

/// `channel-sim/scenarios/occlusion.toml` is the `occlusion` preset written as a file: the
/// same seed gives the same numbers for every estimator (the occlusion family and its `-mix`
/// variants, `ikf`, `kf`, `pf` and `pf-mix`), bit for bit, and the same channel; only the
/// scenario's name differs. The model fingerprints agree too (a stream of one is accepted
/// by a runner of the other).
#[test]
fn the_occlusion_preset_as_toml_gives_the_presets_numbers() {
    let dir = temp_dir("preset");
    let file = scenarios().join("occlusion.toml");
    let common = [
        "--runs",
        "40",
        "--steps",
        "100",
        "--seed",
        "11",
        "--loss-rate",
        "0.1",
        "--particles",
        "300",
    ];
    let preset = eval_json(
        &dir,
        "preset",
        &[&["--scenario", "occlusion"], &common[..]].concat(),
    );
    let toml = eval_json(
        &dir,
        "toml",
        &[&["--config", file.to_str().unwrap()], &common[..]].concat(),
    );
    let names: Vec<&String> = preset["estimators"].as_object().unwrap().keys().collect();
    for want in [
        "kf",
        "ikf",
        "cce",
        "kf-io",
        "adf",
        "cce-mix",
        "kf-io-mix",
        "adf-mix",
        "pf",
        "pf-mix",
    ] {
        assert!(names.iter().any(|n| *n == want), "{want} not in {names:?}");
    }
    assert_eq!(preset["estimators"], toml["estimators"]);
    assert_eq!(preset["channel"], toml["channel"]);
    assert_eq!(preset["scenario"], "occlusion");
    assert_eq!(toml["scenario"], "occlusion-toml");

    let header = |args: &[&str]| {
        let out = ipc_runner(&[&["stream-header"], args].concat());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v["model"].clone()
    };
    let fp = header(&["--scenario", "occlusion"]);
    assert!(!fp.is_null());
    assert_eq!(fp, header(&["--config", file.to_str().unwrap()]));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A user's own two-state model with two occlusion bands: the occlusion estimators apply
/// (cce, kf-io, adf and with a loss rate their -mix variants), the channel drops packets in
/// the bands, every estimator's MSE is finite, and `adf`, which reads each dropout as "in a
/// band", beats `ikf`, which ignores what a dropout says (a paired comparison over 400 runs
/// with a fixed seed; on this model the gap is several times its noise).
#[test]
fn a_user_model_with_regions_runs_the_occlusion_estimators() {
    let dir = temp_dir("user");
    let file = scenarios().join("occlusion-user.toml");
    let r = eval_json(
        &dir,
        "user",
        &[
            "--config",
            file.to_str().unwrap(),
            "--runs",
            "400",
            "--steps",
            "100",
            "--seed",
            "5",
            "--loss-rate",
            "0.05",
        ],
    );
    assert_eq!(r["scenario"], "occlusion-user");
    let est = r["estimators"].as_object().unwrap();
    for want in [
        "ikf",
        "cce",
        "kf-io",
        "adf",
        "cce-mix",
        "kf-io-mix",
        "adf-mix",
    ] {
        let e = est
            .get(want)
            .unwrap_or_else(|| panic!("{want} missing: {:?}", est.keys()));
        let mse = e["mse"].as_array().unwrap();
        assert_eq!(mse.len(), 101, "{want}: k = 0..=100");
        assert!(
            mse.iter().all(|v| v.as_f64().unwrap().is_finite()),
            "{want}"
        );
        assert_eq!(e["diverged_runs"], 0, "{want}");
    }
    let node = &r["channel"]["nodes"][0];
    let (delivered, dropped) = (
        node["delivered"].as_u64().unwrap(),
        node["dropped"].as_u64().unwrap(),
    );
    assert_eq!(delivered + dropped, 400 * 100);
    assert!(dropped > 2000 && delivered > 2000, "{node}");
    let avg = |n: &str| est[n]["avg_mse"].as_f64().unwrap();
    assert!(
        avg("adf") < avg("ikf"),
        "adf {} ikf {}",
        avg("adf"),
        avg("ikf")
    );
    let _ = std::fs::remove_dir_all(&dir);
}
