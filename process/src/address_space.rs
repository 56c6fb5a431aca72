//! The address-space limit (`ulimit -v`, `RLIMIT_AS`): what a process may map, shared
//! memory and thread stacks included. Under a tight one, `eval` aborted ("memory allocation
//! of 80 bytes failed") 3 times in 10 and `run` blamed "another runner using this --prefix"
//! (issue #39, item 16; docs/security.md, "Limits of the machine").
//!
//! Why `eval` aborted at random: glibc gives every thread that allocates an arena of its
//! own, and an arena reserves 64 MiB of address space. Under the limit a worker thread that
//! came too late for one got none, and then glibc maps every allocation of that thread
//! separately, a page or more each, until the limit is reached and an allocation fails
//! (which Rust turns into an abort). Which thread came late was a matter of scheduling.
//! [`share_one_heap`] makes every thread use the main heap when a limit is set, so the
//! process's address space grows with what it allocates, and the commands leave room for
//! what their budget does not count ([`headroom`]).

/// The soft `RLIMIT_AS` in bytes; `None` when there is none (`unlimited`).
pub fn limit() -> Option<u64> {
    let mut r = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes the struct we own.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut r) };
    (rc == 0 && r.rlim_cur != libc::RLIM_INFINITY).then_some(r.rlim_cur)
}

/// The address space this process has mapped (`VmSize` of `/proc/self/status`), in bytes.
pub fn in_use() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmSize:"))?
        .trim()
        .strip_suffix("kB")?
        .trim()
        .parse()
        .ok()?;
    Some(kib.saturating_mul(1024))
}

/// What the limit leaves: `Some((limit, left))` in bytes under a limit, `None` without one
/// (or where the address space in use cannot be read).
pub fn headroom() -> Option<(u64, u64)> {
    let limit = limit()?;
    Some((limit, limit.saturating_sub(in_use()?)))
}

/// `the address-space limit (ulimit -v N)`, N in KiB as `ulimit -v` takes it.
pub fn describe(limit: u64) -> String {
    format!("the address-space limit (ulimit -v {})", limit / 1024)
}

/// Under an address-space limit, every thread allocates from the main heap (glibc's
/// `M_ARENA_MAX` = 1) instead of reserving 64 MiB of address space for an arena of its
/// own. Without a limit nothing changes. Call it first thing in `main`, before any thread.
pub fn share_one_heap() {
    if limit().is_some() {
        #[cfg(all(target_os = "linux", target_env = "gnu"))]
        // SAFETY: mallopt changes a tunable of glibc's allocator; called before any thread
        // of ours exists.
        #[allow(unsafe_code)]
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, 1);
        }
    }
}
