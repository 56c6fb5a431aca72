//! The publisher's iceoryx2 side: its node, the slot, truth and ready services, the ports on
//! them, and the gate that decides what a full subscriber queue does.

use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;
use estpipe_wire::{self as wire, Truth};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;

use super::PublisherArgs;
use crate::backpressure::{Gate, Mode};
use crate::sim::Scenario;
use crate::slot_sender::SlotSender;
use crate::wire::stream_header;

/// Everything the publisher sends through.
pub(super) struct Ports {
    pub(super) node: Arc<Node<ipc::Service>>,
    pub(super) slots: Arc<wire::services::SlotService>,
    pub(super) gate: Arc<Gate>,
    pub(super) sender: SlotSender,
    /// Node 0's process publishes the truth; the others have none.
    truth: Option<Publisher<ipc::Service, Truth, ()>>,
    pub(super) notifier: Notifier<ipc::Service>,
}

impl Ports {
    /// Creates the node (removing a SIGKILLed predecessor's ports first), the services and
    /// the ports; `with_truth` for the process that publishes node 0.
    pub(super) fn open(
        args: &PublisherArgs,
        scenario: &dyn Scenario,
        with_truth: bool,
    ) -> Result<Self> {
        let node = Arc::new(estpipe_process::node::create("channel-sim")?);
        let _ = node.try_cleanup_dead_nodes();
        let slots = Arc::new(wire::slot_service(&node, &args.prefix)?);
        let truth = wire::truth_service(&node, &args.prefix)?;
        let ready = wire::ready_event_service(&node, &args.prefix)?;
        let gate = Gate::new();
        gate.set_unread_limit(args.unread_limit);
        if let Some(pid) = args.parent_pid {
            gate.set_parent(pid);
        }
        gate.set_mode(if args.backpressure.blocks(args.rate) {
            Mode::Block
        } else {
            Mode::Discard
        });
        // What a failed creation left in /dev/shm is removed (estpipe_process::shm_leftovers).
        let since = std::time::SystemTime::now() - Duration::from_secs(1);
        let refused = |e, service: &str, hint: &str| {
            anyhow::anyhow!(estpipe_process::shm_leftovers::publisher_error(
                e,
                node.config(),
                since,
                &format!("{}/{service}", args.prefix),
                hint,
            ))
        };
        let publisher = slots
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            .set_backpressure_handler(gate.handler())
            .create()
            .map_err(|e| {
                let hint = format!(
                    "are {} publishers already running with this --prefix?",
                    wire::MAX_NODES
                );
                refused(e, "slots", &hint)
            })?;
        let truth = match with_truth {
            true => Some(truth.publisher_builder().create().map_err(|e| {
                let hint = "is another publisher of node 0 running with this --prefix?";
                refused(e, "truth", hint)
            })?),
            false => None,
        };
        let notifier = ready
            .notifier_builder()
            .default_event_id(wire::READY_EVENT)
            .create()
            .map_err(|e| anyhow::anyhow!("cannot notify on {}/slots-ready: {e:?}", args.prefix))?;
        let sender = SlotSender::new(
            publisher,
            stream_header(scenario),
            Arc::clone(&gate),
            Arc::clone(&node),
            Arc::clone(&slots),
        );
        Ok(Self {
            node,
            slots,
            gate,
            sender,
            truth,
            notifier,
        })
    }

    /// Publishes `t` if this process publishes the truth.
    pub(super) fn send_truth(&self, t: Truth) -> Result<()> {
        if let Some(p) = &self.truth {
            p.loan_uninit()?.write_payload(t).send()?;
        }
        Ok(())
    }

    /// The subscribers of the slots now.
    pub(super) fn subscribers(&self) -> usize {
        self.slots.dynamic_config().number_of_subscribers()
    }
}
