//! The shared-memory wire format between the `channel-sim` publisher and the `ipc-runner` loop.
//!
//! Every payload is `#[repr(C)]`, fixed-size and pointer-free, carries [`WIRE_VERSION`] as its
//! first field and has an explicit iceoryx2 type name, so that two separately built binaries
//! agree on the type (without `#[type_name]` iceoryx2 uses the Rust path and refuses the
//! connection). Publishers write them in place into loaned shared memory
//! (`loan_uninit()` → [`write_payload`](iceoryx2::sample_mut_uninit::SampleMutUninit::write_payload)
//! → `send()`); subscribers read them in place: nothing is copied or serialised.
//!
//! Services (all names start with the user's `--prefix`, so parallel runs never collide):
//!
//! | service                 | pattern            | payload      | written by  |
//! |-------------------------|--------------------|--------------|-------------|
//! | `<prefix>/slots`        | publish-subscribe  | [`Slot`]     | channel-sim |
//! | `<prefix>/slots-ready`  | event              | –            | channel-sim (one notification per instant) |
//! | `<prefix>/truth`        | publish-subscribe  | [`Truth`]    | channel-sim (evaluation only) |
//! | `<prefix>/estimates`    | publish-subscribe  | [`Estimate`] | ipc-runner  |

use crate::sim::{Observation, MAX_NODES, MAX_NX, MAX_NY};
use iceoryx2::port::event_id::EventId;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{blackboard, event, publish_subscribe};

/// Version of the payload layouts below. Bump on any change to a field's meaning or layout.
pub const WIRE_VERSION: u32 = 1;

/// Default service-name prefix.
pub const DEFAULT_PREFIX: &str = "estpipe";

/// [`Slot::kind`]: one node's observation of one instant.
pub const SLOT_DATA: u32 = 0;
/// [`Slot::kind`]: the stream is complete; `seq` is the number of data slots sent.
pub const SLOT_END: u32 = 1;
/// [`Slot::kind`]: the publisher was asked to stop (SIGINT/SIGTERM) before the last instant.
pub const SLOT_ABORT: u32 = 2;

/// Observation flag added by the runner (never by the channel): the slot was lost inside the
/// IPC (subscriber queue overflow), detected by a gap in sequence numbers. Chosen above the
/// channel-side `FLAG_*` bits of [`crate::sim`].
pub const FLAG_IPC_LOST: u32 = 1 << 31;

/// Subscriber queue capacity the services are created with (the runner may use less).
pub const MAX_SUBSCRIBER_BUFFER: usize = 4096;

/// One node's observation of one sampling instant (a *slot*).
///
/// Sequence numbers are dense per stream: `seq = (k − 1)·nodes + node`, so the runner can tell
/// exactly which `(k, node)` a gap corresponds to.
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Slot")]
pub struct Slot {
    /// [`WIRE_VERSION`] of the writer. Always the first field.
    pub version: u32,
    /// [`SLOT_DATA`], [`SLOT_END`] or [`SLOT_ABORT`].
    pub kind: u32,
    /// Identifies one publisher run; a new value means channel-sim was restarted.
    pub stream_id: u64,
    /// Dense sequence number within the stream (for END/ABORT: data slots sent).
    pub seq: u64,
    /// Sampling instant k ≥ 1.
    pub k: u32,
    /// Sensor node, 0-based.
    pub node: u8,
    /// Number of nodes in the scenario.
    pub nodes: u8,
    /// Valid entries of `y`.
    pub ny: u8,
    /// 1 if the channel delivered a measurement, 0 if the packet was dropped.
    pub delivered: u8,
    /// Channel-side flags (`sim::FLAG_*`).
    pub flags: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// `CLOCK_MONOTONIC` time (ns) at which the slot was written, just before `send()`.
    pub send_ns: u64,
    /// The publisher's sampling period in ns (0 = as fast as possible).
    pub period_ns: u64,
    /// `CLOCK_MONOTONIC` when the stream started (after a subscriber had connected): a
    /// subscriber older than this saw the whole stream, so any slot it misses before its
    /// first one was lost in the IPC rather than sent before it joined.
    pub stream_start_ns: u64,
    /// The measurement (entries ≥ `ny` are 0; meaningful iff `delivered == 1`).
    pub y: [f64; MAX_NY],
}

/// The true state x_k of one instant (evaluation only; estimators never read it).
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Truth")]
pub struct Truth {
    /// [`WIRE_VERSION`] of the writer.
    pub version: u32,
    /// Sampling instant k (0 = the initial state x_0).
    pub k: u32,
    /// Identifies one publisher run (same as in [`Slot`]).
    pub stream_id: u64,
    /// Valid entries of `x`.
    pub nx: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// x_k.
    pub x: [f64; MAX_NX],
}

/// One estimator's estimate x̂_k, published by the runner after each instant.
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Estimate")]
pub struct Estimate {
    /// [`WIRE_VERSION`] of the writer.
    pub version: u32,
    /// Sampling instant k.
    pub k: u32,
    /// Stream the estimate belongs to.
    pub stream_id: u64,
    /// Running count of estimates published by this runner.
    pub seq: u64,
    /// Index of the estimator in the runner's list.
    pub estimator: u32,
    /// Valid entries of `x`.
    pub nx: u32,
    /// Estimator name, UTF-8, zero-padded.
    pub name: [u8; 16],
    /// 0 = step succeeded; 1 = step rejected the input (state kept, see `ipc-runner` docs).
    pub status: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// x̂_k.
    pub x: [f64; MAX_NX],
    /// `send_ns` of the slot that completed instant k.
    pub slot_send_ns: u64,
    /// `CLOCK_MONOTONIC` when the runner received that slot.
    pub receive_ns: u64,
    /// `CLOCK_MONOTONIC` when this estimator's step finished.
    pub step_done_ns: u64,
}

/// Why a received payload cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireError {
    /// The writer uses another wire format version.
    Version {
        /// Version found in the payload.
        found: u32,
    },
    /// A field is out of range (names the field).
    Invalid(&'static str),
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Version { found } => write!(
                f,
                "wire format version {found} received, but this binary speaks version \
                 {WIRE_VERSION}: build channel-sim and ipc-runner from the same source \
                 (`cargo build --release`)"
            ),
            Self::Invalid(what) => write!(f, "malformed slot: {what}"),
        }
    }
}

impl std::error::Error for WireError {}

impl Slot {
    /// The slot carrying `obs` as the `seq`-th slot of stream `stream_id`.
    pub fn data(
        obs: &Observation,
        nodes: u8,
        stream_id: u64,
        send_ns: u64,
        period_ns: u64,
        stream_start_ns: u64,
    ) -> Self {
        Self {
            version: WIRE_VERSION,
            kind: SLOT_DATA,
            stream_id,
            seq: Self::seq_of(obs.k, obs.node, nodes),
            k: obs.k,
            node: obs.node,
            nodes,
            ny: obs.ny,
            delivered: u8::from(obs.delivered),
            flags: obs.flags,
            reserved: 0,
            send_ns,
            period_ns,
            stream_start_ns,
            y: obs.y,
        }
    }

    /// An END ([`SLOT_END`]) or ABORT ([`SLOT_ABORT`]) marker after `sent` data slots.
    pub fn marker(kind: u32, sent: u64, last_k: u32, nodes: u8, stream_id: u64, now: u64) -> Self {
        Self {
            version: WIRE_VERSION,
            kind,
            stream_id,
            seq: sent,
            k: last_k,
            node: 0,
            nodes,
            ny: 0,
            delivered: 0,
            flags: 0,
            reserved: 0,
            send_ns: now,
            period_ns: 0,
            stream_start_ns: 0,
            y: [0.0; MAX_NY],
        }
    }

    /// The dense sequence number of `(k, node)`: `(k − 1)·nodes + node`.
    pub fn seq_of(k: u32, node: u8, nodes: u8) -> u64 {
        (u64::from(k).saturating_sub(1)) * u64::from(nodes) + u64::from(node)
    }

    /// `(k, node)` of sequence number `seq` (inverse of [`Slot::seq_of`]).
    pub fn position_of(seq: u64, nodes: u8) -> (u32, u8) {
        let n = u64::from(nodes.max(1));
        ((seq / n + 1) as u32, (seq % n) as u8)
    }

    /// Checks the version and the ranges of the header fields.
    pub fn validate(&self) -> Result<(), WireError> {
        if self.version != WIRE_VERSION {
            return Err(WireError::Version {
                found: self.version,
            });
        }
        if self.kind > SLOT_ABORT {
            return Err(WireError::Invalid("kind"));
        }
        if self.kind != SLOT_DATA {
            return Ok(());
        }
        if self.nodes == 0 || usize::from(self.nodes) > MAX_NODES {
            return Err(WireError::Invalid("nodes out of range"));
        }
        if self.node >= self.nodes {
            return Err(WireError::Invalid("node ≥ nodes"));
        }
        if usize::from(self.ny) > MAX_NY {
            return Err(WireError::Invalid("ny > MAX_NY"));
        }
        if self.k == 0 {
            return Err(WireError::Invalid("k = 0 (the prior has no slot)"));
        }
        if self.seq != Self::seq_of(self.k, self.node, self.nodes) {
            return Err(WireError::Invalid("seq ≠ (k − 1)·nodes + node"));
        }
        if self.delivered > 1 {
            return Err(WireError::Invalid("delivered is not 0/1"));
        }
        Ok(())
    }

    /// The observation this slot carries (validated). Non-finite measurement values are passed
    /// through unchanged: rejecting them is the estimator's job, which keeps its state.
    pub fn observation(&self) -> Result<Observation, WireError> {
        self.validate()?;
        if self.kind != SLOT_DATA {
            return Err(WireError::Invalid("not a data slot"));
        }
        let mut y = [0.0; MAX_NY];
        if self.delivered == 1 {
            y[..usize::from(self.ny)].copy_from_slice(&self.y[..usize::from(self.ny)]);
        }
        Ok(Observation {
            k: self.k,
            node: self.node,
            delivered: self.delivered == 1,
            ny: self.ny,
            y,
            flags: self.flags,
        })
    }
}

impl Truth {
    /// Truth payload of instant `k`.
    pub fn new(k: u32, stream_id: u64, nx: usize, x: &[f64; MAX_NX]) -> Self {
        Self {
            version: WIRE_VERSION,
            k,
            stream_id,
            nx: nx as u32,
            reserved: 0,
            x: *x,
        }
    }
}

impl Estimate {
    /// The placeholder of a latest-estimate board entry before the estimator's first step:
    /// `k = 0`, `seq = u64::MAX`, `status = 2` (no estimate yet), `x` zero.
    pub fn none_yet(estimator: u32, name: [u8; 16]) -> Self {
        Self {
            version: WIRE_VERSION,
            k: 0,
            stream_id: 0,
            seq: u64::MAX,
            estimator,
            nx: 0,
            name,
            status: 2,
            reserved: 0,
            x: [0.0; MAX_NX],
            slot_send_ns: 0,
            receive_ns: 0,
            step_done_ns: 0,
        }
    }

    /// Encodes an estimator name into the fixed 16-byte field (truncated on a char boundary).
    pub fn encode_name(name: &str) -> [u8; 16] {
        let mut out = [0u8; 16];
        let mut end = name.len().min(16);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        out[..end].copy_from_slice(&name.as_bytes()[..end]);
        out
    }

    /// The estimator name.
    pub fn name(&self) -> &str {
        let end = self.name.iter().position(|&b| b == 0).unwrap_or(16);
        core::str::from_utf8(&self.name[..end]).unwrap_or("?")
    }
}

/// `CLOCK_MONOTONIC` in ns: one clock shared by all processes of the machine, so send and
/// receive times of different processes are directly comparable.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    #[allow(unsafe_code)]
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Full service name `<prefix>/<what>`.
pub fn service_name(prefix: &str, what: &str) -> anyhow::Result<ServiceName> {
    let s = format!("{prefix}/{what}");
    ServiceName::new(&s).map_err(|e| anyhow::anyhow!("invalid service name {s:?}: {e:?}"))
}

fn explain_open<E: core::fmt::Debug>(what: &str, prefix: &str, e: E) -> anyhow::Error {
    let dbg = format!("{e:?}");
    if dbg.contains("Incompatible") {
        anyhow::anyhow!(
            "service {prefix}/{what} exists with a different payload type or layout ({dbg}): \
             the process on the other side was built from a different version; rebuild both \
             (`cargo build --release`) or use another --prefix"
        )
    } else {
        anyhow::anyhow!("cannot open service {prefix}/{what}: {dbg}")
    }
}

/// Opens (or creates) the publish-subscribe service `{prefix}/{what}` with the QoS both sides
/// agree on: one publisher, no history, a bounded buffer that overwrites the oldest sample
/// (a slow reader sees gaps in `seq`, never blocks the writer).
fn pubsub_service<T: ZeroCopySend + core::fmt::Debug + 'static>(
    node: &Node<ipc::Service>,
    prefix: &str,
    what: &str,
    max_subscribers: usize,
) -> anyhow::Result<publish_subscribe::PortFactory<ipc::Service, T, ()>> {
    node.service_builder(&service_name(prefix, what)?)
        .publish_subscribe::<T>()
        .max_publishers(1)
        .max_subscribers(max_subscribers)
        .subscriber_max_buffer_size(MAX_SUBSCRIBER_BUFFER)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| explain_open(what, prefix, e))
}

/// Opens (or creates) the slot service.
pub fn slot_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> anyhow::Result<publish_subscribe::PortFactory<ipc::Service, Slot, ()>> {
    pubsub_service(node, prefix, "slots", 4)
}

/// Opens (or creates) the truth service.
pub fn truth_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> anyhow::Result<publish_subscribe::PortFactory<ipc::Service, Truth, ()>> {
    pubsub_service(node, prefix, "truth", 4)
}

/// Opens (or creates) the estimate service.
pub fn estimate_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> anyhow::Result<publish_subscribe::PortFactory<ipc::Service, Estimate, ()>> {
    pubsub_service(node, prefix, "estimates", 8)
}

/// Creates the latest-estimate blackboard `{prefix}/estimates-latest`: one entry per
/// estimator, key = its index in the runner's list, value = its newest [`Estimate`]. Unlike
/// the `estimates` queue it keeps no history (a reader gets the newest value and sees skipped
/// ones as jumps in `seq`), and writing an entry allocates nothing — publish-subscribe in
/// iceoryx2 0.10 allocates a reference count per loaned sample. Created by the runner (it
/// knows the estimators); readers open it with `blackboard_opener::<u32>()`.
pub fn latest_estimates_board(
    node: &Node<ipc::Service>,
    prefix: &str,
    names: &[[u8; 16]],
) -> anyhow::Result<blackboard::PortFactory<ipc::Service, u32>> {
    let mut b = node
        .service_builder(&service_name(prefix, LATEST_ESTIMATES)?)
        .blackboard_creator::<u32>()
        .max_readers(8);
    for (i, name) in names.iter().enumerate() {
        let i = i as u32;
        b = b.add(i, Estimate::none_yet(i, *name));
    }
    b.create()
        .map_err(|e| explain_open(LATEST_ESTIMATES, prefix, e))
}

/// Service name (under the prefix) of [`latest_estimates_board`].
pub const LATEST_ESTIMATES: &str = "estimates-latest";

/// Opens (or creates) the event service notified after each published instant.
pub fn ready_event_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> anyhow::Result<event::PortFactory<ipc::Service>> {
    node.service_builder(&service_name(prefix, "slots-ready")?)
        .event()
        .max_notifiers(2)
        .max_listeners(4)
        .open_or_create()
        .map_err(|e| explain_open("slots-ready", prefix, e))
}

/// Event id used for "an instant's slots were published".
pub const READY_EVENT: EventId = EventId::new(1);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::FLAG_OCCLUDED;

    fn obs(k: u32, node: u8, delivered: bool) -> Observation {
        let mut y = [0.0; MAX_NY];
        if delivered {
            y[0] = 1.5;
            y[1] = -2.25;
        }
        Observation {
            k,
            node,
            delivered,
            ny: 2,
            y,
            flags: if delivered { 0 } else { FLAG_OCCLUDED },
        }
    }

    #[test]
    fn layouts_are_fixed_and_pointer_free() {
        // Sizes are part of the format: a change must bump WIRE_VERSION.
        assert_eq!(size_of::<Slot>(), 64 + 8 * MAX_NY);
        assert_eq!(size_of::<Truth>(), 24 + 8 * MAX_NX);
        assert_eq!(size_of::<Estimate>(), 56 + 8 * MAX_NX + 24);
        assert_eq!(core::mem::offset_of!(Slot, version), 0);
        assert_eq!(core::mem::offset_of!(Truth, version), 0);
        assert_eq!(core::mem::offset_of!(Estimate, version), 0);
        assert_eq!(align_of::<Slot>(), 8);
    }

    #[test]
    fn type_names_are_explicit() {
        // SAFETY: type_name has no preconditions; it is unsafe only to discourage overrides.
        #[allow(unsafe_code)]
        unsafe {
            assert_eq!(Slot::type_name(), "estpipe::wire::Slot");
            assert_eq!(Truth::type_name(), "estpipe::wire::Truth");
            assert_eq!(Estimate::type_name(), "estpipe::wire::Estimate");
        }
    }

    #[test]
    fn observation_round_trips() {
        for (k, node, delivered) in [(1, 0, true), (7, 2, false), (300, 1, true)] {
            let o = obs(k, node, delivered);
            let s = Slot::data(&o, 3, 42, 10, 20, 5);
            assert_eq!(s.seq, u64::from(k - 1) * 3 + u64::from(node));
            assert_eq!(Slot::position_of(s.seq, 3), (k, node));
            assert_eq!(s.observation().unwrap(), o);
        }
    }

    #[test]
    fn non_finite_values_pass_through_to_the_estimator() {
        let mut o = obs(3, 0, true);
        o.y[1] = f64::NAN;
        let back = Slot::data(&o, 1, 1, 0, 0, 0).observation().unwrap();
        assert!(back.y[1].is_nan());
    }

    #[test]
    fn wrong_version_and_bad_fields_are_refused() {
        let mut s = Slot::data(&obs(2, 1, true), 2, 1, 0, 0, 0);
        s.version = 99;
        let e = s.observation().unwrap_err();
        assert_eq!(e, WireError::Version { found: 99 });
        assert!(e.to_string().contains("version 99"));
        assert!(e.to_string().contains(&format!("version {WIRE_VERSION}")));

        let good = Slot::data(&obs(2, 1, true), 2, 1, 0, 0, 0);
        let mut s = good;
        s.node = 2;
        assert!(s.validate().is_err());
        let mut s = good;
        s.ny = MAX_NY as u8 + 1;
        assert!(s.validate().is_err());
        let mut s = good;
        s.seq += 1;
        assert!(s.validate().is_err());
        let mut s = good;
        s.k = 0;
        assert!(s.validate().is_err());
    }

    #[test]
    fn names_are_truncated_on_char_boundaries() {
        let mut e = Estimate {
            version: WIRE_VERSION,
            k: 1,
            stream_id: 0,
            seq: 0,
            estimator: 0,
            nx: 0,
            name: Estimate::encode_name("cce"),
            status: 0,
            reserved: 0,
            x: [0.0; MAX_NX],
            slot_send_ns: 0,
            receive_ns: 0,
            step_done_ns: 0,
        };
        assert_eq!(e.name(), "cce");
        e.name = Estimate::encode_name("ααααααααα"); // 18 bytes
        assert_eq!(e.name(), "αααααααα");
    }
}
