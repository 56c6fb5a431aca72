//! Our KF step against `adskalman`'s, **interleaved**: the two alternate in short batches
//! within one process, and the ratio is taken per round, so that both sides of every ratio
//! see the same minute of a shared machine.
//!
//! Criterion times each benchmark for seconds before it starts the next one; on a shared VM
//! the speed of the whole machine drifts by 10–20 % over such spans, and that drift lands in
//! the ratio of two sequential medians. Here each round times a batch of ours and a batch of
//! `adskalman`'s back to back (which one goes first alternates), and the reported ratio is
//! the median of the per-round ratios.
//!
//! ```text
//! kf_interleaved [--rounds N] [--batch B] [--json]
//! ```
//!
//! Same problems and the same step functions as the criterion bench `kf_vs_adskalman`
//! (`benches/src/problems.rs`, `benches/src/ads.rs`); agreement of the results is tested in
//! `tests/agreement.rs`.

use anyhow::{bail, Context, Result};
use benches::ads::AdsProblem;
use benches::compare as cmp;
use benches::problems::{occlusion_3x2_f64, tracking_4x2_f32};
use std::hint::black_box;
use std::time::Instant;

/// Nanoseconds per call of `f`, over `batch` calls. The steps themselves are
/// `benches::compare`'s non-inlined functions, the machine code criterion and `icount` run.
#[inline(always)]
fn time(batch: u32, f: &mut impl FnMut()) -> f64 {
    let t = Instant::now();
    for _ in 0..batch {
        f();
    }
    t.elapsed().as_nanos() as f64 / f64::from(batch)
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// The per-round times and ratios of one comparison.
struct Pair {
    problem: &'static str,
    form: &'static str,
    t_ours: Vec<f64>,
    t_ads: Vec<f64>,
    ratio: Vec<f64>,
}

impl Pair {
    /// Runs `rounds` rounds of `batch` calls of each side (after one warm-up batch each),
    /// alternating which side goes first.
    fn measure<P, A, RP, RA>(
        (problem, form): (&'static str, &'static str),
        rounds: u32,
        batch: u32,
        (ours, p): (fn(&P) -> RP, &P),
        (ads, a): (fn(&A) -> RA, &A),
    ) -> Self {
        let mut ours = || {
            black_box(ours(black_box(p)));
        };
        let mut ads = || {
            black_box(ads(black_box(a)));
        };
        time(batch, &mut ours);
        time(batch, &mut ads);
        let mut p = Self {
            problem,
            form,
            t_ours: Vec::new(),
            t_ads: Vec::new(),
            ratio: Vec::new(),
        };
        for r in 0..rounds {
            let (o, a) = if r % 2 == 0 {
                let o = time(batch, &mut ours);
                (o, time(batch, &mut ads))
            } else {
                let a = time(batch, &mut ads);
                (time(batch, &mut ours), a)
            };
            p.t_ours.push(o);
            p.t_ads.push(a);
            p.ratio.push(o / a);
        }
        p
    }
}

fn run() -> Result<()> {
    let Some((rounds, batch, json)) = parse_args()? else {
        return Ok(());
    };
    let pairs = measure_all(rounds, batch);
    if json {
        print_json(&pairs, rounds, batch);
    } else {
        print_table(&pairs, rounds, batch);
    }
    Ok(())
}

/// `(rounds, batch, json)` from the command line; `None` after `--help`.
fn parse_args() -> Result<Option<(u32, u32, bool)>> {
    let (mut rounds, mut batch, mut json) = (4000u32, 1000u32, false);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut num = |what: &str| -> Result<u32> {
            let v = args
                .next()
                .with_context(|| format!("{what} needs a number"))?;
            match v.parse::<u32>() {
                Ok(n) if n > 0 => Ok(n),
                _ => bail!("{what} {v:?}: expected a positive integer"),
            }
        };
        match a.as_str() {
            "--rounds" => rounds = num("--rounds")?,
            "--batch" => batch = num("--batch")?,
            "--json" => json = true,
            "-h" | "--help" => {
                println!("kf_interleaved [--rounds N (4000)] [--batch B (1000)] [--json]");
                return Ok(None);
            }
            x => bail!("unknown argument {x:?} (try --help)"),
        }
    }
    Ok(Some((rounds, batch, json)))
}

/// The four comparisons, `rounds` rounds of `batch` calls each side.
fn measure_all(rounds: u32, batch: u32) -> Vec<Pair> {
    let (p64, p32) = (occlusion_3x2_f64(), tracking_4x2_f32());
    let (a64, a32) = (AdsProblem::from_core(&p64), AdsProblem::from_core(&p32));
    // The four comparisons take turns in chunks of rounds, so that each one is spread over
    // the whole run rather than over one stretch of it.
    let chunk = rounds.div_ceil(8);
    let mut pairs: Vec<Pair> = Vec::new();
    let mut done = 0;
    while done < rounds {
        let n = chunk.min(rounds - done);
        let parts = [
            Pair::measure(
                ("3x2_f64", "Joseph"),
                n,
                batch,
                (cmp::ours_joseph_3x2_f64, &p64),
                (cmp::ads_joseph_3x2_f64, &a64),
            ),
            Pair::measure(
                ("4x2_f32", "Joseph"),
                n,
                batch,
                (cmp::ours_joseph_4x2_f32, &p32),
                (cmp::ads_joseph_4x2_f32, &a32),
            ),
            Pair::measure(
                ("3x2_f64", "optimal gain"),
                n,
                batch,
                (cmp::ours_standard_3x2_f64, &p64),
                (cmp::ads_symmetric_3x2_f64, &a64),
            ),
            Pair::measure(
                ("4x2_f32", "optimal gain"),
                n,
                batch,
                (cmp::ours_standard_4x2_f32, &p32),
                (cmp::ads_symmetric_4x2_f32, &a32),
            ),
        ];
        if pairs.is_empty() {
            pairs.extend(parts);
        } else {
            for (p, q) in pairs.iter_mut().zip(parts) {
                p.t_ours.extend(q.t_ours);
                p.t_ads.extend(q.t_ads);
                p.ratio.extend(q.ratio);
            }
        }
        done += n;
    }
    pairs
}

/// One JSON array, a row per comparison.
fn print_json(pairs: &[Pair], rounds: u32, batch: u32) {
    let rows: Vec<serde_json::Value> = pairs
        .iter()
        .map(|p| {
            serde_json::json!({
                "problem": p.problem,
                "form": p.form,
                "rounds": rounds,
                "batch": batch,
                "ours_median_ns": quantile(&p.t_ours, 0.5),
                "ads_median_ns": quantile(&p.t_ads, 0.5),
                "ratio_median": quantile(&p.ratio, 0.5),
                "ratio_p10": quantile(&p.ratio, 0.1),
                "ratio_p90": quantile(&p.ratio, 0.9),
            })
        })
        .collect();
    println!("{}", serde_json::Value::Array(rows));
}

/// A table, a line per comparison.
fn print_table(pairs: &[Pair], rounds: u32, batch: u32) {
    println!(
        "{rounds} rounds of {batch} calls each side\n\
         problem  form          ours ns  adskalman ns  ratio (median of rounds, p10-p90)"
    );
    for p in pairs {
        println!(
            "{:8} {:12} {:8.1} {:13.1}  {:.3} ({:.3}-{:.3})",
            p.problem,
            p.form,
            quantile(&p.t_ours, 0.5),
            quantile(&p.t_ads, 0.5),
            quantile(&p.ratio, 0.5),
            quantile(&p.ratio, 0.1),
            quantile(&p.ratio, 0.9)
        );
    }
}

fn main() {
    if let Err(e) = run() {
        eprintln!("kf_interleaved: {e:#}");
        std::process::exit(2);
    }
}
