//! `ipc_latency` works end to end: both transports, both schedules, a JSON per mode with
//! every round counted, and nothing left behind. No timing is asserted except the lower bound
//! that pacing itself guarantees.

use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Instant;

const BIN: &str = env!("CARGO_BIN_EXE_ipc_latency");

/// Runs `ipc_latency`; returns its output, wall time and pid.
fn run(args: &[&str]) -> (std::process::Output, f64, u32) {
    let t = Instant::now();
    let child = Command::new(BIN)
        .args(args)
        .env("IOX2_LOG_LEVEL", "Error")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn ipc_latency");
    let pid = child.id();
    let out = child.wait_with_output().expect("ipc_latency output");
    (out, t.elapsed().as_secs_f64(), pid)
}

fn check_mode(v: &Value, mode: &str, samples: u64) {
    for dir in ["one_way", "round_trip"] {
        let p = &v[mode][dir];
        assert_eq!(p["count"].as_u64(), Some(samples), "{mode} {dir}: {p}");
        let q: Vec<f64> = ["p50_us", "p90_us", "p99_us", "p999_us", "max_us"]
            .iter()
            .map(|k| p[k].as_f64().expect("percentile"))
            .collect();
        assert!(q[0] > 0.0, "{mode} {dir}: {p}");
        assert!(q.windows(2).all(|w| w[0] <= w[1]), "{mode} {dir}: {p}");
    }
    // One way is part of the round trip.
    assert!(v[mode]["one_way"]["p50_us"].as_f64() <= v[mode]["round_trip"]["p50_us"].as_f64());
}

#[test]
fn paced_run_of_both_transports_counts_every_round_and_cleans_up() {
    let json = std::env::temp_dir().join(format!("ipc-latency-test-{}.json", std::process::id()));
    let (samples, warmup, rate) = (1500u64, 100u64, 5000.0);
    let (out, secs, pid) = run(&[
        "--samples",
        &samples.to_string(),
        "--warmup",
        &warmup.to_string(),
        "--rate",
        &rate.to_string(),
        "--modes",
        "iox-spin,uds-block",
        "--json",
        json.to_str().expect("utf-8 path"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("JSON written")).unwrap();
    let _ = std::fs::remove_file(&json);
    check_mode(&v, "iox-spin", samples);
    check_mode(&v, "uds-block", samples);
    // Paced: ping i is not sent before i / rate, in each of the two modes.
    let floor = 2.0 * (samples + warmup - 1) as f64 / rate;
    assert!(secs >= floor, "{secs} s < {floor} s: not paced");
    // The socket file carries the parent's pid and must not survive the run.
    for block in 0..2 {
        let sock = std::env::temp_dir().join(format!("benches-ipc-{pid}-{block}.sock"));
        assert!(!sock.exists(), "{sock:?} left behind");
    }
}

#[test]
fn bad_arguments_are_refused_with_a_message() {
    for (args, msg) in [
        (&["--rate", "-1"][..], "--rate must be"),
        (&["--rate", "NaN"][..], "--rate must be"),
        (&["--modes", "carrier-pigeon"][..], "unknown mode"),
        (&["--samples", "0"][..], "--samples must be positive"),
    ] {
        let (out, _, _) = run(args);
        assert!(!out.status.success(), "{args:?} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(msg), "{args:?}: {err}");
    }
}
