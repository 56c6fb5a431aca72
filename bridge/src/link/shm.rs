//! This host's end of the bridge: the prefix's iceoryx2 services, which both sides open alike,
//! and one sample written into one of them.

use anyhow::{anyhow, Result};
use estpipe_wire::{self as wire, Estimate, Slot, StreamHeader, Truth};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::fmt::Debug;

/// The prefix's services, and the node that holds them. It lives as long as the bridge: the
/// runner tells a bridge from a publisher by its node's name ([`crate::NODE_NAME`]).
pub(crate) struct Services {
    pub node: Node<ipc::Service>,
    pub slots: publish_subscribe::PortFactory<ipc::Service, Slot, StreamHeader>,
    pub truth: publish_subscribe::PortFactory<ipc::Service, Truth, ()>,
    pub estimates: publish_subscribe::PortFactory<ipc::Service, Estimate, ()>,
    pub ready: event::PortFactory<ipc::Service>,
}

impl Services {
    /// Opens (or creates) the services of `prefix`.
    pub(crate) fn open(prefix: &str) -> Result<Self> {
        let node = estpipe_process::node::create(crate::NODE_NAME)?;
        // A predecessor killed on this prefix would otherwise still hold its ports.
        let _ = node.try_cleanup_dead_nodes();
        Ok(Self {
            slots: wire::slot_service(&node, prefix)?,
            truth: wire::truth_service(&node, prefix)?,
            estimates: wire::estimate_service(&node, prefix)?,
            ready: wire::ready_event_service(&node, prefix)?,
            node,
        })
    }
}

/// A subscriber of `service` (`<prefix>/<name>`) with the largest queue the contract allows:
/// a bridge that falls behind for a moment must not lose what it forwards.
pub(crate) fn subscribe<T: IceoryxSend + Debug, H: Debug + ZeroCopySend>(
    service: &publish_subscribe::PortFactory<ipc::Service, T, H>,
    prefix: &str,
    name: &str,
) -> Result<Subscriber<ipc::Service, T, H>> {
    service
        .subscriber_builder()
        .buffer_size(wire::MAX_SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {prefix}/{name}: {e:?}"))
}

/// Writes `value` into a sample of `publisher` and sends it; an error names `what`.
pub(crate) fn write<T: IceoryxSend + ZeroCopySend + Debug>(
    publisher: &Publisher<ipc::Service, T, ()>,
    value: T,
    what: &str,
) -> Result<()> {
    let out = publisher
        .loan_uninit()
        .map_err(|e| anyhow!("{what}: {e:?}"))?
        .write_payload(value);
    out.send().map_err(|e| anyhow!("{what}: {e:?}"))?;
    Ok(())
}
