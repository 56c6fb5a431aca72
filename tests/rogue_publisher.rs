//! A publisher of arbitrary slots for the tests (`tests/hostile_slots.rs`,
//! `tests/pipeline_nodes.rs`): what a buggy or hostile sensor process could put on
//! `<prefix>/slots`, always with the scenario's correct stream header unless told otherwise.
//!
//! ```text
//! rogue-publisher --prefix P --scenario S --script FILE     # the slots of a JSON script
//! rogue-publisher --prefix P --scenario S --simulate --steps N --reverse-nodes
//! ```
//!
//! A script is a JSON array of slots. Every field of a slot is optional and defaults to a
//! well-formed data slot of instant `k` of node `node` (stream id 1, `seq = k − 1`,
//! `nodes` and `ny` the header's, delivered with `y` = k, `send_ns` now, `stream_start_ns` the
//! stream's start); `"model_xor": X` flips bits of the header's model fingerprint, `"end":
//! true` makes it an END marker of `node` after instant `k`. `--simulate` publishes the
//! scenario's own simulation (seed/run as channel-sim, truth included), each instant's nodes
//! in reversed order with `--reverse-nodes`. After the last slot the process keeps its ports
//! until the runner has detached (the runner reads the tail from its data segment).

use clap::Parser;
use estpipe_wire::{self as wire, Slot, StreamHeader, Truth, SLOT_END};
use iceoryx2::prelude::*;
use serde_json::Value;
use std::time::{Duration, Instant};

#[derive(Debug, Parser)]
struct Args {
    #[arg(long)]
    prefix: String,
    #[arg(long, default_value = "linear")]
    scenario: String,
    #[arg(long)]
    script: Option<std::path::PathBuf>,
    #[arg(long)]
    simulate: bool,
    #[arg(long, default_value_t = 100)]
    steps: u32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long)]
    reverse_nodes: bool,
    /// Seconds to wait for a subscriber, and to linger after the last slot.
    #[arg(long, default_value_t = 20.0)]
    timeout: f64,
}

fn field(v: &Value, name: &str) -> Option<u64> {
    v.get(name).and_then(Value::as_u64)
}

fn slot_of_json(v: &Value, h: &StreamHeader, start: u64) -> (Slot, StreamHeader) {
    let k = field(v, "k").unwrap_or(1) as u32;
    let node = field(v, "node").unwrap_or(0) as u8;
    let mut s = Slot::data(k, node, h.nodes, field(v, "stream_id").unwrap_or(1));
    let ny = h.ny.get(usize::from(node)).copied().unwrap_or(1);
    s.ny = ny;
    s.delivered = 1;
    for y in s.y.iter_mut().take(usize::from(ny)) {
        *y = f64::from(k);
    }
    s.send_ns = wire::monotonic_ns();
    s.stream_start_ns = start;
    if v.get("end").and_then(Value::as_bool) == Some(true) {
        s = Slot {
            stream_start_ns: start,
            ..Slot::marker(SLOT_END, k, node, h.nodes, s.stream_id, 0)
        };
    }
    let set = |name: &str, d: &mut u64| {
        if let Some(x) = field(v, name) {
            *d = x;
        }
    };
    set("seq", &mut s.seq);
    set("send_ns", &mut s.send_ns);
    set("period_ns", &mut s.period_ns);
    set("stream_start_ns", &mut s.stream_start_ns);
    let small = |name: &str| field(v, name);
    if let Some(x) = small("version") {
        s.version = x as u32;
    }
    if let Some(x) = small("kind") {
        s.kind = x as u32;
    }
    if let Some(x) = small("nodes") {
        s.nodes = x as u8;
    }
    if let Some(x) = small("ny") {
        s.ny = x as u8;
    }
    if let Some(x) = small("delivered") {
        s.delivered = x as u8;
    }
    if let Some(x) = small("flags") {
        s.flags = x as u32;
    }
    if let Some(ys) = v.get("y").and_then(Value::as_array) {
        for (d, y) in s.y.iter_mut().zip(ys) {
            // JSON has no NaN: the strings "nan" and "inf" stand for them.
            *d = match y.as_str() {
                Some("nan") => f64::NAN,
                Some("inf") => f64::INFINITY,
                _ => y.as_f64().unwrap_or(0.0),
            };
        }
    }
    let mut header = *h;
    if let Some(x) = field(v, "model_xor") {
        header.model ^= x;
    }
    (s, header)
}

fn main() {
    set_log_level_from_env_or(LogLevel::Error);
    let a = Args::parse();
    let scenario = channel_sim::scenario::resolve(&a.scenario, None).expect("scenario");
    let h = channel_sim::wire::stream_header(&*scenario);
    let node = NodeBuilder::new().create::<ipc::Service>().expect("node");
    let slots = wire::slot_service(&node, &a.prefix).expect("slot service");
    let truth = wire::truth_service(&node, &a.prefix).expect("truth service");
    let ready = wire::ready_event_service(&node, &a.prefix).expect("event service");
    let publ = slots
        .publisher_builder()
        .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
        .create()
        .expect("slot publisher");
    let notifier = ready
        .notifier_builder()
        .default_event_id(wire::READY_EVENT)
        .create()
        .expect("notifier");
    // Before a subscriber can exist: the runner then sees every truth message. Only a
    // simulation publishes the truth (the service takes one publisher: channel-sim's, when
    // a script joins its stream).
    let truth_pub = a
        .simulate
        .then(|| truth.publisher_builder().create().expect("truth publisher"));
    let timeout = Duration::from_secs_f64(a.timeout);
    let t0 = Instant::now();
    while slots.dynamic_config().number_of_subscribers() == 0 {
        assert!(t0.elapsed() < timeout, "no subscriber");
        std::thread::sleep(Duration::from_millis(2));
    }
    let start = wire::monotonic_ns();
    let send = |s: Slot, header: StreamHeader| {
        let mut sample = publ.loan_uninit().expect("loan");
        *sample.user_header_mut() = header;
        sample.write_payload(s).send().expect("send");
        notifier.notify().expect("notify");
    };
    if a.simulate {
        let mut sim = scenario.start(a.seed, 0);
        let nx = scenario.nx();
        let sid = 77;
        let x0 = sim.initial_truth();
        let truth_pub = truth_pub.as_ref().expect("created for --simulate");
        let send_truth = |t: Truth| {
            let n = truth_pub
                .loan_uninit()
                .expect("loan")
                .write_payload(t)
                .send()
                .expect("truth");
            if std::env::var_os("ROGUE_DEBUG").is_some() {
                eprintln!("truth {} sent to {n}", t.k);
            }
        };
        send_truth(Truth::new(0, sid, nx, &x0));
        for _ in 0..a.steps {
            let inst = sim.next_instant();
            send_truth(Truth::new(inst.k, sid, nx, &inst.truth));
            let mut obs: Vec<_> = inst.obs.iter().copied().collect();
            if a.reverse_nodes {
                obs.reverse();
            }
            for o in &obs {
                let s = channel_sim::wire::slot_of(o, h.nodes, sid, wire::monotonic_ns(), 0, start);
                send(s, h);
            }
        }
        for m in 0..h.nodes {
            let end = Slot {
                stream_start_ns: start,
                ..Slot::marker(SLOT_END, a.steps, m, h.nodes, sid, 1)
            };
            send(end, h);
        }
    } else {
        let path = a.script.expect("--script or --simulate");
        let text = std::fs::read_to_string(&path).expect("script");
        let v: Value = serde_json::from_str(&text).expect("JSON script");
        for s in v.as_array().expect("an array of slots") {
            let (slot, header) = slot_of_json(s, &h, start);
            send(slot, header);
        }
    }
    eprintln!("rogue-publisher: sent");
    let t1 = Instant::now();
    while slots.dynamic_config().number_of_subscribers() > 0 && t1.elapsed() < timeout {
        let _ = node.try_cleanup_dead_nodes();
        std::thread::sleep(Duration::from_millis(5));
    }
}
