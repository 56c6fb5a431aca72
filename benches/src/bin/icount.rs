//! Runs one benchmark kernel `n` times, for instruction counting under callgrind.
//!
//! `icount KERNEL N` does the setup (building the problem, converging the prior), then calls
//! the kernel `N` times. Running it with `N` and `2N` under `valgrind --tool=callgrind` and
//! taking `(I(2N) − I(N)) / N` cancels the setup and process start-up exactly, leaving the
//! instructions of one step. `icount list` prints the kernel names.

use benches::ads::AdsProblem;
use benches::compare as cmp;
use benches::problems::{occlusion_3x2_f32, occlusion_3x2_f64, tracking_4x2_f32, tracking_4x2_f64};
use std::hint::black_box;
use std::process::ExitCode;

type Kernel = Box<dyn FnMut(u64) -> u64>;

/// Repeats `f` `n` times; counts the successful steps so nothing is optimised away.
fn repeat<R, E>(mut f: impl FnMut() -> Result<R, E> + 'static) -> Kernel {
    Box::new(move |n| {
        let mut ok = 0;
        for _ in 0..n {
            if black_box(f()).is_ok() {
                ok += 1;
            }
        }
        ok
    })
}

fn kernels() -> Vec<(&'static str, Kernel)> {
    let mut out = part_kernels();
    out.extend(kf_kernels());
    library_kernels(&mut out);
    out
}

/// Profiling parts of the 3x2 f64 step (not a product API): where the instructions go.
fn part_kernels() -> Vec<(&'static str, Kernel)> {
    let pp = occlusion_3x2_f64();
    let c = pp.model.c;
    let s = c * pp.prior.estimate().covariance() * c.transpose()
        + nalgebra::SMatrix::<f64, 2, 2>::identity();
    let s = (s + s.transpose()) * 0.5;
    let m3 = *pp.prior.estimate().covariance();
    Vec::from([
        (
            "parts/validated_cholesky_2x2",
            repeat(move || {
                estimator_core::linalg::cholesky(black_box(&s), "S").map(|c| c.l_dirty()[(0, 0)])
            }),
        ),
        (
            "parts/nalgebra_cholesky_2x2",
            repeat(move || {
                black_box(s)
                    .cholesky()
                    .ok_or(())
                    .map(|c| c.l_dirty()[(0, 0)])
            }),
        ),
        (
            "parts/asymmetry_3x3",
            repeat(move || Ok::<f64, ()>(estimator_core::linalg::asymmetry(black_box(&m3)))),
        ),
        (
            "parts/predict",
            repeat(move || {
                let mut f = black_box(&pp).prior;
                f.predict(&pp.model, 1).map(|_| f)
            }),
        ),
        (
            "parts/update",
            repeat(move || {
                let mut f = black_box(&pp).prior;
                f.update(&pp.model, 1, &pp.y).map(|_| f)
            }),
        ),
    ])
}

/// The Kalman filter's and the intermittent filter's steps, ours against adskalman's.
fn kf_kernels() -> Vec<(&'static str, Kernel)> {
    let p64 = occlusion_3x2_f64();
    let p32 = occlusion_3x2_f32();
    let t64 = tracking_4x2_f64();
    let t32 = tracking_4x2_f32();
    let a64 = AdsProblem::from_core(&p64);
    let a32 = AdsProblem::from_core(&t32);
    let (a64s, a32s) = (a64.clone(), a32.clone());
    Vec::from([
        (
            "kf/3x2_f64",
            repeat(move || cmp::ours_joseph_3x2_f64(black_box(&p64))),
        ),
        (
            "adskalman/3x2_f64",
            repeat(move || cmp::ads_joseph_3x2_f64(black_box(&a64))),
        ),
        (
            "kf/4x2_f32",
            repeat(move || cmp::ours_joseph_4x2_f32(black_box(&t32))),
        ),
        (
            "adskalman/4x2_f32",
            repeat(move || cmp::ads_joseph_4x2_f32(black_box(&a32))),
        ),
        (
            "kf_standard/3x2_f64",
            repeat(move || cmp::ours_standard_3x2_f64(black_box(&p64))),
        ),
        (
            "adskalman_symmetric/3x2_f64",
            repeat(move || cmp::ads_symmetric_3x2_f64(black_box(&a64s))),
        ),
        (
            "kf_standard/4x2_f32",
            repeat(move || cmp::ours_standard_4x2_f32(black_box(&t32))),
        ),
        (
            "adskalman_symmetric/4x2_f32",
            repeat(move || cmp::ads_symmetric_4x2_f32(black_box(&a32s))),
        ),
        ("kf/3x2_f32", repeat(move || black_box(&p32).kf_step())),
        ("kf/4x2_f64", repeat(move || black_box(&t64).kf_step())),
        (
            "ikf_arrival/3x2_f64",
            repeat(move || black_box(&p64).ikf_arrival_step()),
        ),
        (
            "ikf_dropout/3x2_f64",
            repeat(move || black_box(&p64).ikf_dropout_step()),
        ),
        (
            "ikf_arrival/4x2_f32",
            repeat(move || black_box(&t32).ikf_arrival_step()),
        ),
        (
            "ikf_dropout/4x2_f32",
            repeat(move || black_box(&t32).ikf_dropout_step()),
        ),
    ])
}

/// The kernels the library's modules name: the papers' estimators, late packets, the view's
/// tap.
fn library_kernels(out: &mut Vec<(&'static str, Kernel)>) {
    // The papers' estimators: the same kernels as the criterion bench `steps`.
    let est = benches::estimators::all_kernels();
    for (name, f) in est {
        out.push((Box::leak(name.into_boxed_str()), repeat(f)));
    }
    // A late packet through the fixed-lag layer (issue #33).
    for (name, f) in benches::late::kernels() {
        out.push((Box::leak(name.into_boxed_str()), repeat(f)));
    }
    // The live view's tap (report part `view`, not the `icount` table).
    for (name, f) in benches::view_tap::kernels() {
        out.push((Box::leak(name.into_boxed_str()), repeat(f)));
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let mut ks = kernels();
    match args.get(1).map(String::as_str) {
        Some("list") => {
            for (name, _) in &ks {
                println!("{name}");
            }
            ExitCode::SUCCESS
        }
        Some(name) => {
            let Some((_, k)) = ks.iter_mut().find(|(n, _)| *n == name) else {
                eprintln!("icount: unknown kernel {name:?}; `icount list` names them");
                return ExitCode::from(2);
            };
            let n: u64 = match args.get(2).map(|s| s.parse()) {
                Some(Ok(n)) => n,
                _ => {
                    eprintln!("usage: icount KERNEL N");
                    return ExitCode::from(2);
                }
            };
            let ok = k(n);
            if ok != n {
                eprintln!("icount: {name}: {} of {n} steps failed", n - ok);
                return ExitCode::FAILURE;
            }
            ExitCode::SUCCESS
        }
        None => {
            eprintln!("usage: icount KERNEL N | icount list");
            ExitCode::from(2)
        }
    }
}
