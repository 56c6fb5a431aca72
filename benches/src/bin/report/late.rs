//! What a late packet costs (issue #33): the fixed-lag layer (`estimator_core::FixedLag`,
//! L = 8) over IKF and ADF. On the host from the `icount` part's `late/…` kernels
//! (`benches/src/late.rs`), net of the kernels' putting back of their fixed history; on the
//! Cortex-M4 from `.ci/firmware`'s `lag_counts.csv` (the `ikf-lag8` and `adf-lag8` binaries'
//! steps and folds) and `sizes.csv`.

use crate::firmware::Csv;
use crate::prose;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The estimators of the host kernels: (tag, what).
const HOST: &[(&str, &str)] = &[
    ("ikf", "IKF (3x2, the converged problem)"),
    ("adf", "ADF (S = 4, n_x = 3)"),
];

/// The host table, from the instructions per call of every kernel (`res`: name → count).
/// Nothing if the `late/…` kernels were not counted.
pub fn host(md: &mut String, res: &BTreeMap<String, u64>) {
    let get = |tag: &str, event: &str| {
        res.get(&format!("late/{tag}_{event}/3x2_f64"))
            .map(|&v| v as i64)
    };
    let mut rows = String::new();
    for &(tag, what) in HOST {
        let (
            Some(reset),
            Some(plain),
            Some(lag_reset),
            Some(step),
            Some(lost),
            Some(fold1),
            Some(fold8),
        ) = (
            get(tag, "reset"),
            get(tag, "plain"),
            get(tag, "lag8_reset"),
            get(tag, "lag8_step"),
            get(tag, "lag8_step_lost"),
            get(tag, "lag8_step_fold1"),
            get(tag, "lag8_fold8"),
        )
        else {
            continue;
        };
        let plain = plain - reset;
        let (step, lost, step_fold1, fold8) = (
            step - lag_reset,
            lost - lag_reset,
            fold1 - lag_reset,
            fold8 - lag_reset,
        );
        let _ = writeln!(
            rows,
            "| {what} | {plain} | {step} | {:+} | {lost} | {step_fold1} | {} | {fold8} | {:.1} |",
            step - plain,
            step_fold1 - lost,
            fold8 as f64 / plain as f64,
        );
    }
    if rows.is_empty() {
        return;
    }
    prose::push(md, include_str!("prose/late_host.md"));
    md.push_str("| estimator | plain step | step through the layer | the layer's part | step without its packet | step + fold l = 1 | fold l = 1 | fold l = 8 | fold l = 8 ÷ plain step |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    md.push_str(&rows);
    md.push('\n');
}

/// The events of `lag_counts.csv`, in the table's order: (event, what).
const EVENTS: &[(&str, &str)] = &[
    ("plain_step", "on-time binary's step (same instants)"),
    ("step", "step through the layer, packet on time"),
    ("layer", "the layer's part of it (per instant)"),
    ("step_late", "step without its packet (late)"),
    ("step+fold1", "step + fold of its packet, l = 1"),
    ("fold1", "fold, l = 1"),
    ("fold8", "fold, l = 8"),
];

/// The Cortex-M4 tables: sizes of the fixed-lag binaries beside their on-time binaries, and
/// their steps and folds. Nothing if `.ci/firmware` wrote no fixed-lag rows.
pub fn firmware(md: &mut String, lag: &Csv, sizes: &Csv) {
    let mut bins: Vec<&str> = Vec::new();
    for r in &lag.rows {
        if let Some(b) = r.first() {
            if !bins.contains(&b.as_str()) {
                bins.push(b);
            }
        }
    }
    if bins.is_empty() {
        return;
    }
    prose::push(md, include_str!("prose/late_firmware.md"));
    md.push_str("| binary | flash B | on-time binary | its flash B | difference | peak stack B | its peak stack B | difference |\n|---|---:|---|---:|---:|---:|---:|---:|\n");
    for &b in &bins {
        let plain = b.split("-lag").next().unwrap_or(b);
        let n = |bin: &str, col: &str| sizes.num(bin, col);
        let cell = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
        let diff = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:+.0}", a - b),
            _ => "–".into(),
        };
        let _ = writeln!(
            md,
            "| `{b}` | {} | `{plain}` | {} | {} | {} | {} | {} |",
            cell(n(b, "flash")),
            cell(n(plain, "flash")),
            diff(n(b, "flash"), n(plain, "flash")),
            cell(n(b, "stack_peak")),
            cell(n(plain, "stack_peak")),
            diff(n(b, "stack_peak"), n(plain, "stack_peak")),
        );
    }
    md.push('\n');
    md.push_str("| binary | event | n | min | median | max | max at | mean |\n|---|---|---:|---:|---:|---:|---:|---:|\n");
    for &b in &bins {
        for &(event, what) in EVENTS {
            let g = |c: &str| {
                lag.rows
                    .iter()
                    .find(|r| {
                        r.first().map(String::as_str) == Some(b)
                            && r.get(1).map(String::as_str) == Some(event)
                    })
                    .and_then(|r| {
                        let i = lag.header.iter().position(|h| h == c)?;
                        r.get(i).cloned()
                    })
            };
            let Some(n) = g("n") else { continue };
            let v = |c: &str| g(c).unwrap_or_else(|| "–".into());
            let _ = writeln!(
                md,
                "| `{b}` | {what} | {n} | {} | {} | {} | k = {} | {} |",
                v("min"),
                v("median"),
                v("max"),
                v("argmax_k"),
                v("mean"),
            );
        }
    }
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_table_is_net_of_the_reset() {
        let mut res = BTreeMap::new();
        for (event, v) in [
            ("reset", 10),
            ("plain", 110),
            ("lag8_reset", 50),
            ("lag8_step", 170),
            ("lag8_step_lost", 90),
            ("lag8_step_fold1", 250),
            ("lag8_fold8", 1050),
        ] {
            res.insert(format!("late/ikf_{event}/3x2_f64"), v);
        }
        let mut md = String::new();
        host(&mut md, &res);
        // plain 100, step 120 (+20), lost 40, step + fold1 200, fold1 160, fold8 1000 (10×).
        assert!(
            md.contains("| IKF (3x2, the converged problem) | 100 | 120 | +20 | 40 | 200 | 160 | 1000 | 10.0 |"),
            "{md}"
        );
        // ADF was not counted: no row.
        assert!(!md.contains("| ADF"));
        let mut none = String::new();
        host(&mut none, &BTreeMap::new());
        assert!(none.is_empty());
    }

    #[test]
    fn the_firmware_tables_fill() {
        let lag = Csv::parse(
            "bin,event,n,min,median,max,argmax_k,mean\nikf-lag8,step,71,891,2067,2067,2,1669.4\nikf-lag8,fold8,9,7837,13717,16069,13,13063.7\n",
        );
        let sizes = Csv::parse(
            "bin,text,data,flash,stack_peak\nikf,17488,0,17488,1344\nikf-lag8,21728,0,21728,2888\n",
        );
        let mut md = String::new();
        firmware(&mut md, &lag, &sizes);
        assert!(
            md.contains("| `ikf-lag8` | 21728 | `ikf` | 17488 | +4240 | 2888 | 1344 | +1544 |"),
            "{md}"
        );
        assert!(
            md.contains(
                "| `ikf-lag8` | fold, l = 8 | 9 | 7837 | 13717 | 16069 | k = 13 | 13063.7 |"
            ),
            "{md}"
        );
        // Events the file does not have are left out.
        assert!(!md.contains("fold, l = 1 |"));
        let mut none = String::new();
        firmware(&mut none, &Csv::parse("bin,event\n"), &sizes);
        assert!(none.is_empty());
    }
}
