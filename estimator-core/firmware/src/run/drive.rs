//! The estimator interface of the firmware ([`Driven`]), its input ([`Instant`]), and the one
//! driver ([`drive`]) every firmware binary and the host check run.

use estimator_core::Error;
use nalgebra::Vector2;

use super::digest::Fnv1a64;
use super::summary::{Summary, MAX_NX};

/// One sampling instant as an estimator sees it: k and what each of the `L` nodes delivered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instant<const L: usize> {
    /// Sampling instant k ≥ 1.
    pub k: u32,
    /// Node m's measurement, `None` when nothing arrived.
    pub y: [Option<Vector2<f32>>; L],
}

/// An estimator as the driver sees it: one instant with what each of the `L` nodes delivered.
/// On error the estimator must keep its state (the core's contract).
pub trait Driven<const L: usize> {
    /// Whether [`Driven::step`] returns a region label; if not, the digest records 0 for
    /// every step, else the label (255 for a refused step).
    const LABELS: bool;
    /// One instant; returns the region-label estimate (ignored unless [`Driven::LABELS`]).
    fn step(&mut self, k: usize, y: [Option<&Vector2<f32>>; L]) -> Result<usize, Error>;
    /// Feeds the current estimate into the digest (x̂, then P's upper triangle, …).
    fn digest(&self, h: &mut Fnv1a64);
    /// The current x̂.
    fn x(&self) -> &[f32];
}

/// Runs the estimator's constructor in a frame of its own, and [`step_all`] the steps in
/// another: the constructor's temporaries (model and region validation, Gaussian-sum tables)
/// and the steps' then share the same stack instead of being laid out side by side in one
/// frame of the driver (stack coloring does not overlap them once everything is inlined).
#[inline(never)]
fn construct<E>(build: impl FnOnce() -> Result<E, Error>) -> Result<E, Error> {
    build()
}

/// The one driver: builds the estimator, steps it over the first `steps` instants (all of them
/// if `steps` exceeds the stream), and digests after every instant the label byte and the
/// estimate. Counts arrivals and dropouts per node slot, and the refused steps.
pub fn drive<const L: usize, E: Driven<L>>(
    name: &'static str,
    instants: impl Iterator<Item = Instant<L>>,
    steps: usize,
    build: impl FnOnce() -> Result<E, Error>,
) -> Summary {
    let mut s = Summary::new(name);
    // Borrowed in place: moving the estimator out of the `Result` would be a second copy of
    // it on the stack.
    let mut built = construct(build);
    let Ok(est) = &mut built else {
        s.errors = 1;
        return s;
    };
    s.digest = step_all(&mut s, est, instants.take(steps));
    let x = est.x();
    s.nx = x.len().min(MAX_NX);
    for (b, v) in s.x_bits.iter_mut().zip(x) {
        *b = v.to_bits();
    }
    s
}

/// The loop of [`drive`], in a frame of its own (see [`construct`]). Returns the digest.
#[inline(never)]
fn step_all<const L: usize, E: Driven<L>>(
    s: &mut Summary,
    est: &mut E,
    instants: impl Iterator<Item = Instant<L>>,
) -> u64 {
    let mut h = Fnv1a64::default();
    for inst in instants {
        s.steps += 1;
        for y in &inst.y {
            if y.is_some() {
                s.arrivals += 1;
            } else {
                s.dropouts += 1;
            }
        }
        let label = match est.step(inst.k as usize, inst.y.each_ref().map(Option::as_ref)) {
            Ok(label) => label,
            Err(_) => {
                s.error(inst.k);
                usize::MAX
            }
        };
        h.bytes(&[if E::LABELS { label.min(255) as u8 } else { 0 }]);
        est.digest(&mut h);
    }
    h.0
}
