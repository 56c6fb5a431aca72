//! What an evaluation will hold, checked before any run: the worker threads, the estimators
//! that apply, and the runs a chunk may hold within the memory budget.

use channel_sim::Scenario;

use super::{build_all, product, Factory, Role, RunStart};
use super::{memory_need, Control, EvalOptions, RunConfig, CHUNK};
use crate::estimators::pf_bytes_per_particle_for;

/// An evaluation's shape, once it fits the budget.
pub(super) struct Plan {
    /// Worker threads.
    pub(super) threads: usize,
    /// The estimators run 0 builds, and each one's role.
    pub(super) names: Vec<&'static str>,
    pub(super) roles: Vec<Role>,
    /// Runs computed before their results are reduced.
    pub(super) chunk: u64,
}

impl Plan {
    /// `Err` for options out of range, no estimator that applies, or a budget too small.
    pub(super) fn check(
        scenario: &dyn Scenario,
        options: &EvalOptions,
        factories: &[Factory],
        config: &RunConfig,
        control: &Control<'_>,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(options.runs >= 1, "--runs must be at least 1");
        anyhow::ensure!(options.horizon >= 1, "--steps must be at least 1");
        // Not rayon's global pool, which panics when RAYON_NUM_THREADS asks for more threads
        // than can start: the count is ours, and the pool built below is given it.
        let threads = config
            .threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        // Before anything is built: the particle filters allocate their particles at once.
        let spec = scenario.estimator_spec();
        let pf = product(&[
            options.particles as u64,
            pf_bytes_per_particle_for(&spec),
            threads as u64 + 1,
        ]);
        control.budget.check(
            &format!("--particles {} on {threads} thread(s)", options.particles),
            pf,
        )?;
        let probe = RunStart {
            seed: options.seed,
            run: 0,
            initial: None,
        };
        let (names, roles): (Vec<&'static str>, Vec<Role>) =
            build_all(factories, &spec, options, &probe)?
                .iter()
                .map(|e| (e.name(), Role::of_estimator(e.name(), e.full_information())))
                .unzip();
        anyhow::ensure!(
            !names.is_empty(),
            "no estimator applies to scenario '{}'",
            scenario.name()
        );
        let chunk = Self::chunk(scenario, options, names.len(), threads, pf, control)?;
        Ok(Self {
            threads,
            names,
            roles,
            chunk,
        })
    }

    /// The runs a chunk may hold beside the reductions and the particles (`pf` bytes).
    fn chunk(
        scenario: &dyn Scenario,
        options: &EvalOptions,
        estimators: usize,
        threads: usize,
        pf: u64,
        control: &Control<'_>,
    ) -> anyhow::Result<u64> {
        let (fixed, per_run) =
            memory_need(scenario.nx(), estimators, options.horizon, options.runs);
        let held = fixed.saturating_add(pf);
        // Each thread computes one run, and a chunk holds at least one run per thread.
        let minimum = held.saturating_add(product(&[2, threads as u64, per_run]));
        control.budget.check(
            &format!(
                "--runs {} --steps {} ({} estimators × {} states, {threads} thread(s))",
                options.runs,
                options.horizon,
                estimators,
                scenario.nx()
            ),
            minimum,
        )?;
        Ok(((control.budget.bytes - held) / per_run.max(1))
            .saturating_sub(threads as u64)
            .clamp(threads as u64, CHUNK))
    }
}
