//! The slot log: the CSV of received slots that `ipc-runner run --slots-csv` and `demo`
//! write and `ipc-runner replay` reads (see `docs/replay.md` and the example log
//! `docs/examples/example-slots.csv`).
//!
//! One header line, then one row per slot (sampling instant k and sensor node), in
//! increasing k; within an instant any node order:
//!
//! | column        | type    | meaning |
//! |---------------|---------|---------|
//! | `k`           | integer | sampling instant, ≥ 1 (k = 0 is the prior and has no slot) |
//! | `node`        | integer | sensor node, 0-based, < the scenario's node count |
//! | `delivered`   | 0 / 1   | 1 if a measurement reached the estimator, 0 if the packet was dropped |
//! | `flags`       | integer | channel-side flags (`channel_sim::sim::FLAG_*`; 0 if unknown); bit 31 (`FLAG_IPC_LOST`, 2147483648) marks a slot that never reached the receiver |
//! | `y_0` … `y_{ny−1}` | float | the measurement; ignored (may be empty) when `delivered = 0` |
//!
//! A row with `delivered = 0` is a packet the channel dropped (a dropout, which may carry
//! information: occlusion, event trigger), unless its flags have `FLAG_IPC_LOST`: then the
//! packet was lost in transport and carries none (`Packet::Lost`, docs/design.md "A loss is not
//! a dropout"). A node missing from an instant is lost, and so is a missing instant: the
//! estimators always see every k from 1 to the last one in the file. Values `nan`/`inf` are
//! passed to the estimators, which reject them and keep their state (counted).

use anyhow::{bail, Context, Result};
use channel_sim::sim::{MAX_NODES, MAX_NY};
use channel_sim::Observation;
use estpipe_wire::FLAG_IPC_LOST;
use std::io::{BufRead, Write};
use std::path::Path;

/// Writes observations as a slot log.
pub fn write_slots(path: &Path, slots: &[Observation], ny: usize) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
    );
    write!(w, "k,node,delivered,flags")?;
    for j in 0..ny {
        write!(w, ",y_{j}")?;
    }
    writeln!(w)?;
    for o in slots {
        write!(
            w,
            "{},{},{},{}",
            o.k,
            o.node,
            u8::from(o.delivered),
            o.flags
        )?;
        for j in 0..ny {
            if o.delivered {
                write!(w, ",{:e}", o.y[j])?;
            } else {
                write!(w, ",")?;
            }
        }
        writeln!(w)?;
    }
    Ok(())
}

/// Reads a slot log; returns the instants (every k from 1 to the last, all nodes present).
pub fn read_slots(
    path: &Path,
    nodes: usize,
    ny: usize,
) -> Result<Vec<(u32, heapless::Vec<Observation, MAX_NODES>)>> {
    let f = std::fs::File::open(path).with_context(|| format!("cannot open {path:?}"))?;
    let mut lines = std::io::BufReader::new(f).lines();
    let header = lines.next().context("empty slot log")??;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let idx = |name: &str| {
        cols.iter()
            .position(|c| *c == name)
            .with_context(|| format!("{path:?}: header lacks column {name:?} (have {cols:?})"))
    };
    let (ck, cn, cd, cf) = (
        idx("k")?,
        idx("node")?,
        idx("delivered")?,
        idx("flags").ok(),
    );
    let cy: Vec<usize> = (0..ny)
        .map(|j| idx(&format!("y_{j}")))
        .collect::<Result<_>>()?;
    if ny > MAX_NY || nodes > MAX_NODES {
        bail!("scenario dimensions exceed the wire limits");
    }
    let mut out: Vec<(u32, heapless::Vec<Observation, MAX_NODES>)> = Vec::new();
    let blank = |k: u32| {
        let mut v = heapless::Vec::new();
        for n in 0..nodes {
            let _ = v.push(Observation::dropped(k, n as u8, ny as u8, FLAG_IPC_LOST));
        }
        v
    };
    for (ln, line) in lines.enumerate() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        let at = || format!("{path:?} line {}", ln + 2);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |c: usize| f.get(c).copied().unwrap_or("");
        let k: u32 = get(ck)
            .parse()
            .with_context(|| format!("{}: bad k", at()))?;
        let node: usize = get(cn)
            .parse()
            .with_context(|| format!("{}: bad node", at()))?;
        let delivered = match get(cd) {
            "1" | "true" => true,
            "0" | "false" => false,
            v => bail!("{}: delivered must be 0 or 1, got {v:?}", at()),
        };
        let flags: u32 = match cf {
            Some(c) if !get(c).is_empty() => get(c)
                .parse()
                .with_context(|| format!("{}: bad flags", at()))?,
            _ => 0,
        };
        if k == 0 {
            bail!("{}: k must be ≥ 1 (k = 0 is the prior)", at());
        }
        if node >= nodes {
            bail!("{}: node {node} but the scenario has {nodes} node(s)", at());
        }
        let last = out.last().map_or(0, |(lk, _)| *lk);
        if k < last {
            bail!(
                "{}: k = {k} after k = {last}; rows must be in increasing k",
                at()
            );
        }
        while out.last().map_or(0, |(lk, _)| *lk) < k {
            let next = out.last().map_or(1, |(lk, _)| lk + 1);
            out.push((next, blank(next)));
        }
        let mut y = [0.0; MAX_NY];
        if delivered {
            for (j, &c) in cy.iter().enumerate() {
                y[j] = get(c)
                    .parse()
                    .with_context(|| format!("{}: bad y_{j} {:?}", at(), get(c)))?;
            }
        }
        let obs = &mut out.last_mut().expect("pushed above").1[node];
        *obs = Observation {
            k,
            node: node as u8,
            delivered,
            ny: ny as u8,
            y,
            flags,
        };
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_fills_missing_nodes_and_instants() {
        let dir = std::env::temp_dir().join(format!("replay-rt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("s.csv");
        let mut y = [0.0; MAX_NY];
        y[0] = 0.1 + 0.2; // not exactly representable in short decimal: tests round-trip
        y[1] = -1e-300;
        let slots = [
            Observation {
                k: 1,
                node: 1,
                delivered: true,
                ny: 2,
                y,
                flags: 4,
            },
            Observation::dropped(3, 0, 2, 16),
        ];
        write_slots(&p, &slots, 2).unwrap();
        let r = read_slots(&p, 2, 2).unwrap();
        assert_eq!(r.len(), 3);
        assert_eq!(r[0].1[1], slots[0]);
        // Missing rows are lost.
        assert_eq!(r[0].1[0], Observation::dropped(1, 0, 2, FLAG_IPC_LOST));
        assert_eq!(r[1].1[0], Observation::dropped(2, 0, 2, FLAG_IPC_LOST));
        assert_eq!(r[1].1[1], Observation::dropped(2, 1, 2, FLAG_IPC_LOST));
        assert_eq!(r[2].1[1], Observation::dropped(3, 1, 2, FLAG_IPC_LOST));
        assert_eq!(r[2].1[0], slots[1]);
        std::fs::write(&p, "k,node,delivered\n1,5,0\n").unwrap();
        let e = read_slots(&p, 2, 0).unwrap_err().to_string();
        assert!(e.contains("node 5"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
