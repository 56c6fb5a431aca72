//! Publishing the estimates, in place: on the `<prefix>/estimates` queue (`loan_uninit` /
//! `write_payload` / `send`), or with `--latest-estimates` on the blackboard
//! `<prefix>/estimates-latest`, or not at all (`--no-publish-estimates`).
//!
//! Queue samples for the next instant are loaned right after an instant's estimates are out
//! ([`Publisher::loan_ahead`]): a loan after a period of idling is slow in the tail, and
//! iceoryx2 0.10 allocates in it, so neither sits between a slot's arrival and the `send()`
//! of its estimates. A blackboard entry is written in place and allocates nothing.

use crate::transport::{Transport, PRELOANED_ESTIMATES};
use anyhow::{anyhow, Result};
use estpipe_wire::{self as wire, Estimate};
use iceoryx2::port::writer::{EntryHandleMut, Writer};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::blackboard;

use super::args::RunArgs;

/// A queue sample loaned ahead of its estimate.
type PreLoaned = iceoryx2::sample_mut_uninit::SampleMutUninit<
    ipc::Service,
    core::mem::MaybeUninit<Estimate>,
    (),
>;

/// The writer side of `estpipe_wire::latest_estimates_board`, one entry handle per
/// estimator (created once; updating an entry writes in place and allocates nothing).
struct LatestBoard {
    entries: Vec<EntryHandleMut<ipc::Service, u32, Estimate>>,
    _writer: Writer<ipc::Service, u32>,
    _service: blackboard::PortFactory<ipc::Service, u32>,
}

impl LatestBoard {
    fn create(t: &Transport, prefix: &str, names: &[[u8; 16]]) -> Result<Self> {
        let service = wire::latest_estimates_board(&t.node, prefix, names)?;
        let board = format!("{prefix}/{}", wire::LATEST_ESTIMATES);
        // One writer per board: a second is another runner with --latest-estimates on the
        // prefix, alive (a dead one's port was cleaned up when this node started).
        let writer = service.writer_builder().create().map_err(|e| {
            wire::ContractError::Refused(format!(
                "cannot write the blackboard {board} ({e:?}): another runner with \
                 --latest-estimates is using this --prefix; stop it or use another --prefix"
            ))
        })?;
        let entries = (0..names.len() as u32)
            .map(|i| {
                writer.entry::<Estimate>(&i).map_err(|e| {
                    wire::ContractError::Refused(format!(
                        "the blackboard {board} has no entry {i} for estimator {:?} ({e:?}): {}",
                        String::from_utf8_lossy(&names[i as usize]).trim_end_matches('\0'),
                        wire::services::LATEST_ENTRIES_DIFFER
                    ))
                    .into()
                })
            })
            .collect::<Result<Vec<_>>>()?;
        // A board left by an earlier run holds its last estimates: a reader sees "no step
        // yet" under this run's names until its first instant.
        for (i, (e, n)) in entries.iter().zip(names).enumerate() {
            e.update_with_copy(Estimate::none_yet(i as u32, *n));
        }
        Ok(Self {
            entries,
            _writer: writer,
            _service: service,
        })
    }
}

/// Where the loop's estimates go.
pub(super) struct Publisher {
    on: bool,
    /// The latest-estimate board, when estimates go there instead of the queue.
    board: Option<LatestBoard>,
    /// Queue samples loaned for the next instant's estimates (one per estimator, up to
    /// [`PRELOANED_ESTIMATES`]).
    held: Vec<Option<PreLoaned>>,
    /// Estimates published (for the allocation accounting).
    pub(super) published: u64,
    /// The first failed loan or send, reported by the loop after the slot.
    err: Option<anyhow::Error>,
}

impl Publisher {
    /// For estimators named `names` (wire encoding), as `args` asks.
    pub(super) fn new(t: &Transport, args: &RunArgs, names: &[[u8; 16]]) -> Result<Self> {
        let board = if args.latest_estimates {
            Some(LatestBoard::create(t, &args.prefix, names)?)
        } else {
            None
        };
        Ok(Self {
            on: !args.no_publish_estimates,
            board,
            held: (0..names.len().min(PRELOANED_ESTIMATES))
                .map(|_| None)
                .collect(),
            published: 0,
            err: None,
        })
    }

    /// Whether estimates are published at all.
    #[inline]
    pub(super) fn is_on(&self) -> bool {
        self.on
    }

    /// Publishes estimator `e`'s `msg` (only called when [`Publisher::is_on`]). A failure is
    /// kept for [`Publisher::take_error`], which the loop asks once the slot's instants are out.
    #[inline]
    pub(super) fn send(&mut self, t: &Transport, e: usize, msg: Estimate) {
        self.published += 1;
        if let Some(b) = &self.board {
            b.entries[e].update_with_copy(msg);
            return;
        }
        let sent = match self.held.get_mut(e).and_then(Option::take) {
            Some(s) => Ok(s),
            None => t.estimate_pub.loan_uninit(),
        }
        .map_err(|e| anyhow!("loan for estimate: {e:?}"))
        .and_then(|s| {
            s.write_payload(msg)
                .send()
                .map_err(|e| anyhow!("send estimate: {e:?}"))
        });
        if let Err(e) = sent {
            self.err.get_or_insert(e);
        }
    }

    /// Loans the next instant's queue samples now, off the latency path. A failed loan is
    /// left to the send, which then loans itself and reports the error.
    pub(super) fn loan_ahead(&mut self, t: &Transport) {
        if !self.on || self.board.is_some() {
            return;
        }
        for h in self.held.iter_mut().filter(|h| h.is_none()) {
            match t.estimate_pub.loan_uninit() {
                Ok(s) => *h = Some(s),
                Err(_) => break,
            }
        }
    }

    /// The first failure since the last call.
    pub(super) fn take_error(&mut self) -> Option<anyhow::Error> {
        self.err.take()
    }
}
