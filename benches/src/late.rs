//! What a late packet costs on the host: the step kernels of the fixed-lag layer
//! ([`FixedLag`], L = [`LAG`]) over IKF and ADF in `f64`, which `icount` counts the
//! instructions of (BENCHMARKS.md, "What a late packet costs on the host").
//!
//! Every kernel starts from a fixed history, put back at every call, so every call does the
//! same work: the estimator stepped over instants `1..=LAG` with the same delivered packet
//! (IKF: the converged 3x2 problem of [`crate::problems`]; ADF: the state of the ADF kernels
//! of [`crate::estimators`]), the model borrowed as on the microcontroller. The events,
//! at instant `LAG + 1`:
//!
//! - `<e>_reset`, `<e>_plain`: the estimator put back; and then its own step;
//! - `<e>_lag8_reset`: the layer put back (the cost every `lag8` kernel includes);
//! - `<e>_lag8_step`: a step through the layer, the packet on time;
//! - `<e>_lag8_step_lost`: a step through the layer without its packet (late);
//! - `<e>_lag8_step_fold1`: that step, then the fold of its packet (`l = 1`);
//! - `<e>_lag8_fold8`: the fold of a packet `l = LAG` late, into a history whose oldest
//!   instant was stepped without it (the other instants on time).

use crate::estimators::StepFn;
use crate::problems::occlusion_3x2_f64;
use estimator_core::filter::{AssumedDensityFilter, IntermittentKalmanFilter};
use estimator_core::model::LinearModel;
use estimator_core::papers::Seed001Example;
use estimator_core::{Estimator, FixedLag, OnModel, Packet, Revision};
use nalgebra::{vector, SMatrix};
use std::hint::black_box;

/// The lag of the kernels (the firmware's fixed-lag binaries have the same).
pub const LAG: usize = 8;

type Model = LinearModel<f64, 3, 3, 2, 2>;
type Lagged<E> = FixedLag<E, Packet<f64, 2>, LAG>;

/// The kernels of one estimator `est` (as it is before instant 1), named
/// `late/<tag>_<event>/3x2_f64`, with the delivered packet `y` of every instant.
fn kernels_of<E>(tag: &str, est: E, y: Packet<f64, 2>) -> Vec<(String, StepFn)>
where
    E: Estimator<f64, 3, Measurement = Packet<f64, 2>> + Clone + 'static,
{
    let (on_time, oldest_late) = histories(est, y);
    let name = |event: &str| format!("late/{tag}_{event}/3x2_f64");
    let mut out = estimator_kernels(&name, on_time.inner().clone(), y);
    out.extend(layer_kernels(&name, &on_time, &oldest_late, y));
    out
}

/// The two histories of instants `1..=LAG` through the layer: every packet on time, and the
/// oldest instant's stepped without it; checked to fold what the events are meant to.
fn histories<E>(est: E, y: Packet<f64, 2>) -> (Lagged<E>, Lagged<E>)
where
    E: Estimator<f64, 3, Measurement = Packet<f64, 2>> + Clone + 'static,
{
    let k = LAG + 1;
    let mut on_time = Lagged::new(est.clone());
    let mut oldest_late = Lagged::new(est);
    for i in 1..=LAG {
        on_time.step(i, &y).expect("history");
        let yi = if i == 1 { Packet::Lost } else { y };
        oldest_late.step(i, &yi).expect("history");
    }
    // The events fold what they are meant to.
    let mut check = on_time.clone();
    check.step(k, &Packet::Lost).expect("step");
    assert_eq!(
        check.fold_in(k, &y),
        Ok(Revision::Folded {
            from: k,
            restepped: 1
        })
    );
    let mut check = oldest_late.clone();
    assert_eq!(
        check.fold_in(1, &y),
        Ok(Revision::Folded {
            from: 1,
            restepped: LAG
        })
    );
    (on_time, oldest_late)
}

/// `<e>_reset` and `<e>_plain`: the estimator without the layer (`plain`, after the
/// history) put back, and then its own step at instant `LAG + 1`.
fn estimator_kernels<E>(
    name: &dyn Fn(&str) -> String,
    plain: E,
    y: Packet<f64, 2>,
) -> Vec<(String, StepFn)>
where
    E: Estimator<f64, 3, Measurement = Packet<f64, 2>> + Clone + 'static,
{
    let k = LAG + 1;
    let mut out: Vec<(String, StepFn)> = Vec::new();
    {
        let (mut e, plain) = (plain.clone(), plain.clone());
        out.push((
            name("reset"),
            Box::new(move || {
                e.clone_from(black_box(&plain));
                black_box(&e);
                Ok(())
            }),
        ));
    }
    {
        let mut e = plain.clone();
        out.push((
            name("plain"),
            Box::new(move || {
                e.clone_from(black_box(&plain));
                e.step(k, black_box(&y))?;
                black_box(&e);
                Ok(())
            }),
        ));
    }
    out
}

/// The `<e>_lag8_*` kernels: the layer put back from one of the histories, then its event at
/// instant `LAG + 1` (module docs).
fn layer_kernels<E>(
    name: &dyn Fn(&str) -> String,
    on_time: &Lagged<E>,
    oldest_late: &Lagged<E>,
    y: Packet<f64, 2>,
) -> Vec<(String, StepFn)>
where
    E: Estimator<f64, 3, Measurement = Packet<f64, 2>> + Clone + 'static,
{
    let k = LAG + 1;
    // (event, history, packet of instant k, fold: (instant, packet))
    type Event = (&'static str, bool, Option<Packet<f64, 2>>, Option<usize>);
    let events: [Event; 5] = [
        ("lag8_reset", true, None, None),
        ("lag8_step", true, Some(y), None),
        ("lag8_step_lost", true, Some(Packet::Lost), None),
        ("lag8_step_fold1", true, Some(Packet::Lost), Some(k)),
        ("lag8_fold8", false, None, Some(1)),
    ];
    let mut out: Vec<(String, StepFn)> = Vec::new();
    for (event, on, step, fold) in events {
        let history = if on {
            on_time.clone()
        } else {
            oldest_late.clone()
        };
        let mut l = history.clone();
        out.push((
            name(event),
            Box::new(move || {
                l.clone_from(black_box(&history));
                if let Some(s) = &step {
                    l.step(k, black_box(s))?;
                }
                if let Some(j) = fold {
                    l.fold_in(j, black_box(&y))?;
                }
                black_box(&l);
                Ok(())
            }),
        ));
    }
    out
}

/// The kernels of IKF and ADF (module docs).
pub fn kernels() -> Vec<(String, StepFn)> {
    let p = occlusion_3x2_f64();
    let m: &'static Model = Box::leak(Box::new(p.model));
    let ikf = OnModel::<_, IntermittentKalmanFilter<f64, 3>, 2>::new(m, p.prior_ikf);
    let mut out = kernels_of("ikf", ikf, Packet::Delivered(p.y));
    // The ADF kernels' state and packet (`estimators::occlusion_kernels`).
    let occ = Seed001Example::occlusion::<f64>().expect("valid occlusion");
    let adf = AssumedDensityFilter::new(
        vector![35.0, 1.0, 0.5],
        SMatrix::<f64, 3, 3>::identity() * 0.5,
        occ,
    )
    .expect("valid");
    let m: &'static Model = Box::leak(Box::new(
        Seed001Example::model::<f64>().expect("valid model"),
    ));
    out.extend(kernels_of(
        "adf",
        OnModel::<_, _, 2>::new(m, adf),
        Packet::Delivered(vector![100.0, 35.0]),
    ));
    out
}
