//! `zenoh_latency` (the raw zenoh baseline of the report's `bridge` part) works end to end:
//! two processes over TCP on loopback, every message received once and in order, counts that
//! add up, the report's JSON shape. No timing is asserted except the lower bound that pacing
//! itself guarantees.

use serde_json::Value;
use std::process::Command;
use std::time::Instant;

const BIN: &str = env!("CARGO_BIN_EXE_zenoh_latency");

fn run(args: &[&str]) -> (Value, f64) {
    let t = Instant::now();
    let out = Command::new(BIN)
        .args(args)
        .arg("--json")
        .output()
        .expect("run zenoh_latency");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    (v, t.elapsed().as_secs_f64())
}

fn check(v: &Value, samples: u64, warmup: u64) {
    let u = |k: &str| v[k].as_u64().unwrap_or_else(|| panic!("{k} in {v}"));
    assert_eq!(u("payload_bytes"), 156, "{v}");
    assert_eq!(u("sent"), samples + warmup, "{v}");
    assert_eq!(u("received"), u("sent"), "{v}");
    assert_eq!(u("lost"), 0, "{v}");
    assert_eq!(u("refused"), 0, "{v}");
    assert_eq!(u("out_of_order"), 0, "{v}");
    assert_eq!(u("measured"), samples, "{v}");
    let p = &v["one_way"];
    assert_eq!(p["count"].as_u64(), Some(samples), "{v}");
    let q: Vec<f64> = ["p50_us", "p90_us", "p99_us", "p999_us", "max_us"]
        .iter()
        .map(|k| p[k].as_f64().expect("percentile"))
        .collect();
    assert!(q[0] > 0.0, "{v}");
    assert!(q.windows(2).all(|w| w[0] <= w[1]), "{v}");
    let thr = v["throughput_per_s"].as_f64().expect("throughput");
    let span = v["span_s"].as_f64().expect("span");
    assert!(thr > 0.0 && span > 0.0, "{v}");
    assert!(
        (thr * span - samples as f64).abs() < 1e-6 * samples as f64,
        "{v}"
    );
}

#[test]
fn paced_and_unpaced_runs_receive_every_message_once_in_order() {
    let (v, secs) = run(&["--samples", "300", "--warmup", "20", "--rate", "2000"]);
    check(&v, 300, 20);
    assert_eq!(v["rate"].as_f64(), Some(2000.0), "{v}");
    // Paced: message i is not sent before i / rate.
    assert!(secs >= 319.0 / 2000.0, "{secs} s: not paced");
    let (v, _) = run(&["--samples", "5000", "--rate", "0"]);
    check(&v, 5000, 0);
}

#[test]
fn bad_arguments_are_refused_with_a_message() {
    for (args, msg) in [
        (&["--rate", "-1"][..], "--rate must be"),
        (&["--rate", "NaN"][..], "--rate must be"),
        (&["--samples", "0"][..], "--samples must be positive"),
        (&["--fast"][..], "unknown argument"),
    ] {
        let out = Command::new(BIN).args(args).output().expect("run");
        assert!(!out.status.success(), "{args:?} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.starts_with("zenoh_latency: ") && err.contains(msg),
            "{args:?}: {err}"
        );
    }
}
