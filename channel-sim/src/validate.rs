//! Parameter checks shared by plants, channel stages and the initial distribution: the
//! estimator spec's ([`estpipe_spec::validate`]), every error naming the offending field.

pub use estpipe_spec::validate::*;
