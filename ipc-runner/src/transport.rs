//! The runner's side of the shared-memory services (see `estpipe_wire` and `docs/wire.md`).
//!
//! Ports are created in an order that makes the publisher's "wait for a subscriber" safe:
//! truth subscriber and event listener first, the slot subscriber last — channel-sim starts
//! publishing as soon as the slot subscriber exists, and by then everything else is connected.

use anyhow::{anyhow, Result};
use estpipe_wire::services::SlotService;
use estpipe_wire::{self as wire, Estimate, Slot, StreamHeader, Truth};
use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

/// Estimate samples the loop loans ahead (one per estimator, up to this many); the publisher
/// allows one more, for the estimators past it, which loan at send time.
pub const PRELOANED_ESTIMATES: usize = 16;

/// Open ports of one runner.
#[derive(Debug)]
pub struct Transport {
    /// The runner's iceoryx2 node (signal handling, dead-node cleanup).
    pub node: Node<ipc::Service>,
    /// Slot service (for publisher counts).
    pub slots: SlotService,
    /// Slot subscriber; every slot's user header is the stream's [`StreamHeader`].
    pub slot_sub: Subscriber<ipc::Service, Slot, StreamHeader>,
    /// Truth subscriber (evaluation beside the loop).
    pub truth_sub: Subscriber<ipc::Service, Truth, ()>,
    /// Estimate publisher.
    pub estimate_pub: Publisher<ipc::Service, Estimate, ()>,
    /// Listener of `slots-ready` (only in blocking mode).
    pub listener: Option<Listener<ipc::Service>>,
    /// `CLOCK_MONOTONIC` just before the slot subscriber was created.
    pub subscribed_ns: u64,
}

impl Transport {
    /// Opens (or creates) the services under `prefix` with a slot queue of `buffer` samples.
    pub fn open(prefix: &str, buffer: usize, with_listener: bool) -> Result<Self> {
        if buffer == 0 || buffer > wire::MAX_SUBSCRIBER_BUFFER {
            return Err(anyhow!(
                "--buffer must be in 1..={}, got {buffer}",
                wire::MAX_SUBSCRIBER_BUFFER
            ));
        }
        let node = estpipe_process::node::create("ipc-runner")?;
        // Remove what SIGKILLed processes left behind (their ports would count as connected).
        let _ = node.try_cleanup_dead_nodes();
        let truth = wire::truth_service(&node, prefix)?;
        let estimates = wire::estimate_service(&node, prefix)?;
        let slots = wire::slot_service(&node, prefix)?;
        let truth_sub = truth
            .subscriber_builder()
            .buffer_size(wire::MAX_SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow!("cannot subscribe to {prefix}/truth: {e:?}"))?;
        // What a failed creation left in /dev/shm is removed (estpipe_process::shm_leftovers).
        let since = std::time::SystemTime::now() - std::time::Duration::from_secs(1);
        let estimate_pub = estimates
            .publisher_builder()
            .max_loaned_samples(PRELOANED_ESTIMATES + 1)
            .create()
            .map_err(|e| {
                anyhow!(estpipe_process::shm_leftovers::publisher_error(
                    e,
                    node.config(),
                    since,
                    &format!("{prefix}/estimates"),
                    "is another runner using this --prefix?",
                ))
            })?;
        let listener = if with_listener {
            let ready = wire::ready_event_service(&node, prefix)?;
            Some(
                ready
                    .listener_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot listen on {prefix}/slots-ready: {e:?}"))?,
            )
        } else {
            None
        };
        let subscribed_ns = wire::monotonic_ns();
        let slot_sub = slots
            .subscriber_builder()
            .buffer_size(buffer)
            .create()
            .map_err(|e| anyhow!("cannot subscribe to {prefix}/slots: {e:?}"))?;
        Ok(Self {
            node,
            slots,
            slot_sub,
            truth_sub,
            estimate_pub,
            listener,
            subscribed_ns,
        })
    }

    /// Publishers currently registered on the slot service.
    pub fn publishers(&self) -> usize {
        self.slots.dynamic_config().number_of_publishers()
    }

    /// Whether slot publisher `origin` (a sample's [`UniquePublisherId`] value) belongs to
    /// the estimator side of a bridge (a node named
    /// [`estpipe_process::node::BRIDGE_NODE_NAME`]): a relay, which may go away and come back
    /// with the same stream (docs/bridge.md, "A bridge that goes away"). Lists the service's
    /// publishers and the nodes: a cold path, asked once per new publisher.
    ///
    /// [`UniquePublisherId`]: iceoryx2::identifiers::UniquePublisherId
    pub fn is_bridge(&self, origin: u128) -> bool {
        let mut node = None;
        self.slots.dynamic_config().list_publishers(|p| {
            if p.publisher_id.value() == origin {
                node = Some(p.node_id);
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        let Some(node) = node else { return false };
        match Node::<ipc::Service>::state_of(self.node.config(), node) {
            Ok(Some(NodeState::Alive(v))) => v
                .details()
                .as_ref()
                .is_some_and(|d| d.name().as_str() == estpipe_process::node::BRIDGE_NODE_NAME),
            _ => false,
        }
    }
}
