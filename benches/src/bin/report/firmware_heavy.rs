//! Part `firmware`, issue #37: the heavy estimators (CCE, ADF, KF-IO, NN, Tobit fusion, the
//! centralised moment-matched Tobit filter) against their floor, branch by branch: the operations their equations need
//! (`estimator_core::floor`, whose tests hold the figures), each special-function call priced
//! at what one costs on the M4 (the per-function profile, `.ci/firmware-profile`), beside the
//! completed steps of that branch as `.ci/firmware` counted them in both builds
//! (`branch_counts.csv`).

use crate::firmware::Csv;
use crate::prose;
use estimator_core::floor::{adf, cce, kf_io, nn_seed003, tobit2, tobit_cmm2, Ops};
use std::fmt::Write as _;

/// Instructions of one call on the Cortex-M4 in the speed build, the callees included
/// (prose/firmware_heavy.md says where each comes from): `sqrtf`, `expf`, `logf`, `erfcf`
/// (with its two `expf` beyond |x| ≥ 0.84), half of one `sincosf` for each of `sin` and
/// `cos` (software double precision), `tanhf` (with its `expm1f`).
const PRICE: [(&str, usize); 7] = [
    ("sqrt", 51),
    ("exp", 53),
    ("ln", 54),
    ("erfc", 193),
    ("sin", 1445),
    ("cos", 1445),
    ("tanh", 105),
];

/// The calls of `o` by kind, in [`PRICE`]'s order.
fn calls(o: &Ops) -> [usize; 7] {
    [o.sqrt, o.exp, o.ln, o.erfc, o.sin, o.cos, o.tanh]
}

/// The arithmetic at one instruction an operation, plus every call at its price.
pub fn priced(o: &Ops) -> usize {
    o.arithmetic()
        + calls(o)
            .iter()
            .zip(PRICE)
            .map(|(n, (_, p))| n * p)
            .sum::<usize>()
}

/// "2 exp, 1 ln" (empty: "–").
fn call_list(o: &Ops) -> String {
    let v: Vec<String> = calls(o)
        .iter()
        .zip(PRICE)
        .filter(|(n, _)| **n > 0)
        .map(|(n, (k, _))| format!("{n} {k}"))
        .collect();
    if v.is_empty() {
        "–".into()
    } else {
        v.join(", ")
    }
}

/// The firmware's dimensions: seed 001's 3 states, 2 measurements, 4 regions, 15 Gaussians;
/// seed 003's example; seed 004's 3 nodes on 2 states. `key` is `.ci/firmware`'s: 1 for an
/// arrival, 0 for a dropout; for `tobit` the nodes that sent; for `tobit-cmm` 100 × the nodes
/// that sent + 10 × those of them censored + the silences held.
fn branch(bin: &str, key: usize) -> Option<(String, Ops)> {
    let arrival = key == 1;
    let word = if arrival { "arrival" } else { "dropout" };
    Some(match bin {
        "cce" => (word.into(), cce(3, 4, 15, !arrival)),
        "adf" => (word.into(), adf(3, 4, !arrival)),
        "kf-io" => (word.into(), kf_io(3, 4)),
        "nn" => (format!("{word} (γ_k = 1)"), nn_seed003(true, arrival)),
        "tobit" => (format!("{key} of 3 nodes sent"), tobit2(3, key)),
        "tobit-cmm" => {
            let (sent, censored, held) = (key / 100, key / 10 % 10, key % 10);
            if sent > 3 || censored > sent || held + sent > 3 {
                return None;
            }
            (
                format!("{sent} of 3 sent, {censored} censored, {held} held"),
                tobit_cmm2(sent, censored, held),
            )
        }
        _ => return None,
    })
}

/// The table, if `.ci/firmware` counted the branches.
pub fn render(md: &mut String, branches: &Csv) {
    prose::push(md, include_str!("prose/firmware_heavy.md"));
    md.push_str("| binary | branch | floor: mul + add + sub + div | floor: calls | floor, priced | steps | this, s (min / median / max) | this, 3 (min / median / max) | this, 3 (median) ÷ priced floor |\n|---|---|---:|---|---:|---:|---:|---:|---:|\n");
    let col = |h: &str| branches.header.iter().position(|c| c == h);
    let (Some(cb), Some(cp), Some(ck), Some(cr), Some(cn), Some(c0), Some(c1), Some(c2)) = (
        col("bin"),
        col("profile"),
        col("key"),
        col("refused"),
        col("n"),
        col("min"),
        col("median"),
        col("max"),
    ) else {
        return;
    };
    let find = |b: &str, p: &str, k: &str| {
        branches
            .rows
            .iter()
            .find(|r| r[cb] == b && r[cp] == p && r[ck] == k && r[cr] == "0")
    };
    for r in branches
        .rows
        .iter()
        .filter(|r| r[cp] == "speed" && r[cr] == "0")
    {
        let Some((name, o)) = r[ck].parse().ok().and_then(|k| branch(&r[cb], k)) else {
            continue;
        };
        let mmm = |row: Option<&Vec<String>>| {
            row.map_or("–".into(), |x| {
                format!("{} / {} / {}", x[c0], x[c1], x[c2])
            })
        };
        let floor = priced(&o);
        let ratio = r[c1]
            .parse::<f64>()
            .map_or("–".into(), |m| format!("{:.1}", m / floor as f64));
        let _ = writeln!(
            md,
            "| `{}` | {name} | {} + {} + {} + {} = {} | {} | {floor} | {} | {} | {} | {ratio} |",
            r[cb],
            o.mul,
            o.add,
            o.sub,
            o.div,
            o.arithmetic(),
            call_list(&o),
            r[cn],
            mmm(find(&r[cb], "release", &r[ck])),
            mmm(Some(r)),
        );
    }
    md.push('\n');
    prose::push(md, include_str!("prose/firmware_heavy_rest.md"));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priced_floors() {
        // 218 operations, no call.
        assert_eq!(priced(&cce(3, 4, 15, false)), 218);
        // 544 operations, 15 exp, 5 ln.
        assert_eq!(priced(&cce(3, 4, 15, true)), 544 + 15 * 53 + 5 * 54);
        // 900 operations, 8 sqrt, sin and cos, 6 tanh.
        assert_eq!(
            priced(&nn_seed003(true, true)),
            900 + 8 * 51 + 2890 + 6 * 105
        );
        // The moment-matched Tobit filter, 3 nodes sent with a censored component each:
        // 258 operations, 6 sqrt, 3 exp, 3 erfc.
        assert_eq!(
            priced(&tobit_cmm2(3, 3, 0)),
            258 + 6 * 51 + 3 * 53 + 3 * 193
        );
    }

    #[test]
    fn the_table_fills() {
        let b = Csv::parse("bin,profile,key,refused,n,min,median,max\nnn,release,1,0,34,9000,20000,28000\nnn,speed,1,0,34,4829,10296,11745\nnn,speed,1,1,34,4358,4358,7915\ntobit,speed,3,0,85,13573,14974,15415\ntobit-cmm,speed,330,0,43,3000,3100,3200\n");
        let mut md = String::new();
        render(&mut md, &b);
        assert!(md.contains("| `nn` | arrival (γ_k = 1) | 512 + 277 + 82 + 29 = 900 | 8 sqrt, 1 sin, 1 cos, 6 tanh | 4828 | 34 | 9000 / 20000 / 28000 | 4829 / 10296 / 11745 | 2.1 |"), "{md}");
        assert!(md.contains("| `tobit` | 3 of 3 nodes sent |"), "{md}");
        assert!(
            md.contains("| `tobit-cmm` | 3 of 3 sent, 3 censored, 0 held | 150 + 63 + 36 + 9 = 258 | 6 sqrt, 3 exp, 3 erfc | 1302 | 43 |"),
            "{md}"
        );
        assert_eq!(md.matches("| `nn` |").count(), 1, "{md}");
    }
}
