//! Late packets on the microcontroller: the driver [`drive_lag`] runs any core estimator under
//! the core's fixed-lag layer ([`FixedLag`]) over a stream whose packets are made late by a
//! fixed pattern ([`lateness`]), folds each late packet in when it arrives, and marks every
//! step and every fold for the instruction-count plugin (a fold's end carries its lateness,
//! [`fold_code`]).
//!
//! The digest is of the *settled* estimates: once instant `j` is `LAG` instants old no packet
//! of it can still arrive, so the estimate after `j` is final, and it is digested then (the
//! last `LAG − 1` at the end). With every late packet within the lag, the digest and the final
//! x̂ are therefore the on-time run's ([`drive`](super::drive)'s) bit for bit; the host check
//! requires it.

use core::fmt;

use estimator_core::{Error, Estimator, FixedLag, LagCounts, LostMeasurement, Revise, Revision};

use super::digest::Fnv1a64;
use super::drive::{construct, Digested, FromNodes, Instant};
use super::mark::{branch, fold_code, step_mark, BEGIN, REFUSED};
use super::summary::{Summary, MAX_NX};

/// The lag of the firmware's fixed-lag binaries (`ikf-lag8`, `adf-lag8`).
pub const LAG: usize = 8;

/// How late instant `k`'s packet arrives, of a stream of `n` instants, under a lag of `lag`:
/// `Some(l)` if it arrives after instant `k + l − 1` was stepped (its own instant stepped
/// without it), `None` on time. The pattern: `l = lag` for k ≡ 6 (mod 10) if it still
/// arrives within the stream (`k + lag − 1 ≤ n`), else `l = 1` for k ≡ 3 (mod 5), else on
/// time — on the 100-instant streams 9 packets `lag` late and 20 one instant late, every fold
/// within the lag.
pub const fn lateness(k: usize, n: usize, lag: usize) -> Option<usize> {
    if lag == 0 {
        None
    } else if k % 10 == 6 && k + lag - 1 <= n {
        Some(lag)
    } else if k % 5 == 3 {
        Some(1)
    } else {
        None
    }
}

/// The layer's counts as the firmware's `LATE` line prints them after the binary's name
/// (`folded=… unchanged=… too_old=… refused=…`); the host check compares the line.
#[derive(Clone, Copy, Debug)]
pub struct LateLine<'a>(pub &'a LagCounts);

impl fmt::Display for LateLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.0;
        write!(
            f,
            "folded={} unchanged={} too_old={} refused={}",
            c.folded, c.unchanged, c.too_old, c.refused
        )
    }
}

/// The driver under the fixed-lag layer: builds the estimator (`build`) and wraps it in a
/// `FixedLag<_, _, LAG>`; steps it over the first `steps` instants of a stream of `n`; an
/// instant whose packet is late ([`lateness`]) is stepped with the packet lost
/// ([`LostMeasurement`]) and the packet kept until it arrives, then folded in
/// ([`FixedLag::fold_in`]), oldest first, after that instant's step. Counts what the
/// instants brought as [`drive`](super::drive) does; a refused step or fold is an error.
/// Returns the summary (the digest of the settled estimates, the final x̂) and the layer's
/// counts.
pub fn drive_lag<const L: usize, const NX: usize, const LAG: usize, E>(
    name: &'static str,
    instants: impl Iterator<Item = Instant<L>>,
    n: usize,
    steps: usize,
    build: impl FnOnce() -> Result<E, Error>,
) -> (Summary, LagCounts)
where
    E: Digested<NX> + Clone,
    E::Measurement: FromNodes<L> + Revise + LostMeasurement + Clone,
{
    let mut s = Summary::new(name);
    // The estimator alone is built in the constructor's frame: the layer (`LAG + 1` copies of
    // it) is laid out once, here.
    let Ok(est) = construct(build) else {
        s.errors = 1;
        return (s, LagCounts::default());
    };
    let lag = &mut layer::<NX, LAG, E>(est);
    s.digest = step_all_lag(&mut s, lag, instants.take(steps), n);
    let x = lag.estimate().state().as_slice();
    s.nx = x.len().min(MAX_NX);
    for (b, v) in s.x_bits.iter_mut().zip(x) {
        *b = v.to_bits();
    }
    (s, lag.counts())
}

/// The layer over `est`, built in the caller's place (not inlined: inlined, the layer was
/// laid out twice in the caller's frame).
#[inline(never)]
fn layer<const NX: usize, const LAG: usize, E>(est: E) -> FixedLag<E, E::Measurement, LAG>
where
    E: Estimator<f32, NX>,
{
    FixedLag::new(est)
}

/// Feeds the label byte and the estimate of the estimator after instant `j` (255 alone if
/// the history has none, after a refused step).
fn digest_after<const NX: usize, E, M, const LAG: usize>(
    h: &mut Fnv1a64,
    lag: &FixedLag<E, M, LAG>,
    j: usize,
) where
    E: Digested<NX> + Clone,
    M: Clone,
{
    match lag.after(j) {
        Some(e) => {
            h.bytes(&[e.label().map_or(0, |l| l.min(255) as u8)]);
            e.digest(h);
        }
        None => h.bytes(&[255]),
    }
}

/// [`FixedLag`]'s step, in a frame of its own: its copies of the estimator and those of a
/// fold ([`fold_in`]) then share the stack instead of lying side by side in the loop's frame.
#[inline(never)]
fn step<const NX: usize, const LAG: usize, E>(
    lag: &mut FixedLag<E, E::Measurement, LAG>,
    k: usize,
    y: &E::Measurement,
) -> Result<(), Error>
where
    E: Estimator<f32, NX> + Clone,
    E::Measurement: LostMeasurement + Clone,
{
    lag.step(k, y)
}

/// [`FixedLag::fold_in`], in a frame of its own (see [`step`]).
#[inline(never)]
fn fold_in<const NX: usize, const LAG: usize, E>(
    lag: &mut FixedLag<E, E::Measurement, LAG>,
    j: usize,
    y: &E::Measurement,
) -> Result<Revision, Error>
where
    E: Estimator<f32, NX> + Clone,
    E::Measurement: Revise + LostMeasurement + Clone,
{
    lag.fold_in(j, y)
}

/// The loop of [`drive_lag`], in a frame of its own. Calls the step marker before the loop,
/// around every step (as [`drive`](super::drive) does; a step whose packet is late has the
/// code of nothing arrived) and around every fold: `(k, BEGIN)` before it, `(k, fold_code(l,
/// refused))` after, k being the instant just stepped. Returns the digest.
#[inline(never)]
fn step_all_lag<const L: usize, const NX: usize, const LAG: usize, E>(
    s: &mut Summary,
    lag: &mut FixedLag<E, E::Measurement, LAG>,
    instants: impl Iterator<Item = Instant<L>>,
    n: usize,
) -> u64
where
    E: Digested<NX> + Clone,
    E::Measurement: FromNodes<L> + Revise + LostMeasurement + Clone,
{
    let mut h = Fnv1a64::default();
    // The late packets not yet arrived: instant j's at j % LAG, with its lateness.
    let mut pending: [Option<(usize, usize, E::Measurement)>; LAG] = [const { None }; LAG];
    let mut last = 0;
    step_mark(0, 0);
    for inst in instants {
        let k = inst.k as usize;
        last = k;
        tally(s, &inst);
        step_now::<L, NX, LAG, E>(s, lag, &mut pending, &inst, n);
        fold_due::<NX, LAG, E>(s, lag, &mut pending, k, inst.k);
        // Instant k − LAG + 1 is settled: none of its packets can arrive any more.
        if let Some(j) = (k + 1).checked_sub(LAG.max(1)).filter(|&j| j >= 1) {
            digest_after::<NX, _, _, LAG>(&mut h, lag, j);
        }
    }
    // The last LAG − 1 instants, settled by the end of the stream.
    for j in (last + 2).saturating_sub(LAG.max(1)).max(1)..=last {
        digest_after::<NX, _, _, LAG>(&mut h, lag, j);
    }
    h.0
}

/// Counts the instant's step and, node by node, its arrivals and dropouts.
#[inline(always)]
fn tally<const L: usize>(s: &mut Summary, inst: &Instant<L>) {
    s.steps += 1;
    for y in &inst.y {
        if y.is_some() {
            s.arrivals += 1;
        } else {
            s.dropouts += 1;
        }
    }
}

/// The instant's own step, marked around: a packet that will arrive late is parked in
/// `pending` and the step sees it lost (with the code of nothing arrived).
#[inline(always)]
fn step_now<const L: usize, const NX: usize, const LAG: usize, E>(
    s: &mut Summary,
    lag: &mut FixedLag<E, E::Measurement, LAG>,
    pending: &mut [Option<(usize, usize, E::Measurement)>; LAG],
    inst: &Instant<L>,
    n: usize,
) where
    E: Digested<NX> + Clone,
    E::Measurement: FromNodes<L> + Revise + LostMeasurement + Clone,
{
    let k = inst.k as usize;
    let late = lateness(k, n, LAG);
    let code = if late.is_some() {
        0
    } else {
        branch(inst.y.each_ref().map(Option::is_some), |m| {
            inst.y[m].as_ref().is_some_and(E::censored)
        })
    };
    let y = E::Measurement::from_nodes(&inst.y);
    let now = match (y, late) {
        (Ok(y), Some(l)) if LAG > 0 => {
            pending[k % LAG] = Some((k, l, y));
            Ok(E::Measurement::lost())
        }
        (y, _) => y,
    };
    step_mark(inst.k, BEGIN);
    let stepped = now.and_then(|y| step(lag, k, &y));
    step_mark(
        inst.k,
        if stepped.is_err() {
            code | REFUSED
        } else {
            code
        },
    );
    if stepped.is_err() {
        s.error(inst.k);
    }
}

/// The late packets arriving after instant `k` was stepped, oldest first, each folded in and
/// marked around (`mark_k` is the instant as the markers carry it).
#[inline(always)]
fn fold_due<const NX: usize, const LAG: usize, E>(
    s: &mut Summary,
    lag: &mut FixedLag<E, E::Measurement, LAG>,
    pending: &mut [Option<(usize, usize, E::Measurement)>; LAG],
    k: usize,
    mark_k: u32,
) where
    E: Estimator<f32, NX> + Clone,
    E::Measurement: Revise + LostMeasurement + Clone,
{
    for back in (0..LAG).rev() {
        let Some(j) = k.checked_sub(back) else {
            continue;
        };
        let slot = &mut pending[j % LAG];
        let due = matches!(slot, Some((pj, l, _)) if *pj == j && j + *l - 1 == k);
        if !due {
            continue;
        }
        let Some((_, l, y)) = slot.take() else {
            continue;
        };
        step_mark(mark_k, BEGIN);
        let folded = fold_in(lag, j, &y);
        step_mark(mark_k, fold_code(l, folded.is_err()));
        if folded.is_err() {
            s.error(mark_k);
        }
    }
}
