//! `--latest-estimates`: the runner writes each estimator's newest estimate into the
//! blackboard `<prefix>/estimates-latest` (allocation-free; see `pipeline_alloc`), and a
//! reader in another node sees every entry advance to the last instant with exactly the
//! estimate the loop recorded.

#[path = "pipeline_common.rs"]
mod common;

use common::{loop_setup, prefix, scratch, start_channel_sim};
use estpipe_wire::{self as wire, Estimate, WIRE_VERSION};
use iceoryx2::prelude::*;
use ipc_runner::run::Hooks;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const S: &str = "linear";
const STEPS: u32 = 300;

/// Polls the board until `stop`; returns the newest value per entry and whether every
/// change seen kept `seq` increasing and `k` non-decreasing.
fn read_board(p: &str, stop: &AtomicBool) -> (Vec<Estimate>, bool) {
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let name = wire::service_name(p, wire::LATEST_ESTIMATES).unwrap();
    let start = Instant::now();
    let service = loop {
        match node
            .service_builder(&name)
            .blackboard_opener::<u32>()
            .open()
        {
            Ok(s) => break s,
            Err(_) if start.elapsed() < Duration::from_secs(20) => {
                std::thread::sleep(Duration::from_millis(1))
            }
            Err(e) => panic!("board never appeared: {e:?}"),
        }
    };
    let reader = service.reader_builder().create().unwrap();
    let entries: Vec<_> = (0u32..)
        .map_while(|i| reader.entry::<Estimate>(&i).ok())
        .collect();
    assert!(!entries.is_empty(), "the board has no entries");
    let mut last: Vec<Estimate> = entries.iter().map(|e| *e.get()).collect();
    let mut monotone = true;
    while !stop.load(Ordering::Relaxed) {
        for (e, l) in entries.iter().zip(last.iter_mut()) {
            let v = *e.get();
            if v.seq != l.seq {
                monotone &= l.seq == u64::MAX || (v.seq > l.seq && v.k >= l.k);
                *l = v;
            }
        }
        std::thread::sleep(Duration::from_micros(100));
    }
    (last, monotone)
}

#[test]
fn a_reader_sees_every_estimators_latest_estimate() {
    let dir = scratch("latest");
    let p = prefix("latest");
    let mut setup = loop_setup(S, &p, STEPS);
    setup.args.latest_estimates = true;
    let nx = setup.nx;
    let stop = Arc::new(AtomicBool::new(false));
    let reader = {
        let (p, stop) = (p.clone(), Arc::clone(&stop));
        std::thread::spawn(move || read_board(&p, &stop))
    };
    let mut publ = start_channel_sim(&dir, &p, S, STEPS, 2000);
    let (r, traj) = setup.run(Hooks::default()).unwrap();
    stop.store(true, Ordering::Relaxed);
    let (last, monotone) = reader.join().unwrap();
    assert!(publ.wait(30).success());
    assert_eq!(r.counts.instants, u64::from(STEPS));
    assert!(monotone, "seq went backwards or k decreased");
    let n_est = traj.names.len();
    assert_eq!(last.len(), n_est, "one board entry per estimator");
    let row = traj.keys.len() - 1;
    for (i, v) in last.iter().enumerate() {
        assert_eq!(v.version, WIRE_VERSION);
        assert_eq!(v.k, STEPS, "{}: the reader saw k = {}", traj.names[i], v.k);
        assert_eq!(v.name(), traj.names[i]);
        let want = &traj.estimates[(row * n_est + i) * nx..(row * n_est + i + 1) * nx];
        assert_eq!(
            &v.x[..nx],
            want,
            "{}: board ≠ loop's estimate",
            traj.names[i]
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
