//! Everything that names a zenoh type but the command line's configuration ([`crate::args`]):
//! the two sides, the session and how its queues are read. The rules they apply to the
//! stream are [`crate::link`]'s.
//!
//! | module | what |
//! |---|---|
//! | [`sensor`] | the sensor side: shared memory → zenoh (slots, truth), zenoh → shared memory (estimates) |
//! | [`estimator`] | the estimator side: zenoh → checked → shared memory (slots, truth), estimates back |
//! | `session` | the session opened, its publishers, a put a stop may cut short, a bounded close |
//! | `inbox` | a subscriber's queue, read a burst at a time |

pub mod estimator;
pub(crate) mod inbox;
pub mod sensor;
pub(crate) mod session;
