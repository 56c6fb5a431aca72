//! Every estimator the pipeline runs, behind one object-safe trait ([`Estimator`]) that
//! `eval`, the real-time loop and `replay` drive alike, and the registry that builds them
//! from a spec: which estimators apply to a scenario, built fresh for every run.
//!
//! This crate knows the core's filters, the spec and the wire's observations, nothing else:
//! no simulator, no loop, no Monte Carlo (docs/design.md, "Crates").
//!
//! ```
//! use estpipe_estimators::{build_all, BuildOptions, RunStart, FACTORIES};
//!
//! // What the estimators know, as a user writes it (specs/linear.toml): a two-state model
//! // seen by one position sensor.
//! let spec = estpipe_spec::file::parse(include_str!("../../specs/linear.toml"), "linear.toml", "linear")?;
//! let mut estimators = build_all(FACTORIES, &spec.into(), &BuildOptions::default(), &RunStart::default())?;
//! let names: Vec<_> = estimators.iter().map(|e| e.name()).collect();
//! // `kf` is eval's full-information oracle; `ikf` reads what the channel delivers.
//! assert_eq!(names, ["kf", "ikf"]);
//! // One instant: node 0 measured y = 0.3 and its slot arrived.
//! let mut y = estpipe_wire::Observation::dropped(1, 0, 1, 0);
//! (y.delivered, y.y[0]) = (true, 0.3);
//! estimators[1].step(1, &[y])?;
//! let mut x = [0.0; 2];
//! estimators[1].estimate(&mut x);
//! assert!(x[0] > 0.0 && x[0] < 0.3);
//! # Ok::<(), anyhow::Error>(())
//! ```
//!
//! Each estimator family is one file with a [`Factory`]; a family returns an empty list for
//! scenarios it does not apply to. Adding a family is one file and one line in [`FACTORIES`].
//!
//! The families run estimator-core's estimators through the core's one interface
//! ([`estimator_core::Estimator`], mostly a filter paired with its model in an
//! [`estimator_core::OnModel`]); the application's [`Estimator`] over one is `adapter`'s, the
//! stepping from slot observations `fed`'s, the conversion of the observations into the core's
//! measurements `slots`', of the spec's model into fixed-size matrices `snapshot`'s. `pf` is
//! the application's own particle filter and implements [`Estimator`] directly.
//!
//! Every family reads only the [`EstimatorSpec`](estpipe_spec::EstimatorSpec) (the model, the
//! prior, what is known of the channel) and the run's [`RunStart`]: never a simulator. A
//! simulated scenario produces its spec; a user writes one (`run --estimator-spec FILE`).

mod estimator;
mod memory;
#[cfg(test)]
mod presets;
mod registry;

mod adapter;
mod fed;
pub mod ikf;
pub mod kf;
mod lagged;
pub mod nn;
pub mod occlusion;
mod particles_rng;
pub mod pf;
pub mod pf_tobit;
pub mod role;
pub mod silence_kf;
mod slots;
mod snapshot;
pub mod tobit;
pub mod tobit_central;

pub use estimator::{CovarianceKind, Estimator, LateFold};
pub use lagged::MAX_LAG;
pub use memory::{pf_bytes_per_particle, pf_bytes_per_particle_for};
pub use registry::{
    build_all, gate_counts, gate_probability, names_match, BuildOptions, Factory, RunStart,
    FACTORIES,
};

#[cfg(test)]
mod tests {
    /// The crate's rule, which Cargo enforces once it is in the manifest: of the product's
    /// crates, only the core, the spec and the wire (docs/design.md, "Crates").
    #[test]
    fn depends_on_the_core_the_spec_and_the_wire_only() {
        let manifest = include_str!("../Cargo.toml");
        let deps = manifest
            .split("[dependencies]")
            .nth(1)
            .and_then(|rest| rest.split("\n[").next())
            .expect("a [dependencies] table");
        let ours: Vec<&str> = deps
            .lines()
            .filter(|l| l.contains("workspace = true"))
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        assert_eq!(ours, ["estimator-core", "estpipe-spec", "estpipe-wire"]);
    }
}
