//! The QoS a publish-subscribe service of the contract is created with, and how a refusal
//! names it.

/// The QoS of a publish-subscribe service of the contract.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PubSubQos {
    /// Publishers the service admits.
    pub max_publishers: usize,
    /// Subscribers the service admits.
    pub max_subscribers: usize,
    /// Longest queue a subscriber may ask for.
    pub subscriber_max_buffer_size: usize,
    /// Samples a new subscriber receives on connecting.
    pub history_size: usize,
    /// `true`: a full queue overwrites its oldest sample; `false`: the publisher's
    /// back-pressure strategy decides (block or discard the new sample).
    pub safe_overflow: bool,
}

impl PubSubQos {
    /// `max_publishers ≥ 1, max_subscribers ≥ 4, …` as the refusals print it.
    pub fn describe(&self) -> String {
        format!(
            "max_publishers ≥ {}, max_subscribers ≥ {}, subscriber_max_buffer_size ≥ {}, \
             history_size ≥ {}, safe overflow {}",
            self.max_publishers,
            self.max_subscribers,
            self.subscriber_max_buffer_size,
            self.history_size,
            if self.safe_overflow { "on" } else { "off" }
        )
    }
}

/// The largest QoS a side accepts from a publish-subscribe service someone else created
/// (issue #39: a consumer that created `<prefix>/estimates` first with 128 subscribers × a
/// 1 M buffer made the runner allocate about 1.5 GB for its publisher's data segment, outside
/// `--max-memory`). Above any of these the open is refused in one line
/// ([`crate::services`]); within them a publisher's data segment is at most
/// [`QosLimit::segment_bytes`], which the runner counts in its `--max-memory`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QosLimit {
    /// Most publishers.
    pub max_publishers: usize,
    /// Most subscribers.
    pub max_subscribers: usize,
    /// Longest subscriber queue.
    pub subscriber_max_buffer_size: usize,
    /// Most samples a subscriber may hold at once.
    pub subscriber_max_borrowed_samples: usize,
    /// Longest history.
    pub history_size: usize,
    /// Most nodes that may open the service.
    pub max_nodes: usize,
}

/// The accepted maximum: twice the contract's counts (docs/wire.md, Services and QoS),
/// its queue length, a history of 64.
pub const QOS_LIMIT: QosLimit = QosLimit {
    max_publishers: 16,
    max_subscribers: 16,
    subscriber_max_buffer_size: 4096,
    subscriber_max_borrowed_samples: 16,
    history_size: 64,
    max_nodes: 64,
};

/// Bytes iceoryx2 0.10 adds to every sample of a data segment (its sample header and
/// alignment), counted generously.
pub const SAMPLE_OVERHEAD: u64 = 64;

impl QosLimit {
    /// The samples a publisher preallocates on a service of this QoS that loans up to
    /// `max_loaned` at once (iceoryx2 0.10: subscribers × (queue + borrowed) + history +
    /// loaned), times `sample_bytes` plus [`SAMPLE_OVERHEAD`] each.
    pub fn segment_bytes(&self, sample_bytes: usize, max_loaned: usize) -> u64 {
        let samples = self.max_subscribers as u64
            * (self.subscriber_max_buffer_size + self.subscriber_max_borrowed_samples) as u64
            + self.history_size as u64
            + max_loaned as u64;
        samples * (sample_bytes as u64 + SAMPLE_OVERHEAD)
    }

    /// The first setting of `have` above this limit, as `name value > limit`.
    pub fn exceeded_by(&self, have: &QosLimit) -> Option<String> {
        [
            ("max_publishers", have.max_publishers, self.max_publishers),
            (
                "max_subscribers",
                have.max_subscribers,
                self.max_subscribers,
            ),
            (
                "subscriber_max_buffer_size",
                have.subscriber_max_buffer_size,
                self.subscriber_max_buffer_size,
            ),
            (
                "subscriber_max_borrowed_samples",
                have.subscriber_max_borrowed_samples,
                self.subscriber_max_borrowed_samples,
            ),
            ("history_size", have.history_size, self.history_size),
            ("max_nodes", have.max_nodes, self.max_nodes),
        ]
        .into_iter()
        .find(|(_, h, l)| h > l)
        .map(|(n, h, l)| format!("{n} {h} > {l}"))
    }
}
