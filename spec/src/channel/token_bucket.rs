//! Seed 003's token bucket (eq. 2) as the estimators know it: one bucket per node with
//! `a` tokens added per instant, `b` spent per transmission, capacity `S`, initial level `z0`.

use estimator_core::protocol::token_bucket::TokenBucketConfig;
use serde::Deserialize;

use crate::error::SpecError;

/// Token-bucket parameters: rate `a`, cost `b`, capacity `s` (the paper's S), initial level
/// `z0`. One bucket per sensor node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenBucket {
    /// Tokens added per instant.
    pub a: u32,
    /// Tokens spent per transmission.
    pub b: u32,
    /// Capacity S.
    pub s: u32,
    /// Initial level z₀.
    pub z0: u32,
}

impl TokenBucket {
    /// The validated core configuration; errors name `field.a`, `field.b`, ….
    pub fn config(&self, field: &str) -> Result<TokenBucketConfig, SpecError> {
        TokenBucketConfig::new(self.a, self.b, self.s, self.z0).map_err(|e| match e {
            estimator_core::Error::InvalidConfig { field: f, reason } => {
                SpecError::invalid(format!("{field}.{}", f.to_lowercase()), reason)
            }
            other => SpecError::invalid(field, other.to_string()),
        })
    }
}
