//! An estimator spec written by hand (`specs/linear.toml`: the model, the prior, no
//! simulation section) configures the runner exactly as the scenario does. A channel-sim
//! publisher of the `linear` preset is accepted by `run --estimator-spec` (the stream header's
//! model fingerprint is the spec's, and the file's equals the preset's), and every estimate is
//! bit for bit the scenario-configured run's; `replay` agrees the same way. A spec of another
//! model is refused at the first slot with the contract's one line (exit code 2).

#[path = "pipeline_common.rs"]
mod common;

use common::{csv, prefix, scratch, start_channel_sim, Proc};
use std::path::{Path, PathBuf};

const STEPS: u32 = 300;

/// A spec file of the repository (`specs/`).
fn spec_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../specs")
        .join(name)
}

/// The hand-written files describe the presets exactly: the same fingerprint, nodes,
/// dimensions and, field by field, the same spec (the name aside).
#[test]
fn the_spec_files_are_the_presets_estimator_specs() {
    for name in ["linear", "occlusion"] {
        let file = estpipe_spec::file::load(&spec_file(&format!("{name}.toml"))).unwrap();
        let preset = channel_sim::scenario::preset(name)
            .unwrap()
            .estimator_spec();
        assert_eq!(*file, *preset, "{name}");
        assert_eq!(file.fingerprint(), preset.fingerprint(), "{name}");
        assert_eq!(file.stream_header(), preset.stream_header(), "{name}");
    }
    // The truth's distribution and a random-loss stage are not the estimators' business: the
    // `linear` preset (20 % Bernoulli loss) has the fingerprint of its spec without them.
    let linear = channel_sim::scenario::preset("linear").unwrap();
    assert_eq!(
        channel_sim::wire::stream_header(&*linear).model,
        estpipe_spec::file::load(&spec_file("linear.toml"))
            .unwrap()
            .fingerprint()
    );
}

/// `run` on a fresh prefix fed by a channel-sim publisher of the `linear` preset, configured by
/// `config` (`--scenario linear` or `--estimator-spec FILE`): its estimates CSV, slot log and
/// report.
fn run(dir: &Path, tag: &str, config: &[&str]) -> (PathBuf, PathBuf, serde_json::Value) {
    let p = prefix(&format!("spec-{tag}"));
    let (est, slots, json) = (
        dir.join(format!("{tag}-estimates.csv")),
        dir.join(format!("{tag}-slots.csv")),
        dir.join(format!("{tag}.json")),
    );
    let steps = STEPS.to_string();
    let mut args = vec!["run"];
    args.extend_from_slice(config);
    args.extend_from_slice(&[
        "--prefix",
        &p,
        "--steps",
        &steps,
        "--buffer",
        "4096",
        "--estimates-csv",
        est.to_str().unwrap(),
        "--slots-csv",
        slots.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let mut runner = Proc::start(dir, &format!("runner-{tag}"), &args);
    runner.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = start_channel_sim(dir, &p, "linear", STEPS, 0);
    assert!(publ.wait(60).success(), "publisher: {}", publ.err());
    let status = runner.wait(60);
    assert!(
        status.success(),
        "runner {tag}: {status:?} {}",
        runner.err()
    );
    (est, slots, common::report(&json))
}

#[test]
fn a_hand_written_spec_gives_the_scenario_runs_estimates_bit_for_bit() {
    let dir = scratch("spec-run");
    let spec = spec_file("linear.toml");
    let (a_est, a_slots, a) = run(&dir, "scenario", &["--scenario", "linear"]);
    let (b_est, b_slots, b) = run(&dir, "spec", &["--estimator-spec", spec.to_str().unwrap()]);
    // The same stream both times (channel-sim's linear preset, seed 0, lossless at --rate 0).
    assert_eq!(
        std::fs::read_to_string(&a_slots).unwrap(),
        std::fs::read_to_string(&b_slots).unwrap()
    );
    let ((ha, ra), (hb, rb)) = (csv(&a_est), csv(&b_est));
    assert_eq!(ha, hb);
    assert!(ha.iter().any(|h| h.starts_with("ikf")), "{ha:?}");
    assert_eq!(ra.len(), STEPS as usize);
    // Bit for bit: every estimate column (and the truth column the CSV carries alike).
    for (x, y) in ra.iter().zip(&rb) {
        for (u, v) in x.iter().zip(y) {
            assert!(
                u.to_bits() == v.to_bits() || (u.is_nan() && v.is_nan()),
                "{x:?} vs {y:?}"
            );
        }
    }
    assert_eq!(a["instants"], b["instants"]);
    assert_eq!(b["scenario"], "linear");

    // replay: the slot log through the spec and through the scenario, the same estimates.
    let out = |tag: &str, config: &[&str]| {
        let path = dir.join(format!("replay-{tag}.csv"));
        let mut args = vec!["replay", "--input", a_slots.to_str().unwrap()];
        args.extend_from_slice(config);
        args.extend_from_slice(&["--output", path.to_str().unwrap()]);
        let mut r = Proc::start(&dir, &format!("replay-{tag}"), &args);
        assert!(r.wait(60).success(), "replay {tag}: {}", r.err());
        std::fs::read_to_string(path).unwrap()
    };
    assert_eq!(
        out("scenario", &["--scenario", "linear"]),
        out("spec", &["--estimator-spec", spec.to_str().unwrap()])
    );
}

/// A spec whose model differs from the stream's (the occlusion spec against the `linear`
/// preset's publisher) is refused at the first slot with one line, exit code 2.
#[test]
fn a_spec_of_another_model_is_refused() {
    let dir = scratch("spec-refused");
    let p = prefix("spec-refused");
    let spec = spec_file("occlusion.toml");
    let mut runner = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--estimator-spec",
            spec.to_str().unwrap(),
            "--prefix",
            &p,
            "--steps",
            "20",
        ],
    );
    runner.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = start_channel_sim(&dir, &p, "linear", 20, 0);
    let status = runner.wait(60);
    let _ = publ.wait(30);
    assert_eq!(status.code(), Some(2), "{}", runner.err());
    let err = runner.err();
    assert!(err.contains("model") || err.contains("shape"), "{err}");
}

/// A bad spec file is one line naming the file and the field, exit code 2, before anything
/// is opened.
#[test]
fn a_bad_spec_file_is_one_line_naming_the_field() {
    let dir = scratch("spec-bad");
    let bad = dir.join("bad.toml");
    let text = std::fs::read_to_string(spec_file("linear.toml"))
        .unwrap()
        .replace(
            "q = [[0.01, 0.0], [0.0, 0.04]]",
            "q = [[0.01, 0.0], [0.0, -0.04]]",
        );
    std::fs::write(&bad, text).unwrap();
    let mut r = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--estimator-spec",
            bad.to_str().unwrap(),
            "--prefix",
            &prefix("spec-bad"),
        ],
    );
    let status = r.wait(30);
    assert_eq!(status.code(), Some(2), "{}", r.err());
    let err = r.err();
    let line = err
        .lines()
        .find(|l| l.contains("model.q"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(line.contains("bad.toml"), "{line}");
}
