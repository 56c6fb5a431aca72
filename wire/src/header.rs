//! [`StreamHeader`]: the shape of a slot stream, carried as the iceoryx2 user header of every
//! slot (`publish_subscribe::<Slot>().user_header::<StreamHeader>()`).
//!
//! Why in every slot rather than in a start message: a runner that joins a running stream
//! (restarted after a crash, or started after the publisher) reads the shape from the first
//! slot it receives, and no message can be lost before it, so no history and no ordering
//! between two services is needed. The cost is 56 bytes written per slot in the same cache
//! lines as the slot. `docs/wire.md` ("Stream header") has the reasoning in full.

use crate::error::ContractError;
use crate::{MAX_NODES, MAX_NX, MAX_NY, WIRE_VERSION};
use iceoryx2::prelude::*;

/// Bytes of [`StreamHeader::scenario`].
pub const SCENARIO_NAME_LEN: usize = 32;

/// What a slot stream is: its nodes, dimensions, scenario and model.
///
/// The runner compares the header of the first slot of every stream with the one its own
/// scenario gives and refuses the stream when the shape (`nodes`, `nx`, `ny`) or the model
/// fingerprint differ; the scenario name is informational (two names for the same model are
/// accepted). `Default` is all zeros, the empty header (version 0) a publisher that never
/// writes it sends.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::StreamHeader")]
pub struct StreamHeader {
    /// [`WIRE_VERSION`] of the writer (0: the writer left the header empty).
    pub version: u32,
    /// Number of sensor nodes, 1..=[`MAX_NODES`].
    pub nodes: u8,
    /// State dimension, 1..=[`MAX_NX`].
    pub nx: u8,
    /// Reserved, 0.
    pub reserved: u16,
    /// Measurement dimension of every node (entries ≥ `nodes` are 0).
    pub ny: [u8; MAX_NODES],
    /// Fingerprint of the model (`docs/wire.md`, "Model fingerprint").
    pub model: u64,
    /// Scenario name, UTF-8, zero-padded (truncated on a character boundary).
    pub scenario: [u8; SCENARIO_NAME_LEN],
}

impl StreamHeader {
    /// The header of a stream of scenario `name` with `nodes` nodes, `nx` states, `ny[m]`
    /// measurements at node m and model fingerprint `model`.
    pub fn new(name: &str, nodes: usize, nx: usize, ny: &[usize], model: u64) -> Self {
        let mut h = Self {
            version: WIRE_VERSION,
            nodes: nodes.min(usize::from(u8::MAX)) as u8,
            nx: nx.min(usize::from(u8::MAX)) as u8,
            reserved: 0,
            ny: [0; MAX_NODES],
            model,
            scenario: [0; SCENARIO_NAME_LEN],
        };
        for (d, &s) in h.ny.iter_mut().zip(ny) {
            *d = s.min(usize::from(u8::MAX)) as u8;
        }
        let mut end = name.len().min(SCENARIO_NAME_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        h.scenario[..end].copy_from_slice(&name.as_bytes()[..end]);
        h
    }

    /// The scenario name (`?` when it is not UTF-8).
    pub fn scenario_name(&self) -> &str {
        let end = self
            .scenario
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(SCENARIO_NAME_LEN);
        core::str::from_utf8(&self.scenario[..end]).unwrap_or("?")
    }

    /// `ny` of the nodes the header has (at most [`MAX_NODES`]).
    pub fn ny_per_node(&self) -> &[u8] {
        &self.ny[..usize::from(self.nodes).min(MAX_NODES)]
    }

    /// `'linear' (nodes 1, nx 2, ny [1], model 0x…)`. The name comes from the publisher, so
    /// its control characters are escaped (`\n`, `\u{1b}`): an error naming it stays one
    /// line, and no escape sequence reaches the terminal.
    pub fn describe(&self) -> String {
        format!(
            "'{}' (nodes {}, nx {}, ny {:?}, model {:#018x})",
            self.scenario_name().escape_debug(),
            self.nodes,
            self.nx,
            self.ny_per_node(),
            self.model
        )
    }

    /// Whether the header itself is well-formed: the version, dimensions within the limits.
    pub fn validate(&self) -> Result<(), ContractError> {
        if self.version == 0 {
            return Err(ContractError::Refused(
                "the publisher's slots carry an empty stream header (version 0): a publisher \
                 must fill the user header of every slot (docs/wire.md, Stream header)"
                    .into(),
            ));
        }
        if self.version != WIRE_VERSION {
            return Err(ContractError::Refused(format!(
                "the publisher writes stream header version {}, but this runner speaks wire \
                 version {WIRE_VERSION} (docs/wire.md, Versioning)",
                self.version
            )));
        }
        let nodes = usize::from(self.nodes);
        let ny_ok = self.ny_per_node().iter().all(|&n| usize::from(n) <= MAX_NY)
            && self.ny[nodes.min(MAX_NODES)..].iter().all(|&n| n == 0);
        if nodes == 0
            || nodes > MAX_NODES
            || self.nx == 0
            || usize::from(self.nx) > MAX_NX
            || !ny_ok
        {
            return Err(ContractError::Refused(format!(
                "the publisher's stream header {} is outside the limits (1 ≤ nodes ≤ \
                 {MAX_NODES}, 1 ≤ nx ≤ {MAX_NX}, ny ≤ {MAX_NY}; docs/wire.md, Stream header)",
                self.describe()
            )));
        }
        Ok(())
    }

    /// Whether a stream with this header (the publisher's) can feed estimators built for
    /// `expected` (the runner's): the same nodes, nx, ny and model. The refusal is one line
    /// naming both.
    pub fn check(&self, expected: &StreamHeader) -> Result<(), ContractError> {
        self.validate()?;
        let same = self.nodes == expected.nodes
            && self.nx == expected.nx
            && self.ny == expected.ny
            && self.model == expected.model;
        if same {
            return Ok(());
        }
        Err(ContractError::Refused(format!(
            "publisher streams {} but this runner runs {}",
            self.describe(),
            expected.describe()
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn describes_and_compares_shapes() {
        let lin = StreamHeader::new("linear", 1, 2, &[1], 0xabc);
        let occ = StreamHeader::new("occlusion", 1, 3, &[2], 0xdef);
        assert_eq!(
            lin.describe(),
            "'linear' (nodes 1, nx 2, ny [1], model 0x0000000000000abc)"
        );
        assert!(lin.check(&lin).is_ok());
        let e = lin.check(&occ).unwrap_err();
        assert_eq!(e.exit_code(), ContractError::EXIT_REFUSED);
        let m = e.to_string();
        assert!(
            m.starts_with("publisher streams 'linear' (nodes 1, nx 2")
                && m.contains("but this runner runs 'occlusion' (nodes 1, nx 3, ny [2]"),
            "{m}"
        );
        assert!(!m.contains('\n'));
        // Same model under another name: accepted.
        assert!(StreamHeader::new("mine", 1, 2, &[1], 0xabc)
            .check(&lin)
            .is_ok());
        // Same shape, other model: refused.
        assert!(StreamHeader::new("linear", 1, 2, &[1], 0xabd)
            .check(&lin)
            .is_err());
    }

    #[test]
    fn empty_and_out_of_range_headers_are_refused() {
        let lin = StreamHeader::new("linear", 1, 2, &[1], 1);
        let mut empty = lin;
        empty.version = 0;
        assert!(empty.check(&lin).unwrap_err().to_string().contains("empty"));
        let mut h = lin;
        h.ny[3] = 1;
        assert!(h.validate().is_err());
        assert!(StreamHeader::new("x", 9, 2, &[1; 9], 1).validate().is_err());
        assert!(StreamHeader::new("x", 1, 2, &[5], 1).validate().is_err());
    }

    #[test]
    fn a_hostile_name_is_described_on_one_line_without_escape_sequences() {
        let h = StreamHeader::new("evil\nsecond\u{1b}[31mred", 1, 2, &[1], 1);
        let d = h.describe();
        assert!(
            d.starts_with("'evil\\nsecond\\u{1b}[31mred' (nodes 1"),
            "{d}"
        );
        assert!(!d.chars().any(char::is_control), "{d}");
    }

    #[test]
    fn names_are_truncated_on_char_boundaries() {
        let h = StreamHeader::new(&"α".repeat(17), 1, 1, &[1], 0); // 34 bytes
        assert_eq!(h.scenario_name(), "α".repeat(16));
    }
}
