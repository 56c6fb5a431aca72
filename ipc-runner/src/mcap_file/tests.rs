//! The MCAP writer read back with the `mcap` crate's reader.

use super::*;
use estpipe_wire::{COV_BOUND, COV_ESTIMATE, FLAG_IPC_LOST};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mcap-unit-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join("run.mcap")
}

fn obs(k: u32, node: u8, delivered: bool, flags: u32) -> Observation {
    let mut o = Observation::dropped(k, node, 2, flags);
    if delivered {
        o.delivered = true;
        o.y[0] = f64::from(k) + 0.5;
        o.y[1] = -f64::from(node);
    }
    o
}

/// Three instants of two nodes and two estimators: every message comes back on its channel
/// with the times and values written, NaN as null, the counts as returned.
#[test]
fn written_messages_read_back() {
    let path = scratch("readback");
    let names = vec!["kf".to_string(), "nn".to_string()];
    let mut w = McapWriter::create(&path, "linear", 2, &names).unwrap();
    for k in 1..=3u32 {
        let o = [
            obs(k, 0, k != 2, 0),
            obs(k, 1, false, if k == 3 { FLAG_IPC_LOST } else { 0 }),
        ];
        let truth = [f64::from(k), 2.0 * f64::from(k)];
        let xhat = [0.1 * f64::from(k), 0.2, 0.3, f64::NAN];
        let cov = [4.0, 0.5, 0.5, 9.0, 1.0, 0.0, 0.0, 16.0];
        w.instant(&InstantRecord {
            session: 1,
            k,
            times: Times {
                sent: 1000 * u64::from(k),
                received: 1000 * u64::from(k) + 10,
                published: 1000 * u64::from(k) + 20,
            },
            truth: (k != 3).then_some(&truth[..]),
            obs: &o,
            xhat: &xhat,
            cov: &cov,
            cov_kind: &[COV_ESTIMATE, COV_BOUND],
        })
        .unwrap();
    }
    let counts = w.finish().unwrap();
    assert_eq!(
        counts,
        Counts {
            slots: 6,
            truth: 2,
            estimates: vec![3, 3]
        }
    );
    let bytes = std::fs::read(&path).unwrap();
    let mut per_topic: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let k = v["k"].as_u64().unwrap();
        assert_eq!(m.publish_time, 1000 * k, "{}", m.channel.topic);
        let log = match m.channel.topic.as_str() {
            "/slots" => 10,
            "/truth" => 0,
            _ => 20,
        };
        assert_eq!(m.log_time, 1000 * k + log, "{}", m.channel.topic);
        assert_eq!(m.channel.message_encoding, "json");
        assert_eq!(m.channel.schema.as_ref().unwrap().encoding, "jsonschema");
        per_topic
            .entry(m.channel.topic.clone())
            .or_default()
            .push(v);
    }
    let topics: Vec<&str> = per_topic.keys().map(String::as_str).collect();
    assert_eq!(
        topics,
        ["/estimates/kf", "/estimates/nn", "/slots", "/truth"]
    );
    let slots = &per_topic["/slots"];
    let status: Vec<&str> = slots
        .iter()
        .map(|v| v["status"].as_str().unwrap())
        .collect();
    assert_eq!(
        status,
        [
            "delivered",
            "dropped",
            "dropped",
            "dropped",
            "delivered",
            "lost"
        ]
    );
    assert_eq!(slots[4]["y"], serde_json::json!([3.5, -0.0]));
    assert_eq!(per_topic["/truth"][1]["x"], serde_json::json!([2.0, 4.0]));
    let kf = &per_topic["/estimates/kf"][2];
    assert_eq!(kf["x"], serde_json::json!([0.1 * 3.0, 0.2]));
    assert_eq!(kf["sigma"], serde_json::json!([2.0, 3.0]));
    assert_eq!(kf["cov_kind"], "covariance");
    let nn = &per_topic["/estimates/nn"][0];
    assert_eq!(nn["x"], serde_json::json!([0.3, null]));
    assert_eq!(nn["p"], serde_json::json!([1.0, 0.0, 0.0, 16.0]));
    assert_eq!(nn["cov_kind"], "bound");
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, 6 + 2 + 6);
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

/// A path that cannot be created is one error naming it, not a panic.
#[test]
fn uncreatable_path_is_an_error() {
    let e = McapWriter::create(Path::new("/nonexistent-dir/x.mcap"), "linear", 1, &[]).unwrap_err();
    assert!(
        format!("{e:#}").contains("/nonexistent-dir/x.mcap"),
        "{e:#}"
    );
}
