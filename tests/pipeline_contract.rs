//! The runner refuses a peer outside the wire contract (`docs/wire.md`) with one line and exit
//! code 2, before any estimator runs, and never panics: a stream of another scenario's shape
//! or model (every ordered pair of presets), a slot service created with iceoryx2's default
//! QoS, and one whose user header type differs.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, scratch, Proc};
use estpipe_wire::{ContractError, Slot, StreamHeader};
use iceoryx2::prelude::*;

const PRESETS: [&str; 4] = ["occlusion", "nn-token-bucket", "tobit-fusion", "linear"];

fn header(preset: &str) -> StreamHeader {
    channel_sim::wire::stream_header(&*channel_sim::scenario::preset(preset).unwrap())
}

/// The runner's refusal: exit code 2, one `error:` line, no panic, no report written.
fn assert_refused(run: &mut Proc, json: &std::path::Path, needles: &[&str]) -> String {
    let st = run.wait(60);
    let err = run.err();
    assert_eq!(
        st.code(),
        Some(ContractError::EXIT_REFUSED),
        "{}: {st}\n{err}",
        run.name
    );
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("error:")).collect();
    assert_eq!(lines.len(), 1, "one line expected:\n{err}");
    for n in needles {
        assert!(lines[0].contains(n), "{n:?} missing from {:?}", lines[0]);
    }
    // The report is written after the loop: its absence shows no instant was stepped.
    assert!(!json.exists(), "{}: a report was written", run.name);
    lines[0].to_string()
}

#[test]
fn every_mismatched_pair_of_presets_is_refused_naming_both_shapes() {
    let dir = scratch("mismatch");
    let mut pairs = Vec::new();
    for a in PRESETS {
        for b in PRESETS.into_iter().filter(|&b| b != a) {
            pairs.push((a, b));
        }
    }
    assert_eq!(pairs.len(), 12);
    // Two pairs at a time: each pair is two processes, the machine has two cores.
    for chunk in pairs.chunks(2) {
        let mut running = Vec::new();
        for &(published, expected) in chunk {
            let p = prefix(&format!("mismatch-{published}-{expected}"));
            let name = format!("{published}-into-{expected}");
            let json = dir.join(format!("{name}.json"));
            let run = Proc::start(
                &dir,
                &format!("run-{name}"),
                &[
                    "run",
                    "--scenario",
                    expected,
                    "--prefix",
                    &p,
                    "--json",
                    json.to_str().unwrap(),
                ],
            );
            run.wait_for_stderr("waiting for channel-sim", 30);
            let publ = Proc::start(
                &dir,
                &format!("pub-{name}"),
                &[
                    "channel-sim",
                    "--scenario",
                    published,
                    "--prefix",
                    &p,
                    "--rate",
                    "0",
                    "--steps",
                    "50",
                    "--connect-timeout",
                    "1",
                    "--quiet",
                ],
            );
            running.push((published, expected, run, publ, json));
        }
        for (published, expected, mut run, _publ, json) in running {
            let (a, b) = (header(published), header(expected));
            let want = format!(
                "publisher streams {} but this runner runs {}",
                a.describe(),
                b.describe()
            );
            let line = assert_refused(&mut run, &json, &[&want]);
            eprintln!("{published} → {expected}: {line}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A node of this test process that creates services the way a foreign client might.
fn foreign_node() -> Node<ipc::Service> {
    set_log_level(LogLevel::Error);
    NodeBuilder::new().create::<ipc::Service>().unwrap()
}

#[test]
fn a_slot_service_with_default_qos_is_refused_naming_the_required_qos() {
    let dir = scratch("qos");
    let p = prefix("qos");
    let node = foreign_node();
    // What `publish_subscribe::<Slot>().user_header::<StreamHeader>().create()` gives a
    // client that sets no QoS: iceoryx2's defaults (a 2-sample buffer, safe overflow).
    let name = ServiceName::new(&format!("{p}/slots")).unwrap();
    let _service = node
        .service_builder(&name)
        .publish_subscribe::<Slot>()
        .user_header::<StreamHeader>()
        .create()
        .unwrap();
    let json = dir.join("run.json");
    let mut run = Proc::start(
        &dir,
        "run",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--json",
            json.to_str().unwrap(),
        ],
    );
    assert_refused(
        &mut run,
        &json,
        &[
            &format!("service {p}/slots was created with"),
            "subscriber_max_buffer_size ≥ 4096",
            "safe overflow off",
            "docs/wire.md",
        ],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_slot_service_without_the_stream_header_is_refused_naming_both_types() {
    let dir = scratch("types");
    let p = prefix("types");
    let node = foreign_node();
    let name = ServiceName::new(&format!("{p}/slots")).unwrap();
    let _service = node
        .service_builder(&name)
        .publish_subscribe::<Slot>()
        .create()
        .unwrap();
    let json = dir.join("run.json");
    let mut run = Proc::start(
        &dir,
        "run",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--json",
            json.to_str().unwrap(),
        ],
    );
    let size = size_of::<StreamHeader>();
    assert_refused(
        &mut run,
        &json,
        &[
            "user header '()' (size 0, align 1)",
            &format!("user header 'estpipe::wire::StreamHeader' (size {size}, align 8)"),
            &format!("wire version {}", estpipe_wire::WIRE_VERSION),
            "docs/wire.md",
        ],
    );
    let _ = std::fs::remove_dir_all(&dir);
}
