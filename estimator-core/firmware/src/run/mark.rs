//! The step marker: the driver calls [`step_mark`] once before its loop (k = 0), and around
//! every step: with `(k, BEGIN)` just before it and `(k, branch code)` just after. On the host
//! it does nothing observable; under QEMU the instruction-count plugin (`plugin/insn_count.c`)
//! counts the instructions between two calls, so the interval that ends at `(k, code)` is step
//! k alone and the one that ends at `(k, BEGIN)` the driver's bookkeeping before it (reading the
//! instant, the previous step's digest). It reads k and the code from the addresses the marker
//! loads from (QEMU 7's plugin API sees addresses of memory accesses, not registers or values).
//! The fixed-lag binaries mark each fold of a late packet the same way, with its own end code
//! ([`FOLD`]). The marker changes no result: it reads a table nobody writes.

use core::sync::atomic::{AtomicU8, Ordering};

/// Bytes of the marker's table: three regions of 256, for k's low byte, k's high byte and the
/// branch code (the plugin takes this length as `marks=ADDR:768`).
pub const MARKS_LEN: usize = 768;

/// The marker's table, in `.bss` (RAM, no flash). Never written.
static MARKS: [AtomicU8; MARKS_LEN] = [const { AtomicU8::new(0) }; MARKS_LEN];

/// Marks the end of step `k` (k = 0: the start of the loop) taken through branch `branch`:
/// three loads, from `MARKS[k & 0xff]`, `MARKS[256 + ((k >> 8) & 0xff)]` and
/// `MARKS[512 + branch]`. Not inlined, so the plugin finds it by its symbol; the loads are
/// atomic (not removable) and from a table whose address is hidden from the optimiser.
#[inline(never)]
pub fn step_mark(k: u32, branch: u8) {
    let m: &[AtomicU8; MARKS_LEN] = core::hint::black_box(&MARKS);
    let _ = m[(k & 0xff) as usize].load(Ordering::Relaxed);
    let _ = m[256 + ((k >> 8) & 0xff) as usize].load(Ordering::Relaxed);
    let _ = m[512 + usize::from(branch)].load(Ordering::Relaxed);
}

/// Branch code bit: node `m`'s measurement arrived (bit m, m < 3).
pub const ARRIVED: u8 = 1;
/// Branch code bit: node `m`'s delivered measurement has a censored component (bit 3 + m).
pub const CENSORED: u8 = 1 << 3;
/// Branch code bit of an estimator that reads silences: node `m` did not send and the
/// receiver's bucket mirror calls its silence held (bit 3 + m, [`CENSORED`]'s bit, which only
/// a node that sent can have).
pub const HELD: u8 = CENSORED;
/// Branch code bit: the estimator refused the step (it kept its estimate).
pub const REFUSED: u8 = 1 << 6;
/// The code of the call just before a step (the other codes mark its end).
pub const BEGIN: u8 = 1 << 7;
/// The end of a fold of a late packet (the fixed-lag binaries, [`super::drive_lag`]): the
/// code is `FOLD + l` for a packet `l` instants late (1 ≤ l ≤ 31), plus [`REFUSED`] if the
/// fold failed; the call just before a fold has the code [`BEGIN`], like a step's.
pub const FOLD: u8 = BEGIN | 1 << 5;

/// The code of the end of a fold of a packet `l` instants late ([`FOLD`]; l above 31 is
/// marked 31).
pub fn fold_code(l: usize, refused: bool) -> u8 {
    let code = FOLD + l.min(31) as u8;
    if refused {
        code | REFUSED
    } else {
        code
    }
}

/// The branch code of one step with `L ≤ 3` nodes: bit m if node m's measurement arrived,
/// bit 3 + m if it arrived censored (`censored(m)`). The driver computes it before the step
/// (so that it is not counted in the step) and adds [`REFUSED`] after it if the step failed.
pub fn branch<const L: usize>(arrived: [bool; L], censored: impl Fn(usize) -> bool) -> u8 {
    let mut code = 0;
    for (m, &a) in arrived.iter().enumerate().take(3) {
        if a {
            code |= ARRIVED << m;
            if censored(m) {
                code |= CENSORED << m;
            }
        }
    }
    code
}
