//! `kf_interleaved` runs both covariance forms on both problems and reports consistent
//! statistics; bad arguments are refused with a message. No timing is asserted.

use serde_json::Value;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_kf_interleaved");

#[test]
fn reports_every_comparison_with_consistent_statistics() {
    let out = Command::new(BIN)
        .args(["--rounds", "9", "--batch", "20", "--json"])
        .output()
        .expect("run kf_interleaved");
    assert!(out.status.success(), "{out:?}");
    let v: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let rows = v.as_array().expect("an array");
    let mut seen: Vec<(String, String)> = rows
        .iter()
        .map(|r| {
            assert_eq!(r["rounds"].as_u64(), Some(9), "{r}");
            assert_eq!(r["batch"].as_u64(), Some(20), "{r}");
            let f = |k: &str| r[k].as_f64().unwrap_or_else(|| panic!("{k} in {r}"));
            for k in ["ours_median_ns", "ads_median_ns", "ratio_median"] {
                assert!(f(k).is_finite() && f(k) > 0.0, "{k} in {r}");
            }
            assert!(f("ratio_p10") <= f("ratio_median"), "{r}");
            assert!(f("ratio_median") <= f("ratio_p90"), "{r}");
            (
                r["problem"].as_str().unwrap().to_string(),
                r["form"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    seen.sort();
    let want: Vec<(String, String)> = [
        ("3x2_f64", "Joseph"),
        ("3x2_f64", "optimal gain"),
        ("4x2_f32", "Joseph"),
        ("4x2_f32", "optimal gain"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    assert_eq!(seen, want);
}

#[test]
fn refuses_bad_arguments() {
    for args in [
        &["--rounds", "0"][..],
        &["--batch", "many"],
        &["--rounds"],
        &["--fast"],
    ] {
        let out = Command::new(BIN).args(args).output().expect("run");
        assert!(!out.status.success(), "{args:?} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("kf_interleaved: "), "{args:?}: {err}");
    }
}
