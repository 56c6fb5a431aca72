//! Hostile scenario files (issue 20): every bad TOML, through `ipc-runner eval --config` and
//! the publisher (`ipc-runner channel-sim --config`, the code `demo` starts; and the
//! `channel-sim` executable when it has been built beside this one), exits with code 2 and
//! one line on stderr that names the file and the field, and nothing panics. Stages that do
//! not fit the plant (node counts, vector lengths) and finite numbers whose products overflow
//! f64 are refused when the file is read, instead of "NaN, 20/20 runs diverged" or a later
//! exit code 1.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const EXAMPLE: &str = include_str!("../../channel-sim/scenarios/example.toml");
const TWO_SENSORS: &str = include_str!("../../channel-sim/scenarios/two-sensors.toml");

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("ipc-runner-hostile-toml-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Two triggered nodes sharing a bucket (seed 004), with `nodes` and `reference` as given.
fn trigger(nodes: usize, reference: &str) -> String {
    let mut s = String::from(
        "\n[[stages]]\nkind = \"event-trigger\"\ninitial_tokens = 3\nrate = 2\ncapacity = 6\n",
    );
    for _ in 0..nodes {
        s += &format!(
            "[[stages.nodes]]\nsigma = 0.5\nchi = 5.0\nlambda = 0.5\neta0 = 1.0\n\
             reference = {reference}\ncost = 1\n"
        );
    }
    s
}

fn occlusion(body: &str) -> String {
    format!("\n[[stages]]\nkind = \"occlusion\"\n{body}\n")
}

/// (case, file text, the field its error must name).
fn cases() -> Vec<(&'static str, String, &'static str)> {
    let ex = |from: &str, to: &str| {
        assert!(EXAMPLE.contains(from), "example has no {from:?}");
        EXAMPLE.replacen(from, to, 1)
    };
    let plus = |extra: &str| format!("{EXAMPLE}{extra}");
    let a = "a = [[0.95, 0.10], [-0.10, 0.95]]";
    let q = "q = [[0.01, 0.0], [0.0, 0.04]]";
    let cov = "cov = [[1.0, 0.0], [0.0, 1.0]]";
    vec![
        // Stages that do not fit the plant (two sensors, ny = 1 each).
        ("trigger with 3 nodes", plus(&trigger(3, "[0.0]")), "stages[2].nodes"),
        ("trigger with 1 node", plus(&trigger(1, "[0.0]")), "stages[2].nodes"),
        ("trigger reference of ny 2", plus(&trigger(2, "[0.0, 0.0]")), "stages[2].nodes[0].reference"),
        ("tobit for 3 nodes", plus("\n[[stages]]\nkind = \"tobit\"\nthresholds = [[0.0], [0.0], [0.0]]\n"), "stages[2].thresholds"),
        ("tobit thresholds of ny 2", plus("\n[[stages]]\nkind = \"tobit\"\nthresholds = [[0.0, 1.0], [0.0, 1.0]]\n"), "stages[2].thresholds[0]"),
        (
            "tobit thresholds for the wrong node's ny",
            format!("{TWO_SENSORS}\n[[stages]]\nkind = \"tobit\"\nthresholds = [[0.0], [0.0, 0.0]]\n"),
            "stages[1].thresholds[0]",
        ),
        // Finite numbers that overflow f64 in the model's first products.
        ("1e308 in A", ex(a, "a = [[1e308, 0.10], [-0.10, 0.95]]"), "model.a"),
        ("1e200 in A (A P Aᵀ overflows)", ex(a, "a = [[1e200, 0.10], [-0.10, 0.95]]"), "model.a"),
        ("1e308 in C", ex("c = [[1.0, 0.0]]", "c = [[1e308, 0.0]]"), "sensors[0].c"),
        ("1e160 in C (C P Cᵀ overflows)", ex("c = [[1.0, 0.0]]", "c = [[1e160, 0.0]]"), "sensors[0].c"),
        ("1e308 in Q", ex(q, "q = [[1e308, 0.0], [0.0, 0.04]]"), "model.q"),
        ("1e308 in R", ex("r = [[0.25]]", "r = [[1e308]]"), "sensors[0].r"),
        ("cov = 1e308·I", ex(cov, "cov = [[1e308, 0.0], [0.0, 1e308]]"), "initial.cov"),
        ("1e308 in the mean", ex("mean = [0.0, 0.0]", "mean = [1e308, 0.0]"), "initial.mean"),
        ("1e155 in B (B Q Bᵀ overflows)", ex("b = [[1.0, 0.0], [0.0, 1.0]]", "b = [[1e155, 0.0], [0.0, 1.0]]"), "model.b"),
        ("nan in A", ex(a, "a = [[nan, 0.10], [-0.10, 0.95]]"), "model.a"),
        ("inf in R", ex("r = [[0.25]]", "r = [[inf]]"), "sensors[0].r"),
        // Shapes.
        (
            "c with 9 rows",
            ex("c = [[1.0, 0.0]]", &format!("c = [{}]", ["[1.0, 0.0]"; 9].join(", "))),
            "sensors[0].c",
        ),
        ("c with 3 columns", ex("c = [[1.0, 0.0]]", "c = [[1.0, 0.0, 0.0]]"), "sensors[0].c"),
        ("9 sensors", format!("{EXAMPLE}{}", "\n[[sensors]]\nc = [[1.0, 0.0]]\nr = [[1.0]]\n".repeat(7)), "sensors"),
        // Occlusion regions.
        ("occlusion e of the wrong length", plus(&occlusion("e = [1.0]\npsi = 0.1\ncentres = [1.0]\nradii = [0.5]")), "stages[2].e"),
        ("5 occlusion regions", plus(&occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = [1.0, 3.0, 5.0, 7.0, 9.0]\nradii = [0.5, 0.5, 0.5, 0.5, 0.5]")), "stages[2].centres"),
        ("occlusion radii count", plus(&occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = [1.0, 3.0]\nradii = [0.5]")), "stages[2].radii"),
        ("overlapping regions", plus(&occlusion("e = [1.0, 0.0]\npsi = 0.1\ncentres = [1.0, 1.5]\nradii = [0.5, 0.5]")), "stages[2].regions"),
        ("negative psi", plus(&occlusion("e = [1.0, 0.0]\npsi = -0.1\ncentres = [1.0]\nradii = [0.5]")), "stages[2].psi"),
        // Control input.
        ("control b with 3 rows", plus("\n[control]\nb = [[1.0], [0.0], [0.0]]\nu = { kind = \"constant\", value = [1.0] }\n"), "control.b"),
        ("control u of the wrong length", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"constant\", value = [1.0, 2.0] }\n"), "control.u.value"),
        ("control period 0", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"sinusoid\", amplitude = [1.0], period = 0.0 }\n"), "control.u.period"),
        ("empty control list", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"list\", values = [] }\n"), "control.u.values"),
        ("control u of 1e308", plus("\n[control]\nb = [[1.0], [0.0]]\nu = { kind = \"constant\", value = [1e308] }\n"), "control.u"),
        // The parser's own errors name the line and the field.
        ("unknown field", ex("p_loss = 0.1", "p_los = 0.1"), "p_los"),
        ("negative token count", plus(&trigger(2, "[0.0]").replace("initial_tokens = 3", "initial_tokens = -3")), "initial_tokens"),
        ("not TOML", "a = [[".to_string(), "line 1"),
    ]
}

fn ipc_runner(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args(args)
        .env("IOX2_LOG_LEVEL", "Error")
        .output()
        .expect("start ipc-runner")
}

/// Exit code 2, one line naming the file and `field`, no panic.
fn refused(what: &str, out: &Output, file: &Path, field: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: not one line: {err:?}");
    assert!(
        err.contains(file.to_str().unwrap()),
        "{what}: file not named: {err}"
    );
    assert!(err.contains(field), "{what}: {field:?} not in {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert!(!err.contains("must be 9×2"), "{what}: {err}");
}

#[test]
fn every_bad_file_is_refused_with_one_line_naming_the_file_and_the_field() {
    let dir = dir();
    // The channel-sim executable, when a workspace build put it beside this one.
    let channel_sim = Path::new(env!("CARGO_BIN_EXE_ipc-runner")).with_file_name("channel-sim");
    let mut standalone = 0;
    for (i, (what, text, field)) in cases().into_iter().enumerate() {
        let file = dir.join(format!("case-{i}.toml"));
        std::fs::write(&file, &text).unwrap();
        let f = file.to_str().unwrap();
        let eval = ipc_runner(&["eval", "--config", f, "--runs", "2", "--quiet"]);
        refused(&format!("eval: {what}"), &eval, &file, field);
        let prefix = format!("hostile-toml-{}-{i}", std::process::id());
        let publ = ipc_runner(&[
            "channel-sim",
            "--config",
            f,
            "--prefix",
            &prefix,
            "--steps",
            "1",
            "--quiet",
        ]);
        refused(
            &format!("ipc-runner channel-sim: {what}"),
            &publ,
            &file,
            field,
        );
        if channel_sim.exists() {
            let out = Command::new(&channel_sim)
                .args([
                    "--config", f, "--prefix", &prefix, "--steps", "1", "--quiet",
                ])
                .output()
                .unwrap();
            refused(&format!("channel-sim: {what}"), &out, &file, field);
            standalone += 1;
        }
    }
    eprintln!(
        "{} cases; the channel-sim executable checked on {standalone}",
        cases().len()
    );
    // A missing file: named, code 2.
    let missing = dir.join("missing.toml");
    refused(
        "missing file",
        &ipc_runner(&["eval", "--config", missing.to_str().unwrap()]),
        &missing,
        "missing.toml",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The two-sensor file and the example are accepted (the checks refuse only what is wrong).
#[test]
fn the_shipped_files_pass_the_checks() {
    for (name, text) in [("example", EXAMPLE), ("two-sensors", TWO_SENSORS)] {
        assert!(
            channel_sim::scenario::config::parse(text, name, name).is_ok(),
            "{name}"
        );
    }
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios");
    for entry in std::fs::read_dir(scenarios).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            channel_sim::scenario::config::load(&path).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}
