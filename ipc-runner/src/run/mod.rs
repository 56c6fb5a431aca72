//! `ipc-runner run`: the real-time loop over shared memory.
//!
//! Per slot: receive in place → reassemble the instant ([`assemble`]) → step every estimator →
//! publish each estimate in place (`loan_uninit` / `write_payload` / `send`) → record
//! latencies ([`crate::latency`]) and the squared error against the truth service (evaluation
//! beside the loop, never inside the estimator). Once the estimators exist nothing in this path
//! allocates except iceoryx2 0.10 itself, one small block per estimate loaned on the queue
//! (none on the `--latest-estimates` blackboard; `tests/pipeline_alloc.rs` counts). The
//! iceoryx2 behaviour this loop is built around is listed in `docs/design.md` ("iceoryx2 0.10
//! facts").
//!
//! What keeps the latency path short (the measurements behind each are in
//! `docs/pipeline.md`):
//!
//! * the queue samples of the next instant are loaned right after an instant's estimates are
//!   published (`publish.rs`): a loan after a period of idling is slow in the tail, because
//!   the memory it touches goes cold while the loop waits;
//! * the step, end-to-end and transport histograms are recorded after the instant's
//!   estimates are published, not between receive and send (`instant.rs`, `slot_loop.rs`);
//! * the spin loop reads the clock only every 256 empty polls and checks for signals through
//!   `estpipe_process::signal`, not `Node::wait(ZERO)` (`wait.rs`);
//! * the functions on that path that live in other files are `#[inline]`: a call across
//!   modules (codegen units) is otherwise not inlined, and the split into files would add
//!   calls between a slot's arrival and its estimates' `send()`.
//!
//! Waiting (`wait.rs`): `--wait spin` busy-polls `receive()`; `--wait block` sleeps in a
//! WaitSet on the `slots-ready` event and `--wait listener` on its listener directly; both
//! re-drain `receive()` after every wake-up (wake-ups can be spurious and one notification
//! may stand for several slots).
//!
//! Faults: when no slot arrives within `period + --deadline-ms` of the previous one the
//! runner cleans up dead nodes (`try_cleanup_dead_nodes`: a SIGKILLed publisher is otherwise
//! invisible). A publisher still registered then is alive: *stalled*, waited for and reported
//! (up to `--stall-limit`). One that is gone is lost: the runner exits with
//! [`EXIT_PUBLISHER_LOST`], or with `--wait-for-restart` waits for a new channel-sim and
//! starts a new session (fresh estimators; the new process starts its stream at k = 1). Only
//! SIGINT/SIGTERM/SIGHUP stop the loop; any other signal is a wake-up (docs/security.md, "Signals").
//!
//! The parts, one file each: `args` ([`RunArgs`]), `slot_loop` (the loop, [`run_loop`]),
//! `instant` (one instant's work), `lane` (one estimator's state and counts), `publish`,
//! `truth` (the evaluation beside the loop), `wait`, `restart` (which restarts are believed),
//! `report` ([`RunReport`], the output files, the exit code), `trajectories`
//! ([`Trajectories`]); and the public [`assemble`] (slots → instants), [`select`]
//! (estimators by name) and [`system`] (CPU pinning, memory locking).

mod args;
pub mod assemble;
mod deadline;
mod instant;
mod lane;
mod publish;
mod report;
mod restart;
pub mod select;
mod slot_loop;
pub mod system;
mod trajectories;
mod truth;
mod wait;

pub use args::{RunArgs, WaitMode};
pub use report::{
    conclude, exit_code, finish, Ending, EstimatorReport, ExitWith, RunReport, Stalls,
    EXIT_PUBLISHER_LOST,
};
pub use slot_loop::{run_loop, Hooks, Progress, PEER_CHECK_NS};
pub use trajectories::Trajectories;

use crate::limits;
use crate::source::Source;
use anyhow::Result;
use std::sync::Arc;

/// `ipc-runner run`: checks the outputs and the memory budget, resolves scenario and
/// estimators, runs the loop, prints the summary and writes the files (also when the loop
/// ends in a failure). Returns the process exit code.
pub fn main(args: &RunArgs) -> Result<i32> {
    args.check_outputs()?;
    let source = Arc::new(Source::resolve(
        &args.scenario,
        args.config.as_deref(),
        args.estimator_spec.as_deref(),
        args.seed,
        args.run,
    )?);
    let spec = Arc::clone(&source.spec);
    let particles = args.estimator.particle_count();
    // Before any estimator is built: the particle filter allocates its particles at once.
    args.check_memory(spec.nx(), spec.nodes(), 0, particles)?;
    let make = select::estimators_with(
        source,
        &args.estimator,
        select::Experiment {
            seed: args.seed,
            run: args.run,
            horizon: args.steps,
        },
    )
    .map_err(|e| limits::BadInput(format!("{e:#}")))?;
    let n_est = make()?.len();
    args.check_memory(spec.nx(), spec.nodes(), n_est, particles)?;
    let view = crate::view::View::start(&args.view)?;
    let mut args = args.clone();
    args.view_tap = view.tap();
    let (report, traj) = run_loop(&args, &spec, &make, Hooks::default())?;
    let code = conclude(&args, &report, &traj, spec.ny());
    view.end();
    code
}
