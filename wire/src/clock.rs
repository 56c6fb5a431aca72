//! The one clock of every timestamp on the wire.

/// `CLOCK_MONOTONIC` in ns: one clock shared by all processes of the machine, so send and
/// receive times of different processes are directly comparable (Python:
/// `time.clock_gettime_ns(time.CLOCK_MONOTONIC)`, C: `clock_gettime(CLOCK_MONOTONIC, …)`).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    #[allow(unsafe_code)]
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}
