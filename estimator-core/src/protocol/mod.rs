//! Communication-protocol models that run on a sensor node as well as in simulation: the
//! token bucket (seed 003 eq. 2; seed 004 eqs. 16-18), the dynamic event trigger (seed 004
//! eqs. 11-15), Tobit censoring (seed 004 eq. 2) and occlusion regions (seed 001 eqs. 2-3).
//!
//! Each lives in its own file, added by the issue that implements it. Two are the receiver's
//! side of seed 004's protocol: [`bucket_mirror`] (the shared bucket recomputed from the
//! transmissions the receiver sees) and [`trigger_knowledge`] (the silence set of a node's
//! trigger: its reference and the largest threshold it can have).

pub mod bucket_mirror;
pub mod event_trigger;
pub mod occlusion;
pub mod shared_token_bucket;
pub mod tobit;
pub mod token_bucket;
pub mod trigger_knowledge;
