//! A known control input: `x_{k+1} = A x_k + B_u u_k + B w_k`, with `u_k` a deterministic
//! schedule that the plant and every estimator evaluate alike: the estimator spec's
//! ([`estpipe_spec::control`]).

pub use estpipe_spec::control::*;
