//! The services under a prefix, the QoS every side opens them with, and the functions that
//! open (or create) them so.
//!
//! | service | pattern | payload (user header) | written by |
//! |---|---|---|---|
//! | `<prefix>/slots` | publish-subscribe | [`Slot`] ([`StreamHeader`]) | the sensor side (channel-sim, a foreign publisher) |
//! | `<prefix>/slots-ready` | event, id [`READY_EVENT`] | – | the sensor side, after each instant |
//! | `<prefix>/truth` | publish-subscribe | [`Truth`] | channel-sim (evaluation only) |
//! | `<prefix>/estimates` | publish-subscribe | [`Estimate`] | ipc-runner |
//! | `<prefix>/estimates-latest` | blackboard, key `u32` | [`Estimate`] | ipc-runner (`--latest-estimates`) |
//!
//! Whoever comes first creates a service with the QoS below; whoever comes second opens it
//! and requires at least that QoS, so a service created by a foreign process with iceoryx2's
//! defaults is refused with one line that names what the contract requires
//! ([`crate::explain`]).

use crate::error::ContractError;
use crate::explain;
pub use crate::qos::{PubSubQos, QosLimit, QOS_LIMIT};
use crate::{Estimate, Slot, StreamHeader, Truth};
use iceoryx2::port::event_id::EventId;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{blackboard, event, publish_subscribe};

/// Default service-name prefix.
pub const DEFAULT_PREFIX: &str = "estpipe";

/// Instants a stream has unless a command is told otherwise (the publisher's and the
/// runner's `--steps`).
pub const DEFAULT_STEPS: u32 = 100;

/// Sampling rate in Hz a publisher paces its instants at unless told otherwise
/// (`channel-sim --rate`, `ipc-runner demo --rate`): one default for every command.
pub const DEFAULT_RATE_HZ: f64 = 1000.0;

/// Service name (under the prefix) of the slots.
pub const SLOTS: &str = "slots";
/// Service name (under the prefix) of the "an instant was published" event.
pub const SLOTS_READY: &str = "slots-ready";
/// Service name (under the prefix) of the truth.
pub const TRUTH: &str = "truth";
/// Service name (under the prefix) of the estimate queue.
pub const ESTIMATES: &str = "estimates";
/// Service name (under the prefix) of the latest-estimate blackboard.
pub const LATEST_ESTIMATES: &str = "estimates-latest";

/// Subscriber queue capacity the services are created with (a subscriber may use less).
pub const MAX_SUBSCRIBER_BUFFER: usize = 4096;

/// Estimates a new subscriber of `<prefix>/estimates` receives on connecting: the newest of
/// every estimator while the runner runs at most this many.
pub const ESTIMATE_HISTORY: usize = 16;

/// Event id notified on `<prefix>/slots-ready` after each instant's slots were sent.
pub const READY_EVENT: EventId = EventId::new(1);

/// `<prefix>/slots`: up to one publisher per sensor node ([`MAX_NODES`](crate::MAX_NODES);
/// each node is its own stream, `docs/wire.md`, Stream rules); no overflow, so a full queue
/// is the publisher's to handle (it blocks at `--rate 0`, discards and the runner counts the
/// gap when paced).
pub const SLOTS_QOS: PubSubQos = PubSubQos {
    max_publishers: crate::MAX_NODES,
    max_subscribers: 4,
    subscriber_max_buffer_size: MAX_SUBSCRIBER_BUFFER,
    history_size: 0,
    safe_overflow: false,
};

/// `<prefix>/truth`: never blocks the publisher.
pub const TRUTH_QOS: PubSubQos = PubSubQos {
    max_publishers: 1,
    max_subscribers: 4,
    subscriber_max_buffer_size: MAX_SUBSCRIBER_BUFFER,
    history_size: 0,
    safe_overflow: true,
};

/// `<prefix>/estimates`: a slow reader sees gaps in `seq` and never blocks the runner; a
/// late one gets the newest [`ESTIMATE_HISTORY`] estimates.
pub const ESTIMATES_QOS: PubSubQos = PubSubQos {
    max_publishers: 1,
    max_subscribers: 8,
    subscriber_max_buffer_size: MAX_SUBSCRIBER_BUFFER,
    history_size: ESTIMATE_HISTORY,
    safe_overflow: true,
};

/// Notifiers and listeners `<prefix>/slots-ready` admits.
pub const READY_MAX_NOTIFIERS: usize = crate::MAX_NODES;
/// Listeners `<prefix>/slots-ready` admits.
pub const READY_MAX_LISTENERS: usize = 4;
/// Readers `<prefix>/estimates-latest` admits.
pub const LATEST_MAX_READERS: usize = 8;

/// The slot service's port factory.
pub type SlotService = publish_subscribe::PortFactory<ipc::Service, Slot, StreamHeader>;

/// Full service name `<prefix>/<what>`.
pub fn service_name(prefix: &str, what: &str) -> Result<ServiceName, ContractError> {
    let s = format!("{prefix}/{what}");
    ServiceName::new(&s)
        .map_err(|e| ContractError::Refused(format!("invalid service name {s:?}: {e:?}")))
}

/// Opens (or creates) `<prefix>/<what>` with payload `T`, user header `H` and `qos`.
fn pubsub_service<T, H>(
    node: &Node<ipc::Service>,
    prefix: &str,
    what: &str,
    qos: &PubSubQos,
) -> Result<publish_subscribe::PortFactory<ipc::Service, T, H>, ContractError>
where
    T: ZeroCopySend + core::fmt::Debug + 'static,
    H: ZeroCopySend + core::fmt::Debug + 'static,
{
    let name = service_name(prefix, what)?;
    let service = node
        .service_builder(&name)
        .publish_subscribe::<T>()
        .user_header::<H>()
        .max_publishers(qos.max_publishers)
        .max_subscribers(qos.max_subscribers)
        .subscriber_max_buffer_size(qos.subscriber_max_buffer_size)
        .history_size(qos.history_size)
        .enable_safe_overflow(qos.safe_overflow)
        .open_or_create()
        .map_err(|e| explain::pubsub_open::<T, H>(node, &name, qos, &format!("{e:?}")))?;
    within_limit(&name, service.static_config())?;
    Ok(service)
}

/// Refuses a service whose QoS is above [`QOS_LIMIT`] (iceoryx2 only checks that an opened
/// service offers *at least* what the opener asks for; its creator chooses how much every
/// publisher preallocates).
fn within_limit(
    name: &ServiceName,
    c: &iceoryx2::service::static_config::publish_subscribe::StaticConfig,
) -> Result<(), ContractError> {
    let have = QosLimit {
        max_publishers: c.max_publishers(),
        max_subscribers: c.max_subscribers(),
        subscriber_max_buffer_size: c.subscriber_max_buffer_size(),
        subscriber_max_borrowed_samples: c.subscriber_max_borrowed_samples(),
        history_size: c.history_size(),
        max_nodes: c.max_nodes(),
    };
    match QOS_LIMIT.exceeded_by(&have) {
        None => Ok(()),
        Some(what) => Err(ContractError::Refused(format!(
            "service {name} was created with {what}, above what this side accepts \
             (max_publishers ≤ {}, max_subscribers ≤ {}, subscriber_max_buffer_size ≤ {}, \
             subscriber_max_borrowed_samples ≤ {}, history_size ≤ {}, max_nodes ≤ {}: its \
             publishers would preallocate that much shared memory); remove it (stop the process \
             that created it) or use another --prefix (docs/wire.md, Services and QoS)",
            QOS_LIMIT.max_publishers,
            QOS_LIMIT.max_subscribers,
            QOS_LIMIT.subscriber_max_buffer_size,
            QOS_LIMIT.subscriber_max_borrowed_samples,
            QOS_LIMIT.history_size,
            QOS_LIMIT.max_nodes
        ))),
    }
}

/// Opens (or creates) the slot service.
pub fn slot_service(node: &Node<ipc::Service>, prefix: &str) -> Result<SlotService, ContractError> {
    pubsub_service(node, prefix, SLOTS, &SLOTS_QOS)
}

/// Opens (or creates) the truth service.
pub fn truth_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<publish_subscribe::PortFactory<ipc::Service, Truth, ()>, ContractError> {
    pubsub_service(node, prefix, TRUTH, &TRUTH_QOS)
}

/// Opens (or creates) the estimate service.
pub fn estimate_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<publish_subscribe::PortFactory<ipc::Service, Estimate, ()>, ContractError> {
    pubsub_service(node, prefix, ESTIMATES, &ESTIMATES_QOS)
}

/// Creates the latest-estimate blackboard `<prefix>/estimates-latest`: one entry per
/// estimator, key = its index in the runner's list, value = its newest [`Estimate`]. Unlike
/// the `estimates` queue it keeps no history (a reader gets the newest value and sees skipped
/// ones as jumps in `seq`), and writing an entry allocates nothing — publish-subscribe in
/// iceoryx2 0.10 allocates a reference count per loaned sample. Created by the runner (it
/// knows the estimators); readers open it with `blackboard_opener::<u32>()`.
///
/// A blackboard lives as long as a port of it does: a reader left open after its runner
/// ended keeps it (issue #39: the next `--latest-estimates` runner failed with
/// `AlreadyExists`). Such a board is opened again instead, and the caller writes it if it
/// can (its one writer, the old runner, is gone; its entries are this runner's
/// estimators: [`LATEST_ENTRIES_DIFFER`] otherwise).
pub fn latest_estimates_board(
    node: &Node<ipc::Service>,
    prefix: &str,
    names: &[[u8; 16]],
) -> Result<blackboard::PortFactory<ipc::Service, u32>, ContractError> {
    let name = service_name(prefix, LATEST_ESTIMATES)?;
    let mut b = node
        .service_builder(&name)
        .blackboard_creator::<u32>()
        .max_readers(LATEST_MAX_READERS);
    for (i, n) in names.iter().enumerate() {
        let i = i as u32;
        b = b.add(i, Estimate::none_yet(i, *n));
    }
    match b.create() {
        Ok(board) => Ok(board),
        Err(iceoryx2::service::builder::blackboard::BlackboardCreateError::AlreadyExists) => node
            .service_builder(&name)
            .blackboard_opener::<u32>()
            .max_readers(LATEST_MAX_READERS)
            .open()
            .map_err(|e| explain::other_open(&name, "blackboard", &format!("{e:?}"))),
        Err(e) => Err(explain::other_open(&name, "blackboard", &format!("{e:?}"))),
    }
}

/// The end of the line refusing a latest-estimate blackboard left by an earlier run whose
/// entries are not this runner's estimators.
pub const LATEST_ENTRIES_DIFFER: &str =
    "it was created by an earlier runner with other estimators and is kept by a reader still \
     open: close that reader (or use another --prefix)";

/// Opens (or creates) the event service notified with [`READY_EVENT`] after each instant.
pub fn ready_event_service(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<event::PortFactory<ipc::Service>, ContractError> {
    let name = service_name(prefix, SLOTS_READY)?;
    node.service_builder(&name)
        .event()
        .max_notifiers(READY_MAX_NOTIFIERS)
        .max_listeners(READY_MAX_LISTENERS)
        .open_or_create()
        .map_err(|e| explain::other_open(&name, "event", &format!("{e:?}")))
}
