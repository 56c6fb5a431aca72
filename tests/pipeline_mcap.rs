//! `--mcap FILE` (docs/mcap.md): a 2000-instant `demo` and a `replay` of its slot log written
//! as MCAP, read back with the `mcap` crate and compared with the run's CSV files: every
//! channel's message count, and the values (x̂, truth, measurements) bit for bit. The same
//! files read by the `mcap` PyPI package (`$ESTPIPE_PYTHON`, pinned in
//! `clients/python/requirements.txt`) give the same counts; without it that part says so on
//! one line.

mod pipeline_common;
#[path = "skip_log.rs"]
mod skip_log;

use pipeline_common as common;
use pipeline_common::{csv, scratch, Proc};
use std::collections::BTreeMap;
use std::path::Path;

/// Per topic, the messages' JSON in file order; every array of numbers also under
/// `"<key>_exact"`, parsed from the text by `str::parse` (serde_json's own float parsing is
/// not correctly rounded without its `float_roundtrip` feature, so the last bit may differ).
fn read_mcap(path: &Path) -> BTreeMap<String, Vec<serde_json::Value>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "json");
        let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let text = std::str::from_utf8(&m.data).unwrap();
        for key in ["x", "y", "p", "sigma"] {
            if let Some(a) = exact_array(text, key) {
                v[format!("{key}_exact")] =
                    serde_json::json!(a.iter().map(|x| x.map(f64::to_bits)).collect::<Vec<_>>());
            }
        }
        out.entry(m.channel.topic.clone()).or_default().push(v);
    }
    out
}

/// The numbers of the array `"key":[…]` in `text`, exactly (`None` for `null`).
fn exact_array(text: &str, key: &str) -> Option<Vec<Option<f64>>> {
    let start = text.find(&format!("\"{key}\":["))? + key.len() + 4;
    let end = start + text[start..].find(']')?;
    let body = &text[start..end];
    if body.is_empty() {
        return Some(Vec::new());
    }
    Some(body.split(',').map(|s| s.parse::<f64>().ok()).collect())
}

/// Entry `j` of the exact array `key` of message `m` (NaN for `null`).
fn exact(m: &serde_json::Value, key: &str, j: usize) -> f64 {
    m[format!("{key}_exact")][j]
        .as_u64()
        .map_or(f64::NAN, f64::from_bits)
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The per-topic counts the `mcap` PyPI package reads, or `None` when it is not installed.
fn python_counts(path: &Path) -> Option<BTreeMap<String, usize>> {
    let py = std::env::var("ESTPIPE_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = "import sys, json, collections\n\
                  from mcap.reader import make_reader\n\
                  c = collections.Counter()\n\
                  with open(sys.argv[1], 'rb') as f:\n\
                  \x20   for schema, channel, message in make_reader(f).iter_messages():\n\
                  \x20       json.loads(message.data)\n\
                  \x20       c[channel.topic] += 1\n\
                  print(json.dumps(c))\n";
    let ok = std::process::Command::new(&py)
        .args(["-c", "import mcap.reader"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("ESTPIPE_PYTHON").is_none(),
            "ESTPIPE_PYTHON={py} cannot import mcap.reader"
        );
        skip_log::skipped(
            &skip_log::current_test("python_reader"),
            &format!(
                "(the Python MCAP reader part) `{py} -c \"import mcap.reader\"` fails (pip \
                 install -r clients/python/requirements.txt, or point ESTPIPE_PYTHON at such an \
                 interpreter)"
            ),
        );
        return None;
    }
    let o = std::process::Command::new(&py)
        .args(["-c", script])
        .arg(path)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    Some(serde_json::from_slice(&o.stdout).unwrap())
}

fn counts(m: &BTreeMap<String, Vec<serde_json::Value>>) -> BTreeMap<String, usize> {
    m.iter().map(|(t, v)| (t.clone(), v.len())).collect()
}

/// The estimators of a CSV header with `<est>_<j>` columns after `skip` others.
fn estimator_names(head: &[String], skip: usize, nx: usize) -> Vec<String> {
    head[skip..]
        .chunks(nx)
        .map(|c| c[0].trim_end_matches("_0").to_string())
        .collect()
}

/// Every `/estimates/<name>` message equals the CSV's row of its instant, bit for bit, and
/// its σ is √ of the diagonal of its covariance.
fn check_estimates(
    mcap: &BTreeMap<String, Vec<serde_json::Value>>,
    head: &[String],
    rows: &[Vec<f64>],
    k_col: usize,
    first_est_col: usize,
    nx: usize,
) {
    for (e, name) in estimator_names(head, first_est_col, nx).iter().enumerate() {
        let msgs = &mcap[&format!("/estimates/{name}")];
        assert_eq!(msgs.len(), rows.len(), "{name}: messages vs CSV rows");
        for (m, row) in msgs.iter().zip(rows) {
            assert_eq!(f(&m["k"]), row[k_col], "{name}");
            assert_eq!(m["estimator"], name.as_str());
            for j in 0..nx {
                let csv_v = row[first_est_col + e * nx + j];
                let v = exact(m, "x", j);
                assert!(
                    v.to_bits() == csv_v.to_bits() || (v.is_nan() && csv_v.is_nan()),
                    "{name} k {} x[{j}]: mcap {v} csv {csv_v}",
                    row[k_col]
                );
                let (s, p) = (exact(m, "sigma", j), exact(m, "p", j * nx + j));
                assert!(
                    s.is_nan() && p.is_nan() || s == p.sqrt(),
                    "{name}: σ {s} P {p}"
                );
            }
            assert_eq!(m["p"].as_array().unwrap().len(), nx * nx);
        }
    }
}

/// The `/slots` channel against the slot log: one message per node and instant, the
/// delivered ones equal to the log's rows (k, node, y).
fn check_slots(msgs: &[serde_json::Value], log: &Path, instants: usize, nodes: usize) {
    assert_eq!(msgs.len(), instants * nodes, "slots: instants × nodes");
    let (head, rows) = csv(log);
    let ny = head.iter().filter(|h| h.starts_with("y_")).count();
    let delivered: Vec<&Vec<f64>> = rows.iter().filter(|r| r[2] == 1.0).collect();
    let m_delivered: Vec<&serde_json::Value> =
        msgs.iter().filter(|m| m["status"] == "delivered").collect();
    assert_eq!(m_delivered.len(), delivered.len(), "delivered slots");
    for (m, r) in m_delivered.iter().zip(&delivered) {
        assert_eq!((f(&m["k"]), f(&m["node"])), (r[0], r[1]));
        let y = m["y"].as_array().unwrap();
        for (j, v) in y.iter().enumerate().take(ny) {
            assert!(!f(v).is_nan(), "k {} y[{j}]", r[0]);
            assert_eq!(
                exact(m, "y", j).to_bits(),
                r[4 + j].to_bits(),
                "k {} y[{j}]",
                r[0]
            );
        }
    }
    // Not delivered: dropped by the channel, or lost (never in the slot log).
    let logged_dropped = rows.iter().filter(|r| r[2] == 0.0).count();
    let dropped = msgs.iter().filter(|m| m["status"] == "dropped").count();
    let lost = msgs.iter().filter(|m| m["status"] == "lost").count();
    assert_eq!(dropped, logged_dropped, "dropped by the channel");
    // The log has no row for a slot the runner never had.
    assert_eq!(lost, instants * nodes - rows.len(), "lost");
}

/// A 2000-instant demo at full speed with `--mcap`, then `replay --mcap` of its slot log: the
/// counts and values equal the CSV files', in Rust and in Python.
#[test]
fn demo_and_replay_mcap_equal_their_csv() {
    let dir = scratch("mcap");
    let out = dir.join("out");
    let file = dir.join("demo.mcap");
    let (steps, nx, nodes) = (2000usize, 3usize, 1usize);
    let prefix = common::prefix("mcap");
    let mut demo = Proc::start(
        &dir,
        "demo",
        &[
            "demo",
            "--steps",
            &steps.to_string(),
            "--rate",
            "0",
            "--wait",
            "block",
            "--prefix",
            &prefix,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
            "--mcap",
            file.to_str().unwrap(),
        ],
    );
    let status = demo.wait(300);
    assert!(status.success(), "demo: {status}\n{}", demo.err());

    let mcap = read_mcap(&file);
    let (head, rows) = csv(&out.join("estimates.csv"));
    assert_eq!(rows.len(), steps);
    // session, k, truth_0.., then the estimators.
    check_estimates(&mcap, &head, &rows, 1, 2 + nx, nx);
    let truth_rows: Vec<&Vec<f64>> = rows.iter().filter(|r| !r[2].is_nan()).collect();
    let truth = &mcap["/truth"];
    assert_eq!(
        truth.len(),
        truth_rows.len(),
        "truth messages vs CSV rows with truth"
    );
    for (m, r) in truth.iter().zip(&truth_rows) {
        assert_eq!(f(&m["k"]), r[1]);
        for j in 0..nx {
            assert_eq!(exact(m, "x", j).to_bits(), r[2 + j].to_bits());
        }
    }
    check_slots(&mcap["/slots"], &out.join("slots.csv"), steps, nodes);
    let names = estimator_names(&head, 2 + nx, nx);
    assert_eq!(mcap.len(), 2 + names.len(), "{:?}", mcap.keys());
    if let Some(py) = python_counts(&file) {
        assert_eq!(py, counts(&mcap), "the Python reader's counts");
    }

    // The replay of the slot log: no truth, the same slots, the replay's estimates.
    let rfile = dir.join("replay.mcap");
    let rcsv = dir.join("replay.csv");
    let mut replay = Proc::start(
        &dir,
        "replay",
        &[
            "replay",
            "--input",
            out.join("slots.csv").to_str().unwrap(),
            "--output",
            rcsv.to_str().unwrap(),
            "--mcap",
            rfile.to_str().unwrap(),
        ],
    );
    let status = replay.wait(120);
    assert!(status.success(), "replay: {status}\n{}", replay.err());
    let rm = read_mcap(&rfile);
    let (rhead, rrows) = csv(&rcsv);
    assert_eq!(rrows.len(), steps);
    check_estimates(&rm, &rhead, &rrows, 0, 1, nx);
    assert!(!rm.contains_key("/truth"));
    check_slots(&rm["/slots"], &out.join("slots.csv"), steps, nodes);
    if let Some(py) = python_counts(&rfile) {
        assert_eq!(py, counts(&rm), "the Python reader's counts (replay)");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An `--mcap` path that cannot be written is refused before the run starts, in one line
/// (exit 2), as the other outputs.
#[test]
fn unwritable_mcap_is_refused_before_the_run() {
    let dir = scratch("mcap-bad");
    let mut run = Proc::start(
        &dir,
        "run",
        &[
            "run",
            "--prefix",
            &common::prefix("mcap-bad"),
            "--mcap",
            "/nonexistent-dir/run.mcap",
        ],
    );
    let status = run.wait(30);
    assert_eq!(status.code(), Some(2), "{}", run.err());
    let err = run.err();
    assert!(err.contains("--mcap"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
