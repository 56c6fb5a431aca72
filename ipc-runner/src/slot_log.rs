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
//! | `tokens`      | integer, optional | the bucket level a delivered packet reported (the wire's `tokens`); empty when none |
//! | `late_after`  | integer, optional | a slot that arrived late: the newest instant handed on when it came (0 or absent: on time) |
//!
//! A row with `delivered = 0` is a packet the channel dropped (a dropout, which may carry
//! information: occlusion, event trigger), unless its flags have `FLAG_IPC_LOST`: then the
//! packet was lost in transport and carries none (`Packet::Lost`, docs/design.md "A loss is not
//! a dropout"). A node missing from an instant is lost, and so is a missing instant: the
//! estimators always see every k from 1 to the last one in the file. Values `nan`/`inf` are
//! passed to the estimators, which reject them and keep their state (counted). A `(k, node)`
//! given twice is an error naming both lines; so is anything unparsable (file, line, field:
//! exit code 2), a line over 64 KiB, and a k beyond the memory budget (docs/replay.md).

use crate::limits::{BadInput, BoundedLines};
use anyhow::{bail, Context, Result};
use channel_sim::sim::{MAX_NODES, MAX_NY};
use channel_sim::Observation;
use estpipe_wire::FLAG_IPC_LOST;
use std::io::Write;
use std::path::Path;

/// Writes observations as a slot log. `late_after` lists the slots (by index in `slots`)
/// that arrived late and the newest instant handed on when they came: with any, the log has
/// a `late_after` column and its rows are ordered by k (a late slot among its instant's).
pub fn write_slots(
    path: &Path,
    slots: &[Observation],
    ny: usize,
    late_after: &[(usize, u32)],
) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
    );
    write!(w, "k,node,delivered,flags").with_context(|| format!("cannot write {path:?}"))?;
    for j in 0..ny {
        write!(w, ",y_{j}").with_context(|| format!("cannot write {path:?}"))?;
    }
    write!(w, ",tokens").with_context(|| format!("cannot write {path:?}"))?;
    let mut after = vec![
        0u32;
        if late_after.is_empty() {
            0
        } else {
            slots.len()
        }
    ];
    for &(i, k) in late_after {
        if let Some(a) = after.get_mut(i) {
            *a = k;
        }
    }
    let mut order: Vec<usize> = (0..slots.len()).collect();
    if !after.is_empty() {
        write!(w, ",late_after").with_context(|| format!("cannot write {path:?}"))?;
        order.sort_by_key(|&i| slots[i].k);
    }
    writeln!(w).with_context(|| format!("cannot write {path:?}"))?;
    for i in order {
        let o = &slots[i];
        write!(
            w,
            "{},{},{},{}",
            o.k,
            o.node,
            u8::from(o.delivered),
            o.flags
        )
        .with_context(|| format!("cannot write {path:?}"))?;
        for j in 0..ny {
            if o.delivered {
                write!(w, ",{:e}", o.y[j]).with_context(|| format!("cannot write {path:?}"))?;
            } else {
                write!(w, ",").with_context(|| format!("cannot write {path:?}"))?;
            }
        }
        match o.tokens {
            Some(t) => write!(w, ",{t}"),
            None => write!(w, ","),
        }
        .with_context(|| format!("cannot write {path:?}"))?;
        if let Some(a) = after.get(i) {
            write!(w, ",{a}").with_context(|| format!("cannot write {path:?}"))?;
        }
        writeln!(w).with_context(|| format!("cannot write {path:?}"))?;
    }
    // Dropping a BufWriter loses its last error: a full disk must fail the write.
    w.flush()
        .with_context(|| format!("cannot write {path:?}"))?;
    Ok(())
}

/// Reading stopped at this line on SIGINT/SIGTERM/SIGHUP.
#[derive(Debug)]
pub struct Interrupted(pub u64);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted while reading line {}", self.0)
    }
}

impl std::error::Error for Interrupted {}

/// One instant as read from a slot log: k and every node's observation.
pub type LoggedInstant = (u32, heapless::Vec<Observation, MAX_NODES>);

/// Instants [`read_slots`] accepts: the k span the default memory budget holds.
pub const DEFAULT_MAX_INSTANTS: u64 =
    crate::limits::DEFAULT_MAX_MEMORY_MIB * (1 << 20) / size_of::<LoggedInstant>() as u64;

/// A slot log as read: the instants, and the slots that arrived late.
#[derive(Clone, Debug, Default)]
pub struct SlotLog {
    /// Every k from 1 to the last, all nodes present (a late slot is lost at its instant).
    pub instants: Vec<LoggedInstant>,
    /// The slots that arrived late (a `late_after` above 0): the newest instant handed on
    /// when each came, and the slot; in file order.
    pub late: Vec<(u32, Observation)>,
}

/// Reads a slot log; returns the instants (every k from 1 to the last, all nodes present),
/// with at most [`DEFAULT_MAX_INSTANTS`] of them.
pub fn read_slots(path: &Path, nodes: usize, ny: usize) -> Result<Vec<LoggedInstant>> {
    Ok(read_slots_within(path, nodes, ny, DEFAULT_MAX_INSTANTS)?.instants)
}

/// [`read_slots`] with a bound on the k span: a row whose k exceeds `max_instants` is refused
/// before the gap up to it is filled (each instant from 1 to the last k is held). Lines are
/// bounded too ([`crate::limits::BoundedLines`]: at most 64 KiB each, and `2 · max_instants ·
/// nodes + 1` of them, blank ones included). Every error is [`BadInput`] naming the file and,
/// for a row, its line and field; a repeated `(k, node)` names both lines.
pub fn read_slots_within(
    path: &Path,
    nodes: usize,
    ny: usize,
    max_instants: u64,
) -> Result<SlotLog> {
    if ny > MAX_NY || nodes > MAX_NODES {
        bail!("scenario dimensions exceed the wire limits");
    }
    let name = path.display();
    let f = std::fs::File::open(path).map_err(|e| bad(format!("{name}: cannot open ({e})")))?;
    let max_lines =
        crate::limits::product(&[2, max_instants, nodes.max(1) as u64]).saturating_add(1);
    let mut lines = BoundedLines::new(std::io::BufReader::new(f), path, max_lines);
    let header = lines
        .next_line()?
        .ok_or_else(|| bad(format!("{name}: empty slot log (no header line)")))?
        .1
        .to_string();
    let cols = Columns::parse(&header, path, ny)?;
    let mut late: Vec<(u32, Observation)> = Vec::new();
    let mut instants = Instants::new(nodes, ny, max_instants);
    while let Some((ln, line)) = lines.next_line()? {
        // SIGINT/SIGTERM while a long log is read (`replay` installs the flag).
        if ln % 65_536 == 0 && estpipe_process::signal::termination_requested() {
            return Err(anyhow::Error::new(Interrupted(ln)));
        }
        if line.trim().is_empty() {
            continue;
        }
        let row = Row::split(path, ln, line);
        let fields = row.fields(&cols, nodes)?;
        instants.place(&row, &fields)?;
        let o = Observation {
            k: fields.k,
            node: fields.node as u8,
            delivered: fields.delivered,
            ny: ny as u8,
            y: row.y(&cols, fields.delivered)?,
            flags: fields.flags,
            tokens: fields.tokens,
        };
        if fields.late_after > 0 {
            // Lost at its instant; held until the instant it came after (one per row, so
            // bounded like the rows).
            late.push((fields.late_after, o));
        } else {
            instants.out.last_mut().expect("pushed above").1[fields.node] = o;
        }
    }
    Ok(SlotLog {
        instants: instants.out,
        late,
    })
}

fn bad(m: String) -> anyhow::Error {
    anyhow::Error::new(BadInput(m))
}

/// Where in a row each column the reader uses is.
struct Columns {
    k: usize,
    node: usize,
    delivered: usize,
    flags: Option<usize>,
    tokens: Option<usize>,
    late_after: Option<usize>,
    y: Vec<usize>,
}

impl Columns {
    fn parse(header: &str, path: &Path, ny: usize) -> Result<Self> {
        let name = path.display();
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        // A column the reader uses must be there once: with two `k` columns, which one is
        // the instant is a guess.
        let find = |c: &str| -> Result<Option<usize>> {
            let mut at = cols
                .iter()
                .enumerate()
                .filter(|(_, h)| **h == c)
                .map(|(i, _)| i);
            match (at.next(), at.next()) {
                (Some(i), Some(j)) => Err(bad(format!(
                    "{name} line 1: column {c:?} appears twice (columns {} and {})",
                    i + 1,
                    j + 1
                ))),
                (first, _) => Ok(first),
            }
        };
        let idx = |c: &str| -> Result<usize> {
            find(c)?.ok_or_else(|| {
                bad(format!(
                    "{name} line 1: header lacks column {c:?} (have {:?})",
                    cols.iter().take(24).collect::<Vec<_>>()
                ))
            })
        };
        let (k, node, delivered, flags) =
            (idx("k")?, idx("node")?, idx("delivered")?, find("flags")?);
        let tokens = find("tokens")?;
        let late_after = find("late_after")?;
        let y = (0..ny)
            .map(|j| idx(&format!("y_{j}")))
            .collect::<Result<_>>()?;
        Ok(Self {
            k,
            node,
            delivered,
            flags,
            tokens,
            late_after,
            y,
        })
    }
}

/// One line of the log, split into its fields; its errors name the file, line and field.
struct Row<'a> {
    path: &'a Path,
    ln: u64,
    f: Vec<&'a str>,
}

/// A row's fields but the measurement, checked on their own (not against other rows).
struct Fields {
    k: u32,
    node: usize,
    delivered: bool,
    flags: u32,
    tokens: Option<u32>,
    late_after: u32,
}

impl<'a> Row<'a> {
    fn split(path: &'a Path, ln: u64, line: &'a str) -> Self {
        Self {
            path,
            ln,
            f: line.split(',').map(str::trim).collect(),
        }
    }

    fn at(&self, field: &str, why: String) -> anyhow::Error {
        bad(format!(
            "{} line {}: {field}: {why}",
            self.path.display(),
            self.ln
        ))
    }

    fn get(&self, c: usize) -> &'a str {
        self.f.get(c).copied().unwrap_or("")
    }

    /// An optional column's value: absent or empty is `None`.
    fn optional<T: std::str::FromStr>(&self, c: Option<usize>, field: &str) -> Result<Option<T>>
    where
        T::Err: std::fmt::Display,
    {
        match c {
            Some(c) if !self.get(c).is_empty() => {
                Ok(Some(self.get(c).parse().map_err(|e| {
                    self.at(field, format!("{:?} ({e})", self.get(c)))
                })?))
            }
            _ => Ok(None),
        }
    }

    fn fields(&self, cols: &Columns, nodes: usize) -> Result<Fields> {
        let (ck, cn) = (cols.k, cols.node);
        let k: u32 = self
            .get(ck)
            .parse()
            .map_err(|e| self.at("k", format!("{:?} is not an instant ({e})", self.get(ck))))?;
        let node: usize = self
            .get(cn)
            .parse()
            .map_err(|e| self.at("node", format!("{:?} is not a node ({e})", self.get(cn))))?;
        let delivered = match self.get(cols.delivered) {
            "1" | "true" => true,
            "0" | "false" => false,
            v => return Err(self.at("delivered", format!("must be 0 or 1, got {v:?}"))),
        };
        let flags: u32 = self.optional(cols.flags, "flags")?.unwrap_or(0);
        // Tokens are read from delivered slots only: a dropped slot's field is not checked.
        let tokens: Option<u32> = if delivered {
            self.optional(cols.tokens, "tokens")?
        } else {
            None
        };
        if k == 0 {
            return Err(self.at("k", "k must be ≥ 1 (k = 0 is the prior)".into()));
        }
        let late_after: u32 = self.optional(cols.late_after, "late_after")?.unwrap_or(0);
        if late_after != 0 && late_after < k {
            return Err(self.at(
                "late_after",
                format!("{late_after} is before the slot's own instant k = {k}"),
            ));
        }
        if node >= nodes {
            return Err(self.at(
                "node",
                format!("node {node} but the scenario has {nodes} node(s)"),
            ));
        }
        Ok(Fields {
            k,
            node,
            delivered,
            flags,
            tokens,
            late_after,
        })
    }

    /// The measurement; zeros for a dropped slot, whose y fields are not read.
    fn y(&self, cols: &Columns, delivered: bool) -> Result<[f64; MAX_NY]> {
        let mut y = [0.0; MAX_NY];
        if delivered {
            for (j, &c) in cols.y.iter().enumerate() {
                y[j] = self
                    .get(c)
                    .parse()
                    .map_err(|e| self.at(&format!("y_{j}"), format!("{:?} ({e})", self.get(c))))?;
            }
        }
        Ok(y)
    }
}

/// The instants read so far, every k from 1 to the last row's, and which nodes the last
/// instant has rows for.
struct Instants {
    out: Vec<LoggedInstant>,
    /// The line of each node's row in the current instant (0: none yet).
    seen: [u64; MAX_NODES],
    nodes: usize,
    ny: usize,
    max_instants: u64,
}

impl Instants {
    fn new(nodes: usize, ny: usize, max_instants: u64) -> Self {
        Self {
            out: Vec::new(),
            seen: [0; MAX_NODES],
            nodes,
            ny,
            max_instants,
        }
    }

    /// Checks the row against the rows before it and the budget, and fills the instants up
    /// to its k (the gap as lost).
    fn place(&mut self, row: &Row<'_>, fields: &Fields) -> Result<()> {
        let (k, node, max_instants) = (fields.k, fields.node, self.max_instants);
        let last = self.out.last().map_or(0, |(lk, _)| *lk);
        if k < last {
            return Err(row.at(
                "k",
                format!("k = {k} after k = {last}; rows must be in increasing k"),
            ));
        }
        if u64::from(k) > max_instants {
            let per = size_of::<LoggedInstant>() as u64;
            return Err(row.at(
                "k",
                format!(
                    "k = {k} means replaying {k} instants (every k from 1, gaps as lost), \
                     about {} of memory; the budget holds {max_instants} instants \
                     (--max-memory MIB raises it, up to this machine's memory)",
                    crate::limits::human_bytes(u64::from(k).saturating_mul(per))
                ),
            ));
        }
        if k > last {
            self.seen = [0; MAX_NODES];
        }
        if self.seen[node] != 0 {
            return Err(row.at(
                "node",
                format!(
                    "(k = {k}, node {node}) again; line {} has it already (one row per slot)",
                    self.seen[node]
                ),
            ));
        }
        self.seen[node] = row.ln;
        self.grow_to(k, row)?;
        while self.out.last().map_or(0, |(lk, _)| *lk) < k {
            let next = self.out.last().map_or(1, |(lk, _)| lk + 1);
            let lost = self.lost(next);
            self.out.push((next, lost));
        }
        Ok(())
    }

    /// Room for k instants. Grown by doubling, but never past the budget's instants, and
    /// fallibly: a plain push doubled a 5-million-instant log to 8.4 million (3.36 GB) and
    /// aborted.
    fn grow_to(&mut self, k: u32, row: &Row<'_>) -> Result<()> {
        let out = &mut self.out;
        let need = k as usize;
        if out.capacity() < need {
            let want = need
                .max(out.capacity().saturating_mul(2))
                .min(usize::try_from(self.max_instants).unwrap_or(usize::MAX))
                .max(need);
            out.try_reserve_exact(want - out.len()).map_err(|e| {
                row.at(
                    "k",
                    format!(
                        "k = {k}: cannot allocate {want} instants ({e}); --max-memory MIB \
                         lowers the budget"
                    ),
                )
            })?;
        }
        Ok(())
    }

    /// Instant k with every node's slot lost, until a row says otherwise.
    fn lost(&self, k: u32) -> heapless::Vec<Observation, MAX_NODES> {
        let mut v = heapless::Vec::new();
        for n in 0..self.nodes {
            let _ = v.push(Observation::dropped(
                k,
                n as u8,
                self.ny as u8,
                FLAG_IPC_LOST,
            ));
        }
        v
    }
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
                tokens: None,
            },
            Observation::dropped(3, 0, 2, 16),
        ];
        write_slots(&p, &slots, 2, &[]).unwrap();
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

    /// Duplicates name both lines, a k beyond the budget is refused before its gap is
    /// filled, and every refusal is bad input naming file, line and field.
    #[test]
    fn hostile_logs_are_refused_with_file_line_and_field() {
        let dir = std::env::temp_dir().join(format!("replay-hostile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("s.csv");
        let refuse = |text: &str, max: u64| {
            std::fs::write(&p, text).unwrap();
            let e = read_slots_within(&p, 2, 1, max).unwrap_err();
            assert!(BadInput::is_in(&e), "{e:#}");
            format!("{e:#}")
        };
        let e = refuse("k,node,delivered,y_0\n1,0,1,0.5\n1,1,0,\n\n1,0,0,\n", 10);
        assert!(
            e.ends_with(
                "line 5: node: (k = 1, node 0) again; line 2 has it already (one row per slot)"
            ),
            "{e}"
        );
        // The same node at the next k is no duplicate.
        std::fs::write(&p, "k,node,delivered,y_0\n1,0,1,0.5\n2,0,1,0.25\n").unwrap();
        assert_eq!(read_slots_within(&p, 2, 1, 10).unwrap().instants.len(), 2);
        let e = refuse("k,node,delivered,y_0\n1,0,1,0.5\n11,0,0,\n", 10);
        assert!(
            e.contains("line 3: k: k = 11 means replaying 11 instants")
                && e.contains("--max-memory"),
            "{e}"
        );
        let e = refuse("k,node,delivered,y_0\n1,0,1,abc\n", 10);
        assert!(e.contains("line 2: y_0: \"abc\""), "{e}");
        let e = refuse("k,node,delivered,y_0\nx,0,1,1\n", 10);
        assert!(e.contains("line 2: k: \"x\" is not an instant"), "{e}");
        let e = refuse("k,node,delivered,y_0\n1,0,2,1\n", 10);
        assert!(e.contains("line 2: delivered: must be 0 or 1"), "{e}");
        let e = refuse("k,k,node,delivered,y_0\n1,2,0,1,1\n", 10);
        assert!(
            e.contains("line 1: column \"k\" appears twice (columns 1 and 2)"),
            "{e}"
        );
        let e = refuse("k,node,delivered,flags,y_0,flags\n1,0,1,0,1,0\n", 10);
        assert!(e.contains("column \"flags\" appears twice"), "{e}");
        let e = refuse("node,delivered\n", 10);
        assert!(e.contains("line 1: header lacks column \"k\""), "{e}");
        let e = refuse("", 10);
        assert!(e.contains("empty slot log"), "{e}");
        let e = refuse(&"0".repeat(crate::limits::MAX_LINE_BYTES + 10), 10);
        assert!(e.contains("line 1: longer than"), "{e}");
        // Lines: at most 2 · max · nodes + 1 = 5 here, blank ones included.
        let e = refuse("k,node,delivered,y_0\n\n\n\n\n\n", 1);
        assert!(e.contains("line 6: more than 5 lines"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
