//! Steady state of the real-time loop does not allocate: the loop runs in this process (with
//! a counting global allocator) against a real channel-sim process, and the allocations
//! between instant 20 and the end of the stream are counted. A single test function, so
//! that no other test thread allocates meanwhile.
//!
//! Finding: iceoryx2 0.10's `Publisher::loan_uninit` allocates one 48-byte `Rc` per loaned
//! sample (`ChunkMutSharedState::new`), inside the library. Receiving allocates nothing. So
//! the loop is allocation-free when it does not publish estimates, and allocates exactly one
//! block per published estimate when it does; the WaitSet (`--wait block`) adds its own
//! per-wake-up vectors, which `--wait listener` avoids.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, scratch, Proc};
use e2e_tests::CountingAllocator;
use ipc_runner::run::{run_loop, select, Hooks, RunArgs, WaitMode};

#[global_allocator]
static ALLOC: CountingAllocator = CountingAllocator::new();

fn probe() -> usize {
    ALLOC.total()
}

const S: &str = channel_sim::publisher::selftest::NAME;

struct Outcome {
    allocations: usize,
    slots: u64,
    published: u64,
}

fn run_mode(mode: WaitMode, publish: bool) -> Outcome {
    let dir = scratch("alloc");
    let p = prefix("alloc");
    let (scenario, _) = select::scenario(S, None).unwrap();
    let make = select::estimators(scenario.as_ref(), &[]).unwrap();
    let mut args = RunArgs::new(S, &p);
    args.wait = mode;
    args.quiet = true;
    args.record_capacity = 500;
    args.no_publish_estimates = !publish;
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--rate",
            "2000",
            "--steps",
            "400",
        ],
    );
    let (r, _) = run_loop(
        &args,
        scenario.nx(),
        scenario.nodes() as u8,
        scenario.ny() as u8,
        &make,
        Hooks {
            alloc_probe: Some(probe),
            warmup: 20,
            progress: None,
        },
    )
    .unwrap();
    assert!(publ.wait(30).success());
    assert_eq!(r.counts.instants, 400);
    let _ = std::fs::remove_dir_all(&dir);
    Outcome {
        allocations: r.allocations_after_warmup.unwrap(),
        slots: r.slots_after_warmup,
        published: r.published_after_warmup,
    }
}

#[test]
fn steady_state_does_not_allocate_per_slot() {
    let mut lines = Vec::new();
    for (mode, publish) in [
        (WaitMode::Spin, false),
        (WaitMode::Listener, false),
        (WaitMode::Spin, true),
        (WaitMode::Listener, true),
        (WaitMode::Block, false),
    ] {
        let o = run_mode(mode, publish);
        lines.push(format!(
            "{:<8} publish={publish:<5}: {} allocations over {} slots, {} estimates published",
            mode.as_str(),
            o.allocations,
            o.slots,
            o.published
        ));
        let last = lines.last().unwrap();
        assert!(o.slots > 700, "{last}");
        match (mode, publish) {
            (WaitMode::Block, _) => {} // WaitSet internals: measured and reported only
            (_, false) => assert_eq!(o.allocations, 0, "{last}"),
            (_, true) => assert_eq!(
                o.allocations as u64, o.published,
                "expected exactly iceoryx2's one Rc per loaned sample: {last}"
            ),
        }
    }
    eprintln!("{}", lines.join("\n"));
}
