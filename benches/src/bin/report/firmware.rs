//! Part `firmware`: the Cortex-M4 figures from `.ci/firmware` (QEMU `mps2-an386` with the
//! instruction-counting TCG plugin): the core's Kalman filter beside its Rust peers (flash,
//! peak stack, instructions per step), every estimator's single steps (minimum, median,
//! maximum and where the maximum is), the differenced means over N steps, and the sensor
//! node in the loop (flash, RAM, instructions per instant: docs/sensor-node.md).

use crate::command::say;
use crate::format::verdict;
use crate::opts::Opts;
use crate::prose;
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::process::Command;

/// The side-by-side binaries: (problem, binary, implementation, covariance form, validation).
const PEERS: &[(&str, &str, &str, &str, &str)] = &[
    ("3x2", "kf3x2", "ours", "Joseph", VALID_OURS),
    ("3x2", "kfs3x2", "ours", "P − K Gᵀ", VALID_OURS),
    ("3x2", "ads3x2", "adskalman 0.18", "Joseph", VALID_ADS),
    ("3x2", "tk3x2", "typed-kalman 0.1", "Joseph", VALID_TK),
    ("3x2", "mk3x2", "minikalman 0.8", "P − K H P", VALID_MK),
    ("4x2", "kf4x2", "ours", "Joseph", VALID_OURS),
    ("4x2", "kfs4x2", "ours", "P − K Gᵀ", VALID_OURS),
    ("4x2", "ads4x2", "adskalman 0.18", "Joseph", VALID_ADS),
    ("4x2", "tk4x2", "typed-kalman 0.1", "Joseph", VALID_TK),
    ("4x2", "mk4x2", "minikalman 0.8", "P − K H P", VALID_MK),
];
const VALID_OURS: &str = "prior, y, S's pivots, x̂⁺ P⁺ NIS finite; rolls back";
const VALID_ADS: &str = "S's Cholesky (NaN in y: no update)";
const VALID_TK: &str = "y and R finite, S's Cholesky, x̂⁺ P⁺ NIS finite";
const VALID_MK: &str = "none";

/// The binary the verdicts are on (ours, Joseph form: the default) per problem.
const OURS: [(&str, &str); 2] = [("3x2", "kf3x2"), ("4x2", "kf4x2")];

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let script = o.root.join(".ci/firmware");
    if !script.exists() {
        bail!(".ci/firmware not present");
    }
    say("running .ci/firmware (QEMU instruction counts)");
    let out = Command::new(&script)
        .current_dir(&o.root)
        .output()
        .context(".ci/firmware")?;
    if !out.status.success() {
        bail!(
            ".ci/firmware failed: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        );
    }
    let dir = o.root.join("estimator-core/firmware/target/qemu");
    let read = |name: &str| -> Result<Csv> {
        let p = dir.join(name);
        Ok(Csv::parse(
            &std::fs::read_to_string(&p).with_context(|| format!("{p:?}"))?,
        ))
    };
    let data = Data {
        means: read("insn_counts.csv")?,
        steps: read("step_counts.csv")?,
        sizes: read("sizes.csv")?,
        node_sizes: read("node_sizes.csv")?,
        node_counts: read("node_counts.csv")?,
    };
    render(md, &data)?;
    // Issue #37: the speed profile and the floors, if .ci/firmware measured them.
    if let Ok(speed) = read("speed_step_counts.csv") {
        crate::firmware_speed::render(md, &data.steps, &data.sizes, &speed);
    }
    // Issue #37: the heavy estimators against their floor, branch by branch.
    if let Ok(branches) = read("branch_counts.csv") {
        crate::firmware_heavy::render(md, &branches);
    }
    // Late packets (issue #33): the fixed-lag binaries, if .ci/firmware counted them.
    if let Ok(lag) = read("lag_counts.csv") {
        crate::late::firmware(md, &lag, &data.sizes);
    }
    // The part can be regenerated on its own (`--skip` the others): say of which commit.
    let commit = Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .current_dir(&o.root)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "?".into());
    let _ = writeln!(md, "(This part measured at commit {commit}.)\n");
    Ok(())
}

/// The three files `.ci/firmware` writes.
struct Data {
    /// `insn_counts.csv`: the differenced counts.
    means: Csv,
    /// `step_counts.csv`: min, median, max of single steps.
    steps: Csv,
    /// `sizes.csv`: flash and peak stack.
    sizes: Csv,
    /// `node_sizes.csv`: the sensor node's flash, RAM and peak stack.
    node_sizes: Csv,
    /// `node_counts.csv`: the sensor node's instructions per instant, by part.
    node_counts: Csv,
}

/// A CSV file without quoting: the header and the rows by their first column.
pub(crate) struct Csv {
    pub(crate) header: Vec<String>,
    pub(crate) rows: Vec<Vec<String>>,
}

impl Csv {
    pub(crate) fn parse(text: &str) -> Self {
        let mut lines = text.lines().filter(|l| !l.is_empty());
        let split = |l: &str| l.split(',').map(str::to_string).collect::<Vec<_>>();
        Self {
            header: lines.next().map(split).unwrap_or_default(),
            rows: lines.map(split).collect(),
        }
    }

    /// Column `col` of the row whose first column is `bin`.
    fn get(&self, bin: &str, col: &str) -> Option<&str> {
        let c = self.header.iter().position(|h| h == col)?;
        let row = self
            .rows
            .iter()
            .find(|r| r.first().is_some_and(|b| b == bin))?;
        row.get(c).map(String::as_str)
    }

    pub(crate) fn num(&self, bin: &str, col: &str) -> Option<f64> {
        self.get(bin, col)?.parse().ok()
    }
}

fn render(md: &mut String, d: &Data) -> Result<()> {
    prose::push(md, include_str!("prose/firmware.md"));
    peers(md, d)?;
    single_steps(md, d);
    prose::push(md, include_str!("prose/firmware_means.md"));
    let _ = writeln!(md, "| {} |", d.means.header.join(" | "));
    let _ = writeln!(md, "|{}|", vec!["---"; d.means.header.len()].join("|"));
    for r in &d.means.rows {
        let _ = writeln!(md, "| {} |", r.join(" | "));
    }
    md.push('\n');
    sensor_node(md, d);
    Ok(())
}

/// The sensor node: its sizes and its instructions per instant.
fn sensor_node(md: &mut String, d: &Data) {
    prose::push(md, include_str!("prose/firmware_node.md"));
    let g = |c: &str| d.node_sizes.get("sensor-node", c).unwrap_or("–");
    let _ = writeln!(
        md,
        "| flash B (code + rodata + data) | RAM B (data + bss + peak stack) | of which peak stack B |\n|---:|---:|---:|\n| {} | {} | {} |\n",
        g("flash"),
        g("ram"),
        g("stack_peak")
    );
    md.push_str("| scenario | part | instants | min | median | max | mean |\n|---|---|---:|---:|---:|---:|---:|\n");
    for r in &d.node_counts.rows {
        let _ = writeln!(md, "| {} |", r.join(" | "));
    }
    md.push('\n');
}

/// The side-by-side table and its verdicts.
fn peers(md: &mut String, d: &Data) -> Result<()> {
    prose::push(md, include_str!("prose/firmware_peers.md"));
    md.push_str("| problem | implementation | binary | covariance update | validation | flash B | peak stack B | instructions / step | loop / step | ours ÷ this |\n|---|---|---|---|---|---:|---:|---:|---:|---:|\n");
    let step = |b: &str| d.steps.num(b, "mean");
    for &(prob, bin, who, form, valid) in PEERS {
        let ours = OURS.iter().find(|(p, _)| *p == prob).map(|(_, b)| *b);
        let ratio = match (ours.and_then(step), step(bin)) {
            (Some(a), Some(b)) if Some(bin) != ours => format!("{:.2}", a / b),
            _ => "".into(),
        };
        let cell = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
        let _ = writeln!(
            md,
            "| {prob} | {who} | `{bin}` | {form} | {valid} | {} | {} | {} | {} | {ratio} |",
            cell(d.sizes.num(bin, "flash")),
            cell(d.sizes.num(bin, "stack_peak")),
            cell(step(bin)),
            cell(d.means.num(bin, "insn_per_step_N+1_to_2N")),
        );
    }
    md.push('\n');
    for (prob, ours) in OURS {
        let others: Vec<_> = PEERS
            .iter()
            .filter(|p| p.0 == prob && p.2 != "ours")
            .collect();
        let best = others
            .iter()
            .filter_map(|p| Some((p.2, step(p.1)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let smallest = others
            .iter()
            .filter_map(|p| Some((p.2, d.sizes.num(p.1, "flash")?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let joseph = others
            .iter()
            .filter(|p| p.3 == "Joseph")
            .filter_map(|p| Some((p.2, step(p.1)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let (Some(s), Some(f), Some((bw, bs)), Some((sw, sf)), Some((jw, js))) = (
            step(ours),
            d.sizes.num(ours, "flash"),
            best,
            smallest,
            joseph,
        ) else {
            bail!("firmware: a {prob} binary is missing from .ci/firmware's files");
        };
        let _ = writeln!(
            md,
            "- {prob}: instructions per step, ours {s:.0} against the best peer's ({bw}) {bs:.0}: **{:.2}×**, target ≤ 0.8×: {} (against the best Joseph-form peer, {jw} {js:.0}: {:.2}×). Flash, ours {f:.0} B against the smallest peer's ({sw}) {sf:.0} B: {:+.0} B, target ≤: {}.",
            s / bs,
            verdict(s <= 0.8 * bs),
            s / js,
            f - sf,
            verdict(f <= sf),
        );
    }
    md.push('\n');
    Ok(())
}

/// Every binary's single steps.
fn single_steps(md: &mut String, d: &Data) {
    prose::push(md, include_str!("prose/firmware_steps.md"));
    md.push_str("| binary | steps | min | median | max | max at | branch of the max | mean | bookkeeping / step |\n|---|---:|---:|---:|---:|---:|---|---:|---:|\n");
    let mut order: BTreeMap<(bool, String), &Vec<String>> = BTreeMap::new();
    for r in &d.steps.rows {
        let peer = PEERS.iter().any(|p| p.1 == r[0]);
        order.insert((peer, r[0].clone()), r);
    }
    for ((_, bin), _) in order {
        let g = |c: &str| d.steps.get(&bin, c).unwrap_or("–");
        let _ = writeln!(
            md,
            "| `{bin}` | {} | {} | {} | {} | k = {} | {} | {} | {} |",
            g("steps"),
            g("min"),
            g("median"),
            g("max"),
            g("argmax_k"),
            g("argmax_branch"),
            g("mean"),
            g("bookkeeping_mean"),
        );
    }
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> Data {
        let mut means = String::from("bin,N,count_steps0,count_stepsN,count_steps2N,insn_per_step_N+1_to_2N,insn_per_step_1_to_2N\n");
        let mut steps =
            String::from("bin,steps,min,median,max,argmax_k,argmax_branch,mean,bookkeeping_mean\n");
        let mut sizes = String::from("bin,text,data,flash,stack_peak\n");
        for (i, p) in PEERS.iter().enumerate() {
            let n = 1000 + 100 * i;
            means.push_str(&format!("{},50,1,2,3,{},{}\n", p.1, n + 400, n + 400));
            steps.push_str(&format!("{},100,{n},{n},{n},1,arrival,{n}.0,400.0\n", p.1));
            sizes.push_str(&format!("{},{},0,{},1000\n", p.1, 18000 + i, 18000 + i));
        }
        steps.push_str("cce,100,3000,3300,5900,47,dropout,3500.5,420.0\n");
        Data {
            means: Csv::parse(&means),
            steps: Csv::parse(&steps),
            sizes: Csv::parse(&sizes),
            node_sizes: Csv::parse(
                "bin,text,data,bss,flash,stack_peak,ram\nsensor-node,16000,0,768,16000,1600,2368\n",
            ),
            node_counts: Csv::parse(
                "scenario,part,instants,min,median,max,mean\ntobit-fusion,instant,6000,7903,8549,8891,8467.5\n",
            ),
        }
    }

    #[test]
    fn the_tables_fill() {
        let mut md = String::new();
        render(&mut md, &data()).unwrap();
        assert!(md.contains("| 3x2 | ours | `kf3x2` | Joseph |"), "{md}");
        // 3x2: ours 1000 against adskalman's 1200 (the best peer, also the best Joseph-form
        // one; our own other form does not count as a peer).
        assert!(md.contains("ours 1000 against the best peer's (adskalman 0.18) 1200: **0.83×**, target ≤ 0.8×: **missed**"), "{md}");
        assert!(md.contains("(against the best Joseph-form peer, adskalman 0.18 1200: 0.83×)"));
        assert!(md.contains("Flash, ours 18000 B against the smallest peer's (adskalman 0.18) 18002 B: -2 B, target ≤: met."), "{md}");
        assert!(
            md.contains("| `cce` | 100 | 3000 | 3300 | 5900 | k = 47 | dropout | 3500.5 | 420.0 |")
        );
        assert!(md.contains("| 16000 | 2368 | 1600 |"), "{md}");
        assert!(md.contains("| tobit-fusion | instant | 6000 | 7903 | 8549 | 8891 | 8467.5 |"));
        // Estimators first, then the side-by-side binaries.
        assert!(md.find("`cce` |").unwrap() < md.find("| `ads3x2` | 100").unwrap());
    }
}
