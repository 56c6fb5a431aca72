//! The rate of the pipeline runs, and of the paced runs they are compared with.

/// Slots (pings, works) per second of every paced run.
pub const PIPELINE_RATE: f64 = 10_000.0;
