//! The one driver ([`drive`]) every firmware binary and the host check run: any core
//! [`Estimator`] over a stream of [`Instant`]s, what the stream's node slots become for it
//! ([`FromNodes`]), and what the digest records of it after each step ([`Digested`]).

use estimator_core::{Error, Estimator, Packet};
use nalgebra::Vector2;

use super::digest::Fnv1a64;
use super::mark::{branch, step_mark, BEGIN, REFUSED};
use super::summary::{Summary, MAX_NX};

/// One sampling instant of a stream: k and what each of the `L` nodes delivered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instant<const L: usize> {
    /// Sampling instant k ≥ 1.
    pub k: u32,
    /// Node m's measurement, `None` when nothing arrived.
    pub y: [Option<Vector2<f32>>; L],
}

/// An estimator's [`Estimator::Measurement`] read from the `L` node slots of an instant.
pub trait FromNodes<const L: usize>: Sized {
    /// The measurement of an instant whose nodes delivered `y`; an error when the estimator
    /// cannot take what arrived (the step is then counted as refused).
    fn from_nodes(y: &[Option<Vector2<f32>>; L]) -> Result<Self, Error>;
}

/// An estimator that needs a measurement at every instant (the Kalman filter on the lossless
/// link, where every instant has one).
impl FromNodes<1> for Vector2<f32> {
    fn from_nodes([y]: &[Option<Vector2<f32>>; 1]) -> Result<Self, Error> {
        y.ok_or(Error::InvalidConfig {
            field: "y",
            reason: "no measurement for an estimator that needs one at every instant",
        })
    }
}

/// A single node's packet: a missing measurement is a dropout (the streams have no losses in
/// transport).
impl FromNodes<1> for Packet<f32, 2> {
    fn from_nodes([y]: &[Option<Vector2<f32>>; 1]) -> Result<Self, Error> {
        Ok(Packet::from(*y))
    }
}

/// Every node's packet.
impl<const L: usize> FromNodes<L> for [Packet<f32, 2>; L] {
    fn from_nodes(y: &[Option<Vector2<f32>>; L]) -> Result<Self, Error> {
        Ok(y.map(Packet::from))
    }
}

/// What the digest records of an estimator after each step: a label byte, then the estimate.
pub trait Digested<const NX: usize>: Estimator<f32, NX> {
    /// The region-label estimate of the last step, for the estimators that have one (the
    /// label byte is then the label, 255 after a refused step; 0 for the others).
    fn label(&self) -> Option<usize> {
        None
    }

    /// Feeds the estimate: x̂, then P's upper triangle (an estimator with more state worth
    /// pinning feeds that too).
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.estimate().state(), self.estimate().covariance());
    }

    /// Whether a delivered measurement arrived censored (for the branch code the driver passes
    /// to the step marker; the estimators whose streams censor nothing keep `false`).
    fn censored(_y: &Vector2<f32>) -> bool {
        false
    }

    /// For the coming step, whose nodes delivered `y`: the branch code bits
    /// ([`HELD`](super::mark::HELD)` << m`) of the silent nodes whose silence the estimator will
    /// read as held, which the driver adds to the code before the step (so that the step's
    /// count does not include them); 0 for the estimators that read no silence.
    fn held<const L: usize>(&self, _y: &[Option<Vector2<f32>>; L]) -> u8 {
        0
    }
}

/// Runs the estimator's constructor in a frame of its own, and [`step_all`] the steps in
/// another: the constructor's temporaries (model and region validation, Gaussian-sum tables)
/// and the steps' then share the same stack instead of being laid out side by side in one
/// frame of the driver (stack coloring does not overlap them once everything is inlined).
#[inline(never)]
pub(super) fn construct<E>(build: impl FnOnce() -> Result<E, Error>) -> Result<E, Error> {
    build()
}

/// The one driver: builds the estimator, steps it over the first `steps` instants (all of them
/// if `steps` exceeds the stream), and digests after every instant the label byte and the
/// estimate. Counts arrivals and dropouts per node slot, and the refused steps.
pub fn drive<const L: usize, const NX: usize, E>(
    name: &'static str,
    instants: impl Iterator<Item = Instant<L>>,
    steps: usize,
    build: impl FnOnce() -> Result<E, Error>,
) -> Summary
where
    E: Digested<NX>,
    E::Measurement: FromNodes<L>,
{
    let mut s = Summary::new(name);
    // Borrowed in place: moving the estimator out of the `Result` would be a second copy of
    // it on the stack.
    let mut built = construct(build);
    let Ok(est) = &mut built else {
        s.errors = 1;
        return s;
    };
    s.digest = step_all(&mut s, est, instants.take(steps));
    let x = est.estimate().state().as_slice();
    s.nx = x.len().min(MAX_NX);
    for (b, v) in s.x_bits.iter_mut().zip(x) {
        *b = v.to_bits();
    }
    s
}

/// The loop of [`drive`], in a frame of its own (see [`construct`]). Returns the digest.
/// Calls the step marker before the loop and around every step (see [`super::mark`]).
#[inline(never)]
fn step_all<const L: usize, const NX: usize, E>(
    s: &mut Summary,
    est: &mut E,
    instants: impl Iterator<Item = Instant<L>>,
) -> u64
where
    E: Digested<NX>,
    E::Measurement: FromNodes<L>,
{
    let mut h = Fnv1a64::default();
    step_mark(0, 0);
    for inst in instants {
        s.steps += 1;
        for y in &inst.y {
            if y.is_some() {
                s.arrivals += 1;
            } else {
                s.dropouts += 1;
            }
        }
        // The branch code before the step, so that the step's count does not include it.
        let code = branch(inst.y.each_ref().map(Option::is_some), |m| {
            inst.y[m].as_ref().is_some_and(E::censored)
        }) | est.held(&inst.y);
        step_mark(inst.k, BEGIN);
        let stepped =
            E::Measurement::from_nodes(&inst.y).and_then(|y| est.step(inst.k as usize, &y));
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
        let label = match (est.label(), stepped) {
            (None, _) => 0,
            (Some(label), Ok(())) => label.min(255) as u8,
            (Some(_), Err(_)) => 255,
        };
        h.bytes(&[label]);
        est.digest(&mut h);
    }
    h.0
}
