//! A zenoh subscriber's queue, read a burst at a time: each side serves several directions
//! and the stop from one thread, so no direction may hold the others up for long.

use anyhow::{anyhow, Result};
use zenoh::handlers::{FifoChannel, FifoChannelHandler};
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;
use zenoh::{Session, Wait};

/// Messages handled per pass before the other directions and the signal are looked at again.
pub(crate) const BURST: usize = 256;

/// A subscriber with its queue of samples.
pub(crate) type Inbox = Subscriber<FifoChannelHandler<Sample>>;

/// A subscriber to `<key>/<name>` that queues `queue` samples before the network pushes back.
pub(crate) fn subscriber(session: &Session, key: &str, name: &str, queue: usize) -> Result<Inbox> {
    session
        .declare_subscriber(format!("{key}/{name}"))
        .with(FifoChannel::new(queue))
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}/{name}: {e}"))
}

/// The samples waiting in `inbox`, at most [`BURST`]: what is left waits for the next pass.
/// None is taken that the burst does not hand out, so none is lost.
pub(crate) fn burst(inbox: &Inbox) -> impl Iterator<Item = Sample> + '_ {
    std::iter::from_fn(|| inbox.try_recv().ok().flatten()).take(BURST)
}
