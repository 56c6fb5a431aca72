//! What the particle filters hold per particle: `eval` and `run` check a run's memory budget
//! against it before they build any.

use estpipe_spec::EstimatorSpec;

/// Bytes a particle filter holds per particle on a scenario with `nx` states (particles,
/// their copy while resampling, two log-weights), for both `pf` and `pf-mix`.
pub fn pf_bytes_per_particle(nx: usize) -> u64 {
    2 * 8 * (2 * nx as u64 + 2)
}

/// Bytes per particle of the particle filters built for `spec`: seed 001's (the larger, for
/// `pf` and `pf-mix`, [`pf_bytes_per_particle`]) or seed 004's `pf`, whose particles carry
/// every node's trigger state beside x ([`crate::pf_tobit::bytes_per_particle`]).
pub fn pf_bytes_per_particle_for(spec: &EstimatorSpec) -> u64 {
    pf_bytes_per_particle(spec.nx()).max(crate::pf_tobit::bytes_per_particle(spec))
}
