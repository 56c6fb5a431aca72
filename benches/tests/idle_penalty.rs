//! `idle_penalty` measures every work back to back and paced, with consistent statistics;
//! bad arguments are refused with a message. No timing is asserted.

use serde_json::Value;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_idle_penalty");

#[test]
fn reports_every_work_both_ways() {
    let out = Command::new(BIN)
        .args(["--samples", "50", "--rate", "20000", "--json"])
        .env("IOX2_LOG_LEVEL", "Error")
        .output()
        .expect("run idle_penalty");
    assert!(out.status.success(), "{out:?}");
    let v: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let works: Vec<&str> = v
        .as_array()
        .expect("an array")
        .iter()
        .map(|r| {
            assert_eq!(r["samples"].as_u64(), Some(50), "{r}");
            assert_eq!(r["rate_hz"].as_f64(), Some(20_000.0), "{r}");
            for side in ["back_to_back", "paced"] {
                let p = &r[side];
                assert_eq!(p["count"].as_u64(), Some(50), "{side} in {r}");
                let f = |k: &str| p[k].as_f64().unwrap_or_else(|| panic!("{side}.{k} in {r}"));
                assert!(f("p50_us") > 0.0, "{r}");
                assert!(
                    f("p50_us") <= f("p99_us") && f("p99_us") <= f("max_us"),
                    "{r}"
                );
            }
            r["work"].as_str().expect("work")
        })
        .collect();
    assert_eq!(
        works,
        [
            "touch 16 KiB",
            "iceoryx2 loan+send",
            "iceoryx2 send, loaned ahead"
        ]
    );
}

#[test]
fn refuses_bad_arguments() {
    for args in [
        &["--samples", "0"][..],
        &["--rate", "0"],
        &["--rate", "fast"],
        &["--samples"],
        &["--quick"],
    ] {
        let out = Command::new(BIN).args(args).output().expect("run");
        assert_eq!(out.status.code(), Some(2), "{args:?}: {out:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("idle_penalty: "), "{args:?}: {err}");
    }
}
