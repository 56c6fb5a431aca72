//! Real-time niceties that need privileges: CPU pinning and memory locking. Both are
//! best-effort — the outcome is reported, never fatal (`Machine` is what a run got).

use super::args::{RunArgs, WaitMode};

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), String> {
    // SAFETY: `set` is a plain bit set initialised by CPU_ZERO before use; the pointer and size
    // passed to sched_setaffinity describe it exactly.
    #[allow(unsafe_code)]
    unsafe {
        let mut set: libc::cpu_set_t = core::mem::zeroed();
        libc::CPU_ZERO(&mut set);
        if cpu >= 8 * size_of::<libc::cpu_set_t>() {
            return Err(format!("CPU {cpu} out of range"));
        }
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, size_of::<libc::cpu_set_t>(), &set) != 0 {
            return Err(std::io::Error::last_os_error().to_string());
        }
    }
    Ok(())
}

/// Locks current and future pages in RAM (no page faults in the loop).
pub fn lock_memory() -> Result<(), String> {
    // SAFETY: mlockall has no memory-safety preconditions.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc != 0 {
        return Err(std::io::Error::last_os_error().to_string());
    }
    Ok(())
}

/// The stall a thread that never sleeps gets under Linux's real-time throttling, if any:
/// `SCHED_FIFO`/`SCHED_RR` tasks may run `runtime_us` of every `period_us` (by default 950 ms
/// of every second), and a busy-polling loop uses all of it, so the kernel stops it for the
/// rest of every period. `runtime_us = -1` turns throttling off.
pub fn rt_throttle_stall_us(realtime: bool, runtime_us: i64, period_us: i64) -> Option<i64> {
    (realtime && runtime_us >= 0 && runtime_us < period_us).then_some(period_us - runtime_us)
}

/// A warning for `--wait spin` when the calling thread runs under a real-time policy with
/// throttling on: the throttled part of every period becomes the spin pipeline's tail
/// latency (measured under `chrt -f 10` in `docs/pipeline.md`).
pub fn spin_under_rt_throttling() -> Option<String> {
    // SAFETY: sched_getscheduler(0) only reads the calling thread's policy.
    #[allow(unsafe_code)]
    let policy = unsafe { libc::sched_getscheduler(0) };
    let realtime = policy == libc::SCHED_FIFO || policy == libc::SCHED_RR;
    if !realtime {
        return None;
    }
    let read = |name: &str| -> Option<i64> {
        std::fs::read_to_string(format!("/proc/sys/kernel/{name}"))
            .ok()?
            .trim()
            .parse()
            .ok()
    };
    let (runtime, period) = (read("sched_rt_runtime_us")?, read("sched_rt_period_us")?);
    let stall = rt_throttle_stall_us(realtime, runtime, period)?;
    Some(format!(
        "warning: --wait spin under a real-time policy with RT throttling on \
         (kernel.sched_rt_runtime_us = {runtime} of {period}): the kernel stops a thread \
         that never sleeps for {} ms of every {} ms, which becomes the loop's tail latency. \
         Use --wait block or listener, or set kernel.sched_rt_runtime_us = -1 on a machine \
         with a core isolated for the loop.",
        stall / 1000,
        period / 1000
    ))
}

/// What `--cpu` and `--mlock` achieved, and set-up conditions that will show in the latency.
pub(super) struct Machine {
    pub(super) cpu_pinning: Option<String>,
    pub(super) memory_lock: Option<String>,
    pub(super) warnings: Vec<String>,
}

impl Machine {
    pub(super) fn set_up(args: &RunArgs) -> Self {
        let cpu_pinning = args.cpu.map(|c| match pin_to_cpu(c) {
            Ok(()) => format!("pinned to CPU {c}"),
            Err(e) => format!("not pinned ({e})"),
        });
        let memory_lock = args.mlock.then(|| match lock_memory() {
            Ok(()) => "locked".to_string(),
            Err(e) => format!("not locked ({e})"),
        });
        if !args.quiet {
            for m in cpu_pinning.iter().chain(memory_lock.iter()) {
                estpipe_process::errln!("ipc-runner: {m}");
            }
        }
        // After pinning: a warning, not a refusal (a machine with throttling off passes).
        let warnings: Vec<String> = (args.wait == WaitMode::Spin)
            .then(spin_under_rt_throttling)
            .flatten()
            .into_iter()
            .collect();
        for w in &warnings {
            estpipe_process::errln!("ipc-runner: {w}");
        }
        Self {
            cpu_pinning,
            memory_lock,
            warnings,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn throttling_stalls_only_realtime_threads_with_a_budget_below_the_period() {
        assert_eq!(rt_throttle_stall_us(true, 950_000, 1_000_000), Some(50_000));
        assert_eq!(rt_throttle_stall_us(true, -1, 1_000_000), None);
        assert_eq!(rt_throttle_stall_us(true, 1_000_000, 1_000_000), None);
        assert_eq!(rt_throttle_stall_us(false, 950_000, 1_000_000), None);
    }

    #[test]
    fn a_normal_thread_gets_no_warning() {
        // Tests run under SCHED_OTHER (CI and here); a real-time test runner would be odd.
        // SAFETY: as in spin_under_rt_throttling.
        #[allow(unsafe_code)]
        let policy = unsafe { libc::sched_getscheduler(0) };
        if policy == libc::SCHED_OTHER {
            assert_eq!(spin_under_rt_throttling(), None);
        }
    }
}
