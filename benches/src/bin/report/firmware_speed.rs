//! Part `firmware`, issue #37: the two firmware build profiles side by side (`release`,
//! opt-level "s", and `speed`, opt-level 3: flash, peak stack, single-step instructions) and
//! the Kalman steps against their floor (the operations one step must do, counted from the
//! dimensions, and the straight-line `floor3x2` / `floor4x2` binaries as measured).

use crate::firmware::Csv;
use crate::prose;
use std::fmt::Write as _;

/// Floating-point operations of one step of an `n`-state, two-measurement Kalman filter as
/// the straight-line floor does it (`estimator-firmware`'s `peers::ops`, whose test holds the
/// same figures): (mul, add, sub, div). `predict_only`: an instant without its measurement.
pub fn kf_ops(n: usize, predict_only: bool) -> (usize, usize, usize, usize) {
    let m = 2;
    let t = n * (n + 1) / 2;
    let mut mul = n * n + n * n * n + t * n;
    let mut add = n * (n - 1) + n * n * (n - 1) + t * (n - 1) + t;
    let (mut sub, mut div) = (0, 0);
    if !predict_only {
        let tm = m * (m + 1) / 2;
        mul += n * m * n + tm * n + m * n + 5 + n * m * m + n * m + t * m;
        add += n * m * (n - 1) + tm * (n - 1) + tm + m * (n - 1);
        add += n * m * (m - 1) + n * (m - 1) + n + t * (m - 1);
        sub += m + 2 + t;
        div += 1;
    }
    (mul, add, sub, div)
}

/// The Kalman binaries with a floor: (binary, states, its floor binary).
const FLOORED: &[(&str, usize, &str)] = &[
    ("kf", 3, "floor3x2"),
    ("ikf", 3, "floor3x2"),
    ("kf3x2", 3, "floor3x2"),
    ("kfs3x2", 3, "floor3x2"),
    ("kf4x2", 4, "floor4x2"),
    ("kfs4x2", 4, "floor4x2"),
];

/// Both tables, if `.ci/firmware` measured the speed profile.
pub fn render(md: &mut String, release_steps: &Csv, sizes: &Csv, speed: &Csv) {
    prose::push(md, include_str!("prose/firmware_profiles.md"));
    md.push_str("| binary | flash B, s | flash B, 3 | peak stack B, s | peak stack B, 3 | instructions / step, s (min / median / max) | 3 (min / median / max) | median 3 ÷ s |\n|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let cell = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.0}"));
    for r in &speed.rows {
        let b = r[0].as_str();
        let mmm = |c: &Csv| {
            format!(
                "{} / {} / {}",
                cell(c.num(b, "min")),
                cell(c.num(b, "median")),
                cell(c.num(b, "max"))
            )
        };
        let ratio = match (speed.num(b, "median"), release_steps.num(b, "median")) {
            (Some(f), Some(s)) => format!("{:.2}", f / s),
            _ => "–".into(),
        };
        let _ = writeln!(
            md,
            "| `{b}` | {} | {} | {} | {} | {} | {} | {ratio} |",
            cell(sizes.num(b, "flash")),
            cell(speed.num(b, "flash")),
            cell(sizes.num(b, "stack_peak")),
            cell(speed.num(b, "stack_peak")),
            mmm(release_steps),
            mmm(speed),
        );
    }
    md.push('\n');
    prose::push(md, include_str!("prose/firmware_floor.md"));
    md.push_str("| binary | problem | floor: mul + add + sub + div = operations | floor binary, 3 (median) | this, s (max) | this, 3 (max) | this, 3 ÷ floor binary | target ≤ 2× |\n|---|---|---:|---:|---:|---:|---:|---|\n");
    for &(b, n, fb) in FLOORED {
        let (mu, ad, su, dv) = kf_ops(n, false);
        let floor = speed.num(fb, "median");
        let this = speed.num(b, "max");
        let (ratio, verdict) = match (this, floor) {
            (Some(t), Some(f)) => (
                format!("{:.2}", t / f),
                crate::format::verdict(t <= 2.0 * f).to_string(),
            ),
            _ => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            md,
            "| `{b}` | {n}x2 | {mu} + {ad} + {su} + {dv} = {} | {} | {} | {} | {ratio} | {verdict} |",
            mu + ad + su + dv,
            cell(floor),
            cell(release_steps.num(b, "max")),
            cell(this),
        );
    }
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_counts() {
        assert_eq!(kf_ops(3, false), (122, 85, 10, 1));
        assert_eq!(kf_ops(4, false), (221, 168, 14, 1));
        assert_eq!(kf_ops(3, true), (54, 42, 0, 0));
    }

    #[test]
    fn the_tables_fill() {
        let steps = Csv::parse("bin,steps,min,median,max,argmax_k,argmax_branch,mean,bookkeeping_mean\nkf3x2,100,1900,1900,1900,1,arrival,1900.0,400.0\n");
        let sizes = Csv::parse("bin,text,data,flash,stack_peak\nkf3x2,17000,0,17000,1300\n");
        let speed = Csv::parse("bin,text,data,flash,stack_peak,steps,min,median,max,argmax_k,mean\nkf3x2,19000,0,19000,1200,100,950,950,950,1,950.0\nfloor3x2,15000,0,15000,900,100,400,400,400,1,400.0\n");
        let mut md = String::new();
        render(&mut md, &steps, &sizes, &speed);
        assert!(md.contains("| `kf3x2` | 17000 | 19000 | 1300 | 1200 | 1900 / 1900 / 1900 | 950 / 950 / 950 | 0.50 |"), "{md}");
        assert!(md.contains("| `kf3x2` | 3x2 | 122 + 85 + 10 + 1 = 218 | 400 | 1900 | 950 | 2.38 | **missed** |"), "{md}");
    }
}
