//! Support for the estimator firmware on QEMU's `mps2-an386` (Cortex-M4F): semihosting output,
//! command line and exit status, stack painting, and the common `main` of every binary.
//!
//! The estimator drivers themselves live in [`run`], which has no target-specific code and is
//! shared with the host check.
#![no_std]

pub mod peers;
pub mod run;

use core::fmt::{self, Write};
use core::ptr::{addr_of, read_volatile, write_volatile};

use cortex_m_semihosting::hio;

use estimator_core::LagCounts;
use run::{Source, Summary, Vectors};

/// Exit status: run completed (estimator errors, if any, are in the result line).
pub const EXIT_OK: u32 = 0;
/// Exit status: the embedded vector file failed its hash or format check.
pub const EXIT_BAD_VECTORS: u32 = 3;
/// Exit status: a panic (never expected: nothing in the run path panics on data).
pub const EXIT_PANIC: u32 = 101;

/// Writes to the host's stdout; output is best-effort (there is nobody to report a failure to).
pub fn print(args: fmt::Arguments<'_>) {
    if let Ok(mut out) = hio::hstdout() {
        let _ = out.write_fmt(args);
    }
}

/// `print!` over semihosting.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => { $crate::print(format_args!($($arg)*)) };
}

/// Ends the emulation with `code` as QEMU's exit status.
///
/// The A32/T32 `SYS_EXIT` (0x18) only distinguishes success from failure; `SYS_EXIT_EXTENDED`
/// (0x20) takes the block `[ADP_Stopped_ApplicationExit, code]` and QEMU exits with `code`.
pub fn exit(code: u32) -> ! {
    const SYS_EXIT_EXTENDED: usize = 0x20;
    const ADP_STOPPED_APPLICATION_EXIT: u32 = 0x20026;
    let block = [ADP_STOPPED_APPLICATION_EXIT, code];
    loop {
        // SAFETY: a valid semihosting call with a two-word parameter block that outlives it.
        unsafe {
            cortex_m_semihosting::syscall1(SYS_EXIT_EXTENDED, block.as_ptr() as usize);
        }
    }
}

/// Reads `steps=N` from the semihosting command line (QEMU's `-semihosting-config arg=steps=N`,
/// or `-append` after the kernel's path); `None` when absent or when the line does not fit.
// Not inlined, so its buffer is not part of `main_with`'s frame (and of the measured stack).
#[inline(never)]
pub fn cmdline_steps() -> Option<usize> {
    const SYS_GET_CMDLINE: usize = 0x15;
    let mut buf = [0u8; 1024];
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: the block points at a buffer of the stated length that outlives the call.
    let rc =
        unsafe { cortex_m_semihosting::syscall1(SYS_GET_CMDLINE, block.as_mut_ptr() as usize) };
    if rc != 0 {
        return None;
    }
    let len = block[1].min(buf.len());
    let line = core::str::from_utf8(&buf[..len]).ok()?;
    line.split_ascii_whitespace()
        .find_map(|w| w.strip_prefix("steps="))
        .and_then(|n| n.parse().ok())
}

extern "C" {
    // cortex-m-rt: initial stack pointer (top of the stack) and the end of .bss/.uninit.
    static _stack_start: u32;
    static _stack_end: u32;
}

/// Bytes below the top of the stack that are painted: far above the 4 KiB budget, so an
/// overrun of the budget is measured, not missed.
pub const STACK_WINDOW: usize = 64 * 1024;
const PAINT: u32 = 0xC5C5_C5C5;

fn stack_bounds() -> (usize, usize) {
    // Only the addresses of the linker symbols are taken (safe since Rust 1.82).
    let (top, end) = (
        addr_of!(_stack_start) as usize,
        addr_of!(_stack_end) as usize,
    );
    (top.saturating_sub(STACK_WINDOW).max(end), top)
}

/// Fills the unused stack (from the bottom of the window up to just below the current stack
/// pointer) with a pattern.
#[inline(never)]
pub fn paint_stack() {
    let sp: usize;
    // SAFETY: reads the stack pointer.
    unsafe { core::arch::asm!("mov {}, sp", out(reg) sp, options(nomem, nostack)) };
    let (lo, _) = stack_bounds();
    let mut a = lo;
    // Stop 64 bytes short of SP: nothing below SP is live (no interrupts are enabled).
    while a + 64 < sp {
        // SAFETY: [lo, sp) is unused RAM between .bss and the live stack.
        unsafe { write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
}

/// Peak stack use in bytes since the last [`paint_stack`]: distance from the top of the stack
/// to the lowest word that no longer holds the pattern. `(bytes, overflowed_window)`.
#[inline(never)]
pub fn stack_peak() -> (usize, bool) {
    let (lo, top) = stack_bounds();
    let mut a = lo;
    // SAFETY: reads RAM inside the stack window.
    while a < top && unsafe { read_volatile(a as *const u32) } == PAINT {
        a += 4;
    }
    (top - a, a == lo)
}

/// The body of every firmware binary: check the embedded stream `vectors`, run `driver` over it, report.
///
/// With `steps=N` on the command line (instruction-count mode) it runs only the first N
/// instants and exits silently, so that the instruction count of two runs differs only by the
/// estimator steps; otherwise it runs the whole stream with the stack painted and prints
/// `RESULT <summary>` and `STACK <name> peak=<bytes>`.
pub fn main_with<S: Source>(vectors: Vectors, driver: fn(&S, usize) -> Summary) -> ! {
    let stream = open_or_exit(&vectors);
    if let Some(n) = cmdline_steps() {
        let s = driver(&stream, n);
        core::hint::black_box(s);
        exit(EXIT_OK);
    }
    paint_stack();
    let s = driver(&stream, usize::MAX);
    report(&s, stack_peak());
    exit(EXIT_OK);
}

/// The body of the fixed-lag binaries: as [`main_with`], with a driver that also returns the
/// layer's counts of late packets, printed after the result as
/// `LATE <name> folded=… unchanged=… too_old=… refused=…`.
pub fn main_with_lag<S: Source>(
    vectors: Vectors,
    driver: fn(&S, usize) -> (Summary, LagCounts),
) -> ! {
    let stream = open_or_exit(&vectors);
    if let Some(n) = cmdline_steps() {
        let s = driver(&stream, n);
        core::hint::black_box(s);
        exit(EXIT_OK);
    }
    paint_stack();
    let (s, counts) = driver(&stream, usize::MAX);
    report_lag(&s, &counts, stack_peak());
    exit(EXIT_OK);
}

/// The result, the late-packet counts and the stack lines (as [`report`]'s).
#[inline(never)]
fn report_lag(s: &Summary, c: &LagCounts, (peak, overflow): (usize, bool)) {
    out!("RESULT {s}\n");
    out!("LATE {} {}\n", s.name, run::LateLine(c));
    out!(
        "STACK {} peak={}{}\n",
        s.name,
        peak,
        if overflow { " (window overrun)" } else { "" }
    );
}

// The two helpers below are not inlined so that their formatting temporaries are not part of
// `main_with`'s frame, which stays on the stack under the whole run.

/// The embedded stream, or exit with [`EXIT_BAD_VECTORS`].
#[inline(never)]
fn open_or_exit<S: Source>(vectors: &Vectors) -> S {
    match S::open(vectors) {
        Ok(s) => s,
        Err(e) => {
            out!("ERROR {e}\n");
            exit(EXIT_BAD_VECTORS);
        }
    }
}

/// Prints the result and the stack lines.
#[inline(never)]
fn report(s: &Summary, (peak, overflow): (usize, bool)) {
    out!("RESULT {s}\n");
    out!(
        "STACK {} peak={}{}\n",
        s.name,
        peak,
        if overflow { " (window overrun)" } else { "" }
    );
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    out!("PANIC\n");
    exit(EXIT_PANIC);
}
