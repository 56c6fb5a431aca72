//! [`catch_up`] and [`CatchUp`]: the gap instants, the hook's calls, the commit; and the
//! runner's gate over its catch-up (ipc-runner's `adapter.rs` and `fed.rs`, transcribed)
//! against [`Gated`] over [`CatchUp`].

use heapless::Vec;

use nalgebra::{matrix, vector, SMatrix, SVector};

use super::*;
use crate::estimator::OnModel;
use crate::filter::coupled_kf::{Linearisation, NoNonlinearity};
use crate::filter::gate::{GateState, Gated};
use crate::filter::CoupledNoiseKf;
use crate::papers::Seed003Example;

/// What one step saw: the instant, whether a measurement was delivered, the model's instant,
/// whether the step was the gated one.
type Seen = (usize, bool, usize, bool);

/// An estimator that counts its instants and writes down every step it takes.
#[derive(Clone, Debug, PartialEq)]
struct Counting {
    next: usize,
    model: usize,
    fail_at: Option<usize>,
    est: Estimate<f64, 1>,
    /// Every step so far (the tests take at most a few dozen).
    seen: Vec<Seen, 64>,
}

impl Counting {
    fn new() -> Self {
        Self {
            next: 1,
            model: 0,
            fail_at: None,
            est: Estimate::new(SVector::zeros(), SMatrix::identity()).unwrap(),
            seen: Vec::new(),
        }
    }

    fn take(&mut self, k: usize, y: &Packet<f64, 1>, gated: bool) -> Result<()> {
        if k != self.next {
            return Err(Error::OutOfOrder {
                expected: self.next,
                got: k,
            });
        }
        if self.fail_at == Some(k) {
            return Err(Error::Numerical { what: "test" });
        }
        self.seen
            .push((k, y.delivered().is_some(), self.model, gated))
            .map_err(|_| Error::Numerical {
                what: "more steps than the test records",
            })?;
        self.next = k + 1;
        Ok(())
    }
}

impl Estimator<f64, 1> for Counting {
    type Measurement = Packet<f64, 1>;

    fn step(&mut self, k: usize, y: &Packet<f64, 1>) -> Result<()> {
        self.take(k, y, false)
    }

    fn estimate(&self) -> &Estimate<f64, 1> {
        &self.est
    }
}

impl GatedStep<f64, 1> for Counting {
    fn step_gated(
        &mut self,
        k: usize,
        y: &Packet<f64, 1>,
        _gate: &InnovationGate<f64>,
    ) -> Result<GateCounts> {
        self.take(k, y, true)
            .map(|()| GateCounts::one(y.delivered().is_some()))
    }
}

fn delivered() -> Packet<f64, 1> {
    Packet::Delivered(SVector::repeat(1.0))
}

#[test]
fn lost_measurements_are_all_lost() {
    assert_eq!(Packet::<f64, 2>::lost(), Packet::Lost);
    assert_eq!(<[Packet<f32, 3>; 4]>::lost(), [Packet::Lost; 4]);
}

#[test]
fn the_gap_is_stepped_as_lost_each_instant_on_its_own_model() {
    let mut calls: Vec<usize, 8> = Vec::new();
    let mut e = CatchUp::new(Counting::new()).with_remodel(|e: &mut Counting, k: usize| {
        e.model = k;
        Ok(())
    });
    e.step(1, &delivered()).unwrap();
    e.step(5, &delivered()).unwrap();
    assert_eq!(
        e.estimator.seen,
        [
            (1, true, 1, false),
            (2, false, 2, false),
            (3, false, 3, false),
            (4, false, 4, false),
            (5, true, 5, false),
        ]
    );
    // The hook: at k on the estimator, then every gap instant and k on the copy.
    let mut est = Counting::new();
    let mut hook = |e: &mut Counting, k: usize| {
        calls.push(k).expect("a few calls");
        e.model = k;
        Ok(())
    };
    catch_up(&mut est, 3, &delivered(), &mut hook, |e, k, y| e.step(k, y)).unwrap();
    assert_eq!(calls, [3, 1, 2, 3]);
    // Gated: the gap instants take the plain step, k the gated one, whose counts are returned.
    let mut g = CatchUp::new(Counting::new());
    let c = g
        .step_gated(3, &delivered(), &InnovationGate::off())
        .unwrap();
    assert_eq!(c, GateCounts::one(true));
    assert_eq!(
        g.estimator.seen,
        [
            (1, false, 0, false),
            (2, false, 0, false),
            (3, true, 0, true)
        ]
    );
}

#[test]
fn an_error_anywhere_keeps_the_state() {
    let mut e = CatchUp::new(Counting::new());
    e.step(1, &delivered()).unwrap();
    // In the gap, and at k itself.
    for fail in [3, 6] {
        e.estimator.fail_at = Some(fail);
        let before = e.estimator.clone();
        assert_eq!(
            e.step(6, &delivered()),
            Err(Error::Numerical { what: "test" })
        );
        assert_eq!(e.estimator, before);
    }
    // A hook that fails in the gap: its error, and the state kept (the model is k's, as the
    // hook brought the estimator itself to k first).
    let mut est = Counting::new();
    let before = est.clone();
    let mut hook = |e: &mut Counting, k: usize| {
        e.model = k;
        if k == 2 {
            return Err(Error::Numerical { what: "model" });
        }
        Ok(())
    };
    let r = catch_up(&mut est, 4, &delivered(), &mut hook, |e, k, y| e.step(k, y));
    assert_eq!(r, Err(Error::Numerical { what: "model" }));
    assert_eq!(est.seen, before.seen);
    assert_eq!((est.next, est.model), (1, 4));
    // An instant already past is not a gap: the estimator's own refusal.
    let mut e = CatchUp::new(Counting::new());
    e.step(3, &delivered()).unwrap();
    assert_eq!(
        e.step(2, &delivered()),
        Err(Error::OutOfOrder {
            expected: 4,
            got: 2
        })
    );
}

/// The runner's `Fed::step_by` and its gate (`adapter.rs`), transcribed.
fn runner_step<E: GatedStep<f64, 3, Measurement = Packet<f64, 2>> + Clone>(
    est: &mut E,
    state: &mut GateState,
    gate: &InnovationGate<f64>,
    k: usize,
    y: &Packet<f64, 2>,
) -> Result<()> {
    let g = state.gate_for_next(gate);
    let step = |e: &mut E, k: usize, y: &Packet<f64, 2>| e.step_gated(k, y, &g);
    let counts = match step(est, k, y) {
        Err(Error::OutOfOrder { expected, got }) if got > expected => {
            let mut copy = est.clone();
            for j in expected..got {
                copy.step(j, &Packet::Lost)?;
            }
            let counts = step(&mut copy, got, y)?;
            *est = copy;
            Ok(counts)
        }
        done => done,
    }?;
    state.record(counts, &g);
    Ok(())
}

/// The seed 003 coupled-noise KF (it counts its instants) behind the gate with its lock-out,
/// over gaps, outliers and a refused step: [`Gated`] over [`CatchUp`] is the runner's gate
/// over its catch-up, bit for bit, counts included.
#[test]
fn gated_catch_up_is_the_runners_gate_bit_for_bit() {
    let kf = OnModel::new(
        (Seed003Example, NoNonlinearity),
        CoupledNoiseKf::new(
            vector![1.0, -1.0, 0.5],
            SMatrix::identity(),
            matrix![0.1],
            Linearisation::None,
        )
        .unwrap(),
    );
    let gate = InnovationGate::chi2(0.99).unwrap();
    let mut core = Gated::new(CatchUp::new(kf), gate);
    let (mut runner, mut state) = (kf, GateState::default());
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut k = 0;
    let mut stepped = 0;
    while k < 400 {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        k += 1 + usize::from(rng.is_multiple_of(7)) * (1 + (rng >> 8) as usize % 3);
        let v = ((rng >> 20) % 1000) as f64 / 500.0 - 1.0;
        let y = match rng % 11 {
            0 => Packet::Lost,
            1 => Packet::Dropped,
            // Outliers in runs, to trip the lock-out.
            2..=4 if (k / 20).is_multiple_of(3) => Packet::Delivered(vector![1e3 * v, 50.0]),
            5 => Packet::Delivered(vector![f64::NAN, 0.0]),
            _ => Packet::Delivered(vector![v, -v]),
        };
        let a = core.step(k, &y);
        let b = runner_step(&mut runner, &mut state, &gate, k, &y);
        assert_eq!(a, b, "k = {k}");
        assert_eq!(core.estimate(), runner.estimate(), "k = {k}");
        assert_eq!(core.state(), &state, "k = {k}");
        stepped += usize::from(a.is_ok());
    }
    assert!(stepped > 200);
    assert!(state.counts.rejected > 5 && state.forced > 0, "{state:?}");
}
