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
