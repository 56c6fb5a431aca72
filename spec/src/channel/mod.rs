//! What an estimator knows of the channel between the sensors and itself: the parameters of
//! the channel effects whose outcome carries information (a dropout in an occlusion region, a
//! packet the token bucket withheld, a silent event trigger, a censored component), and
//! nothing of the random losses it cannot predict beyond a known rate.

pub mod event_trigger;
pub mod occlusion;
pub mod tobit;
pub mod token_bucket;

pub use event_trigger::{TriggerParams, TriggeredTokenBucket};
pub use occlusion::{Occlusion, MAX_OCCLUSION_REGIONS};
pub use tobit::TobitCensoring;
pub use token_bucket::TokenBucket;

/// The channel as the estimators know it; `None` where the channel has no such effect.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelKnowledge {
    /// Seed 001's occlusion regions (eqs. 2-3).
    pub occlusion: Option<Occlusion>,
    /// Seed 003's token bucket, one per node (eq. 2).
    pub token_bucket: Option<TokenBucket>,
    /// Seed 004's Tobit censoring thresholds τ_m (eq. 2).
    pub tobit: Option<TobitCensoring>,
    /// Seed 004's dynamic event triggers sharing one token bucket (eqs. 11-20).
    pub event_trigger: Option<TriggeredTokenBucket>,
}
