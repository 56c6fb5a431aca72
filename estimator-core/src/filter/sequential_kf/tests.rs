//! [`SequentialKf`] against a transcription of the runner's node-by-node filter it replaces
//! (ipc-runner's `estimators/kf.rs`, `NodeByNode`), on random problems.

use super::*;

const NX: usize = 3;
const NY: usize = 2;
const L: usize = 4;

/// One node's model at one instant, as the runner's `Snapshot` holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node<T: Real> {
    a: SMatrix<T, NX, NX>,
    q: SMatrix<T, NX, NX>,
    c: SMatrix<T, NY, NX>,
    r: SMatrix<T, NY, NY>,
    u: Option<SVector<T, NX>>,
}

impl<T: Real> LinearSystem<T, NX, NY> for Node<T> {
    fn a(&self, _k: usize) -> SMatrix<T, NX, NX> {
        self.a
    }
    fn c(&self, _k: usize) -> SMatrix<T, NY, NX> {
        self.c
    }
    fn process_cov(&self, _k: usize) -> SMatrix<T, NX, NX> {
        self.q
    }
    fn measurement_cov(&self, _k: usize) -> SMatrix<T, NY, NY> {
        self.r
    }
    fn input(&self, _k: usize) -> Option<SVector<T, NX>> {
        self.u
    }
}

/// The runner's `NodeByNode`, transcribed.
#[derive(Clone, Copy)]
struct Old<T: Real> {
    model: [Node<T>; L],
    nodes: usize,
    kf: KalmanFilter<T, NX>,
    fused: bool,
}

fn fused_ok<T: Real>(m: &Node<T>) -> bool {
    symmetrize(&m.q) == m.q && symmetrize(&m.r) == m.r
}

impl<T: Real> Old<T> {
    fn step(&mut self, k: usize, y: &[Packet<T, NY>; L]) -> Result<()> {
        if self.fused && self.nodes == 1 && y[1..].iter().all(|p| p.delivered().is_none()) {
            if let Some(y0) = y[0].delivered().filter(|v| v.iter().all(|e| e.finite())) {
                return self.kf.step(&self.model[0], k, y0);
            }
        }
        let mut kf = self.kf;
        let m0 = &self.model[0];
        match &m0.u {
            None => kf.predict_with(&m0.a, &m0.q)?,
            Some(u) => kf.predict_with_input(&m0.a, &m0.q, u)?,
        }
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                if node >= self.nodes {
                    return Err(UNKNOWN_NODE);
                }
                let m = &self.model[node];
                kf.update_with::<NY>(&m.c, &m.r, y)?;
            }
        }
        self.kf = kf;
        Ok(())
    }

    fn step_gated(
        &mut self,
        y: &[Packet<T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut kf = self.kf;
        kf.predict_with(&self.model[0].a, &self.model[0].q)?;
        let mut counts = GateCounts::NONE;
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                if node >= self.nodes {
                    return Err(UNKNOWN_NODE);
                }
                let m = &self.model[node];
                counts.add(GateCounts::one(
                    kf.update_gated_with::<NY>(&m.c, &m.r, y, gate)?,
                ));
            }
        }
        self.kf = kf;
        Ok(counts)
    }
}

/// A deterministic generator of uniform numbers in [−1, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn below(&mut self, n: usize) -> usize {
        (((self.next() + 1.0) * 0.5 * n as f64) as usize).min(n - 1)
    }

    fn mat<T: Real, const R: usize, const C: usize>(&mut self, scale: f64) -> SMatrix<T, R, C> {
        SMatrix::from_fn(|_, _| T::lit(self.next() * scale))
    }

    /// `G Gᵀ + δ I`, symmetric bit for bit unless `skew` (then one off-diagonal entry is
    /// off by a little, so that symmetrising it changes it).
    fn spd<T: Real, const N: usize>(&mut self, skew: bool) -> SMatrix<T, N, N> {
        let g: SMatrix<T, N, N> = self.mat(1.0);
        let mut s = symmetrize(&(g * g.transpose() + SMatrix::identity() * T::lit(0.1)));
        if skew && N > 1 {
            s[(0, 1)] += T::lit(1e-3);
        }
        s
    }

    fn model<T: Real>(&mut self, nodes: usize) -> [Node<T>; L] {
        let a = self.mat::<T, NX, NX>(0.6) + SMatrix::identity() * T::lit(0.5);
        let skew = self.below(4) == 0;
        let q = self.spd(skew);
        let u = (self.below(2) == 0).then(|| self.mat(1.0));
        core::array::from_fn(|m| {
            let (c, r) = if m < nodes {
                let skew = self.below(4) == 0;
                (self.mat(1.0), self.spd(skew))
            } else {
                (SMatrix::zeros(), SMatrix::identity())
            };
            Node { a, q, c, r, u }
        })
    }

    fn packets<T: Real>(&mut self, nodes: usize) -> [Packet<T, NY>; L] {
        core::array::from_fn(|m| {
            // Mostly the model's nodes; now and then one past them.
            let limit = if self.below(20) == 0 { L } else { nodes };
            match self.below(3) {
                0 if m < limit => {
                    let mut y: SVector<T, NY> = self.mat(3.0);
                    if self.below(40) == 0 {
                        y[0] = T::lit(f64::NAN);
                    } else if self.below(40) == 0 {
                        y[1] = T::lit(1e30);
                    }
                    Packet::Delivered(y)
                }
                1 => Packet::Dropped,
                _ => Packet::Lost,
            }
        })
    }
}

/// Both filters from one random problem.
fn pair<T: Real>(rng: &mut Rng) -> (SequentialKf<T, NX, NY, L, Node<T>>, Old<T>) {
    let nodes = if rng.below(3) == 0 {
        1
    } else {
        1 + rng.below(L)
    };
    let model = rng.model::<T>(nodes);
    let kf = KalmanFilter::new(rng.mat(2.0), rng.spd(false)).unwrap();
    let new = SequentialKf::new(model, nodes, kf).unwrap();
    let old = Old {
        model,
        nodes,
        kf,
        fused: fused_ok(&model[0]),
    };
    (new, old)
}

fn ungated_matches_the_transcription<T: Real>(seed: u64) {
    let mut rng = Rng(seed);
    let mut fused_steps = 0;
    for _ in 0..200 {
        let (mut new, mut old) = pair::<T>(&mut rng);
        for k in 1..=30 {
            if rng.below(10) == 0 {
                // A time-varying plant: new models at k.
                let model = rng.model::<T>(new.nodes());
                *new.models_mut() = model;
                old.model = model;
                old.fused = fused_ok(&model[0]);
            }
            let y = rng.packets::<T>(new.nodes());
            fused_steps += usize::from(new.fused(k, &y).is_some());
            assert_eq!(new.step(k, &y), old.step(k, &y));
            assert_eq!(new.filter(), &old.kf);
        }
    }
    assert!(fused_steps > 100, "the fused path ran {fused_steps} times");
}

#[test]
fn ungated_steps_are_the_runners_bit_for_bit_f64() {
    ungated_matches_the_transcription::<f64>(1);
}

#[test]
fn ungated_steps_are_the_runners_bit_for_bit_f32() {
    ungated_matches_the_transcription::<f32>(2);
}

/// Without a known input, the gated step is the runner's; with one, its prediction adds the
/// input (the runner's gated step left it out), so that the off gate gives
/// [`Estimator::step`]'s bits.
fn gated_matches<T: Real>(seed: u64) {
    let mut rng = Rng(seed);
    let gate = InnovationGate::<T>::chi2(0.99).unwrap();
    let (mut compared, mut rejected) = (0, 0);
    for _ in 0..200 {
        let (mut f, mut old) = pair::<T>(&mut rng);
        for k in 1..=30 {
            let y = rng.packets::<T>(f.nodes());
            let (mut off, mut plain) = (f, f);
            assert_eq!(
                off.step_gated(k, &y, &InnovationGate::off()).map(|_| ()),
                plain.step(k, &y)
            );
            assert_eq!(off.filter(), plain.filter());
            let got = f.step_gated(k, &y, &gate);
            if f.models()[0].u.is_none() {
                assert_eq!(got, old.step_gated(&y, &gate));
                assert_eq!(f.filter(), &old.kf);
                compared += 1;
            }
            rejected += got.map_or(0, |c| c.rejected);
            old.kf = *f.filter();
        }
    }
    assert!(compared > 1000 && rejected > 10, "{compared} {rejected}");
}

#[test]
fn gated_steps_are_the_runners_without_input_f64() {
    gated_matches::<f64>(3);
}

#[test]
fn gated_steps_are_the_runners_without_input_f32() {
    gated_matches::<f32>(4);
}

#[test]
fn nodes_are_validated_and_an_unknown_node_changes_nothing() {
    let mut rng = Rng(5);
    let model = rng.model::<f64>(2);
    let kf = KalmanFilter::new(SVector::zeros(), SMatrix::identity()).unwrap();
    assert!(SequentialKf::<f64, NX, NY, L, _>::new(model, 0, kf).is_err());
    assert!(SequentialKf::<f64, NX, NY, L, _>::new(model, L + 1, kf).is_err());
    let mut f = SequentialKf::<f64, NX, NY, L, _>::new(model, 2, kf).unwrap();
    let mut y = [Packet::Lost; L];
    y[0] = Packet::Delivered(SVector::repeat(1.0));
    y[2] = Packet::Delivered(SVector::repeat(1.0));
    let before = f;
    assert_eq!(f.step(1, &y), Err(UNKNOWN_NODE));
    assert_eq!(f, before);
    assert_eq!(
        f.step_gated(1, &y, &InnovationGate::chi2(0.9).unwrap()),
        Err(UNKNOWN_NODE)
    );
    assert_eq!(f, before);
}
