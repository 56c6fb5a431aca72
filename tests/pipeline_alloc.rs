//! Steady state of the real-time loop does not allocate: the loop runs in this process (with
//! a counting global allocator) against a real channel-sim process, and the allocations
//! between instant 20 and the end of the stream are counted. A single test function, so
//! that no other test thread allocates meanwhile.
//!
//! Finding: iceoryx2 0.10's `Publisher::loan_uninit` allocates one 48-byte `Rc` per loaned
//! sample (`ChunkMutSharedState::new`), inside the library. Receiving allocates nothing. So
//! the loop is allocation-free when it does not publish estimates or publishes them on the
//! latest-estimate blackboard (`--latest-estimates`), and allocates exactly one block per
//! published estimate on the `estimates` queue; the WaitSet (`--wait block`) adds its own
//! per-wake-up vectors, which `--wait listener` avoids.
//!
//! The estimators are measured separately, in this process, over the very same instants
//! (same scenario, seed and run): every preset's estimators, `pf` included, allocate nothing
//! per step after warm-up, and the loop must add nothing on top of them.

#[path = "pipeline_common.rs"]
mod common;

use common::{loop_setup, prefix, scratch, start_channel_sim};
use e2e_tests::CountingAllocator;
use ipc_runner::run::{select, Hooks, WaitMode};

#[global_allocator]
static ALLOC: CountingAllocator = CountingAllocator::new();

fn probe() -> usize {
    ALLOC.total()
}

const S: &str = "linear";

struct Outcome {
    allocations: usize,
    slots: u64,
    published: u64,
}

const STEPS: u32 = 400;
const WARMUP: u64 = 20;

/// Allocations of the estimators' own `step` + `estimate` over instants WARMUP+1..=STEPS.
fn estimator_allocations(name: &str) -> usize {
    estimator_allocations_in(name, None)
}

/// [`estimator_allocations`] of the scenario file `config` when given.
fn estimator_allocations_in(name: &str, config: Option<&std::path::Path>) -> usize {
    let scenario = channel_sim::scenario::resolve(name, config).unwrap();
    let nx = scenario.nx();
    let mut sim = scenario.start(0, 0);
    let exp = select::Experiment {
        seed: 0,
        run: 0,
        horizon: STEPS,
    };
    let source = ipc_runner::source::Source::of_scenario(&*scenario, 0, 0);
    let make = select::estimators(source.into(), &[], exp).unwrap();
    let mut ests = make().unwrap();
    let mut x = [0.0; channel_sim::sim::MAX_NX];
    let mut per = vec![0usize; ests.len()];
    for k in 1..=STEPS {
        let inst = sim.next_instant();
        for (e, count) in ests.iter_mut().zip(per.iter_mut()) {
            let (n, ()) = ALLOC.count(|| {
                let _ = e.step(inst.k, &inst.obs);
                e.estimate(&mut x[..nx]);
            });
            if u64::from(k) > WARMUP {
                *count += n;
            }
        }
    }
    for (e, n) in ests.iter().zip(&per) {
        if *n > 0 {
            eprintln!("{name}/{}: {n} allocations after warm-up", e.name());
        }
    }
    per.iter().sum()
}

/// `publish`: `None` = no estimates published, `Some(false)` = the `estimates` queue,
/// `Some(true)` = the latest-estimate blackboard.
fn run_mode(mode: WaitMode, publish: Option<bool>) -> Outcome {
    let dir = scratch("alloc");
    let p = prefix("alloc");
    let mut setup = loop_setup(S, &p, STEPS);
    setup.args.wait = mode;
    setup.args.no_publish_estimates = publish.is_none();
    setup.args.latest_estimates = publish == Some(true);
    let mut publ = start_channel_sim(&dir, &p, S, STEPS, 2000);
    let (r, _) = setup
        .run(Hooks {
            alloc_probe: Some(probe),
            warmup: WARMUP,
            ..Hooks::default()
        })
        .unwrap();
    assert!(publ.wait(30).success());
    assert_eq!(r.counts.instants, u64::from(STEPS));
    assert_eq!(r.counts.lost_in_ipc, 0, "precondition");
    let _ = std::fs::remove_dir_all(&dir);
    Outcome {
        allocations: r.allocations_after_warmup.unwrap(),
        slots: r.slots_after_warmup,
        published: r.published_after_warmup,
    }
}

#[test]
fn steady_state_does_not_allocate_per_slot() {
    // Every preset's estimators, as the demo runs them (the papers', the baselines and the
    // `pf` reference), allocate nothing per step after warm-up: the adapters convert a
    // time-invariant model once. So the whole slot path is allocation-free without
    // publishing, whatever the scenario.
    for name in channel_sim::scenario::PRESETS.iter().map(|(name, _)| *name) {
        let n = estimator_allocations(name);
        assert_eq!(
            n, 0,
            "{name}: the estimators allocated {n} times after warm-up"
        );
    }
    // A model with a known control input steps without allocating too: only B_u u_{k−1} is
    // written, in place, at each instant (every estimator family, the gated ones included).
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios");
    for file in ["controlled.toml", "occlusion-user-controlled.toml"] {
        let n = estimator_allocations_in(S, Some(&dir.join(file)));
        assert_eq!(
            n, 0,
            "{file}: the estimators allocated {n} times after warm-up"
        );
    }
    let est = estimator_allocations(S);
    let mut lines = vec![format!(
        "the estimators alone: {est} allocations over instants {}..={STEPS}",
        WARMUP + 1
    )];
    for (mode, publish) in [
        (WaitMode::Spin, None),
        (WaitMode::Listener, None),
        (WaitMode::Spin, Some(false)),
        (WaitMode::Listener, Some(false)),
        (WaitMode::Spin, Some(true)),
        (WaitMode::Listener, Some(true)),
        (WaitMode::Block, None),
    ] {
        let o = run_mode(mode, publish);
        let sink = match publish {
            None => "none",
            Some(false) => "queue",
            Some(true) => "latest",
        };
        lines.push(format!(
            "{:<8} estimates={sink:<6}: {} allocations over {} slots, {} estimates published",
            mode.as_str(),
            o.allocations,
            o.slots,
            o.published
        ));
        let last = lines.last().unwrap();
        assert!(o.slots > 350, "{last}");
        match (mode, publish) {
            (WaitMode::Block, _) => {} // WaitSet internals: measured and reported only
            (_, None | Some(true)) => assert_eq!(o.allocations, est, "the loop allocated: {last}"),
            (_, Some(false)) => assert_eq!(
                (o.allocations - est) as u64,
                o.published,
                "expected exactly iceoryx2's one Rc per loaned sample: {last}"
            ),
        }
        if publish.is_some() {
            assert!(o.published > 0, "{last}");
        }
    }
    eprintln!("{}", lines.join("\n"));
}
