//! What the assembler counts: every slot once, by what became of it ([`Counts`], the
//! skipped ones by reason in [`Skipped`]), and the first-seen [`Reason`]s it reports.

use super::MAX_PERIOD_NS;
use estpipe_wire::SlotFault;
use serde::Serialize;

/// Slots skipped, by reason (each also counted nowhere else).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Skipped {
    /// Another wire version.
    pub version: u64,
    /// The stream header differs from the stream's (after the stream was accepted).
    pub header: u64,
    /// `kind` not 0, 1 or 2.
    pub kind: u64,
    /// `nodes` differs from the header's.
    pub nodes: u64,
    /// `node` ≥ `nodes`.
    pub node: u64,
    /// A data slot with `k = 0`.
    pub k_zero: u64,
    /// A data slot with `seq ≠ k − 1`.
    pub seq: u64,
    /// An END/ABORT with `seq ≠ k`.
    pub marker_seq: u64,
    /// `delivered` not 0/1 (the node's slot of that instant is handed on as lost).
    pub delivered: u64,
    /// `ny` not the header's for the node (handed on as lost).
    pub ny: u64,
    /// `delivered = 1` with `ny = 0` (handed on as lost).
    pub ny_zero: u64,
    /// A non-finite measurement entry (handed on as lost).
    pub non_finite: u64,
    /// Another stream id than the node's current stream, not at its first slot (not a
    /// restart).
    pub stream: u64,
    /// The stream id of a stream a restart replaced.
    pub stale_stream: u64,
    /// A new stream at `k = 1` from another publisher than the one whose slot started the
    /// node's stream, while that one is still registered: not a restart (docs/security.md,
    /// "What the runner assumes").
    pub foreign_restart: u64,
    /// `k` more than `--max-gap` past the node's last instant.
    pub gap: u64,
    /// An END/ABORT before the node's last instant or more than `--max-gap` past it.
    pub marker: u64,
    /// A slot of a node after its END/ABORT in the same stream.
    pub after_marker: u64,
}

impl Skipped {
    /// All skipped slots.
    pub fn total(&self) -> u64 {
        self.version
            + self.header
            + self.kind
            + self.nodes
            + self.node
            + self.k_zero
            + self.seq
            + self.marker_seq
            + self.delivered
            + self.ny
            + self.ny_zero
            + self.non_finite
            + self.stream
            + self.stale_stream
            + self.foreign_restart
            + self.gap
            + self.marker
            + self.after_marker
    }

    /// `name n, …` of the non-zero reasons (the summary line).
    pub fn describe(&self) -> String {
        let all = [
            ("version", self.version),
            ("header", self.header),
            ("kind", self.kind),
            ("nodes", self.nodes),
            ("node", self.node),
            ("k_zero", self.k_zero),
            ("seq", self.seq),
            ("marker_seq", self.marker_seq),
            ("delivered", self.delivered),
            ("ny", self.ny),
            ("ny_zero", self.ny_zero),
            ("non_finite", self.non_finite),
            ("stream", self.stream),
            ("stale_stream", self.stale_stream),
            ("foreign_restart", self.foreign_restart),
            ("gap", self.gap),
            ("marker", self.marker),
            ("after_marker", self.after_marker),
        ];
        all.iter()
            .filter(|(_, n)| *n > 0)
            .map(|(r, n)| format!("{r} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    pub(super) fn fault(&mut self, f: SlotFault) -> &mut u64 {
        match f {
            SlotFault::Version => &mut self.version,
            SlotFault::Kind => &mut self.kind,
            SlotFault::Nodes => &mut self.nodes,
            SlotFault::Node => &mut self.node,
            SlotFault::KZero => &mut self.k_zero,
            SlotFault::Seq => &mut self.seq,
            SlotFault::MarkerSeq => &mut self.marker_seq,
            SlotFault::Delivered => &mut self.delivered,
            SlotFault::Ny => &mut self.ny,
            SlotFault::NyZero => &mut self.ny_zero,
            SlotFault::NonFinite => &mut self.non_finite,
        }
    }
}

/// Fields of accepted slots that were not used.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Anomalies {
    /// `period_ns` above [`MAX_PERIOD_NS`]: ignored for loss detection.
    pub period_ns: u64,
    /// `send_ns` of 0 or later than the slot's receipt: not used for latency.
    pub send_ns: u64,
}

/// Slot accounting of one runner (over all its sessions).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Data slots accepted.
    pub received: u64,
    /// Accepted slots carrying a measurement.
    pub delivered: u64,
    /// Accepted slots whose packet the channel dropped (occlusion, token bucket, loss, …).
    pub dropped_by_channel: u64,
    /// Slots lost inside the IPC (gaps in a node's sequence, or before its END/ABORT),
    /// handed on as lost.
    pub lost_in_ipc: u64,
    /// Slots a bridge wrote for what the network lost (`FLAG_NET_LOST`, docs/bridge.md):
    /// received, but without information; and the slots missing when a node's stream went on
    /// from another bridge (one went away and another took over,
    /// [`Assembler::relay_changed`](super::Assembler::relay_changed)).
    pub lost_on_network: u64,
    /// Slots before the first one this runner saw of a stream (joined mid-stream).
    pub missed_before_join: u64,
    /// Slots of a node not there when their instant's deadline passed (paced mode), handed
    /// on as lost.
    pub lost_deadline: u64,
    /// Slots of a node more than [`WINDOW`](super::WINDOW) instants behind another, handed
    /// on as lost.
    pub lost_overrun: u64,
    /// Slots of instants after a node's END/ABORT, handed on as lost.
    pub lost_after_end: u64,
    /// Slots already seen (a duplicate or an older slot of the node): ignored.
    pub out_of_order: u64,
    /// Slots that arrived after their instant was handed on, more than `--lag` instants late
    /// (or without `--lag`): skipped.
    pub late: u64,
    /// Slots that arrived after their instant was handed on, at most `--lag` instants late:
    /// handed to the estimators' fixed-lag history (docs/pipeline.md, "Late packets"). Their
    /// instant's slot was counted lost (by the deadline) when the instant was handed on.
    pub late_folded: u64,
    /// END/ABORT markers accepted (one per node and stream).
    pub markers: u64,
    /// Slots skipped, by reason.
    pub skipped: Skipped,
    /// Fields of accepted slots that were not used, by field.
    pub anomalies: Anomalies,
    /// Instants handed to the estimators.
    pub instants: u64,
}

impl Counts {
    /// Every slot pushed, each counted once: accepted, a marker, a duplicate, late or
    /// skipped.
    pub fn slots_seen(&self) -> u64 {
        self.received
            + self.markers
            + self.out_of_order
            + self.late
            + self.late_folded
            + self.skipped.total()
    }
}

/// A reason counted for the first time
/// ([`Assembler::take_first_seen`](super::Assembler::take_first_seen)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reason {
    /// A malformed slot.
    Fault(SlotFault),
    /// The stream header differs.
    Header,
    /// Another stream id, not a restart.
    Stream,
    /// A replaced stream's slot.
    Stale,
    /// A new stream from a second publisher while the stream's own is alive.
    ForeignRestart,
    /// A jump of `k` beyond `--max-gap`.
    Gap,
    /// An END/ABORT out of bounds.
    Marker,
    /// A slot after the node's END/ABORT.
    AfterMarker,
    /// `period_ns` too long.
    Period,
    /// `send_ns` unusable.
    SendNs,
    /// A slot after its instant was handed on.
    Late,
}

impl Reason {
    /// One line: what was wrong and what the runner does about it.
    pub fn describe(self) -> String {
        match self {
            Self::Fault(f) if f.content_only() => {
                format!("malformed slot ({f}): counted, handed on as lost")
            }
            Self::Fault(f) => format!("malformed slot ({f}): counted and skipped"),
            Self::Header => {
                "a slot whose stream header differs from the stream's: counted and skipped".into()
            }
            Self::Stream => "a slot with another stream id than its node's stream, not at its \
                             first slot (no restart): counted and skipped"
                .into(),
            Self::Stale => "a slot of a stream a restart replaced: counted and skipped".into(),
            Self::ForeignRestart => "a new stream at k = 1 from another publisher while the \
                                     publisher of its node's stream is alive (no restart): \
                                     counted and skipped"
                .into(),
            Self::Gap => "a slot whose k jumps more than --max-gap past its node's last \
                          instant: counted and skipped (no instants filled)"
                .into(),
            Self::Marker => "an END/ABORT before its node's last instant or more than \
                             --max-gap past it: counted and skipped"
                .into(),
            Self::AfterMarker => "a slot after its node's END/ABORT: counted and skipped".into(),
            Self::Period => format!(
                "a slot with period_ns above {} s: counted, period ignored for loss detection",
                MAX_PERIOD_NS / 1_000_000_000
            ),
            Self::SendNs => {
                "a slot with send_ns 0 or in the future: counted, not used for latency".into()
            }
            Self::Late => "a slot after its instant was handed on: counted as late and \
                           skipped"
                .into(),
        }
    }
}
