//! The byte form of the payloads when they leave shared memory: what `ipc-runner bridge`
//! sends over a network (zenoh) and checks when it arrives (`docs/bridge.md`).
//!
//! Inside one host a payload is its `#[repr(C)]` memory; between hosts it is this encoding:
//! every field in declaration order, little-endian, no padding (the payloads have none), so the
//! bytes do not depend on either host's endianness or compiler. A message is a 4-byte tag
//! (the magic `"ES"`, the message [`Kind`], the wire version) followed by the payloads of
//! its kind. Decoding never trusts the bytes: a wrong length, magic, kind or version is a
//! [`NetError`], and the payloads' own checks (`Slot::validate`, `StreamHeader::validate`) run
//! before anything is written into shared memory.

use crate::{Estimate, Slot, StreamHeader, Truth, MAX_NODES, MAX_NX, MAX_NY, WIRE_VERSION};
use crate::{COV_LEN, SLOT_DATA};
use core::fmt;

/// First two bytes of every message.
pub const MAGIC: [u8; 2] = *b"ES";

/// What a message carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Kind {
    /// A [`StreamHeader`] and the [`Slot`] it came with.
    Slot = 1,
    /// A [`Truth`].
    Truth = 2,
    /// An [`Estimate`].
    Estimate = 3,
}

/// Bytes of the tag in front of every message.
pub const TAG_LEN: usize = 4;
/// Bytes of an encoded [`StreamHeader`].
pub const HEADER_LEN: usize = 56;
/// Bytes of an encoded [`Slot`].
pub const SLOT_LEN: usize = 96;
/// Bytes of an encoded [`Truth`].
pub const TRUTH_LEN: usize = 88;
/// Bytes of an encoded [`Estimate`].
pub const ESTIMATE_LEN: usize = 440;
/// Bytes of a whole slot message (tag, header, slot).
pub const SLOT_MESSAGE_LEN: usize = TAG_LEN + HEADER_LEN + SLOT_LEN;
/// Bytes of a whole truth message.
pub const TRUTH_MESSAGE_LEN: usize = TAG_LEN + TRUTH_LEN;
/// Bytes of a whole estimate message.
pub const ESTIMATE_MESSAGE_LEN: usize = TAG_LEN + ESTIMATE_LEN;

/// Why received bytes were not a message of the contract. Each is a counter of the bridge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetError {
    /// Not the length of a message of the expected kind.
    Length {
        /// Bytes received.
        found: usize,
        /// Bytes a message of that kind has.
        expected: usize,
    },
    /// Does not start with [`MAGIC`].
    Magic,
    /// A kind other than the one expected on this key.
    Kind(u8),
    /// Another [`WIRE_VERSION`] (in the tag or a payload).
    Version(u32),
    /// The payload is out of its ranges (the reason names the field).
    Invalid(&'static str),
}

impl NetError {
    /// A short stable name, used as the counter's key in reports.
    pub fn reason(&self) -> &'static str {
        match self {
            Self::Length { .. } => "length",
            Self::Magic => "magic",
            Self::Kind(_) => "kind",
            Self::Version(_) => "version",
            Self::Invalid(_) => "invalid",
        }
    }
}

impl fmt::Display for NetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Length { found, expected } => {
                write!(f, "message of {found} bytes, expected {expected}")
            }
            Self::Magic => write!(f, "message does not start with \"ES\""),
            Self::Kind(k) => write!(f, "message kind {k} not expected here"),
            Self::Version(v) => write!(
                f,
                "wire version {v}, this side speaks {WIRE_VERSION} (docs/wire.md, Versioning)"
            ),
            Self::Invalid(what) => write!(f, "payload out of range: {what}"),
        }
    }
}

impl std::error::Error for NetError {}

/// Little-endian field writer over a fixed buffer.
struct Writer<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        self.buf[self.at..self.at + b.len()].copy_from_slice(b);
        self.at += b.len();
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.bytes(&x.to_bits().to_le_bytes());
        }
    }
}

/// Little-endian field reader; the caller has checked the length.
struct Reader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0; N];
        out.copy_from_slice(&self.buf[self.at..self.at + N]);
        self.at += N;
        out
    }
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
    fn f64s<const N: usize>(&mut self) -> [f64; N] {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = f64::from_bits(self.u64());
        }
        out
    }
}

fn tag(w: &mut Writer<'_>, kind: Kind) {
    w.bytes(&MAGIC);
    w.u8(kind as u8);
    // The tag's version byte: a peer of another version is refused before its payload is read.
    w.u8(WIRE_VERSION as u8);
}

fn check_tag(buf: &[u8], kind: Kind, len: usize) -> Result<(), NetError> {
    if buf.len() != len {
        return Err(NetError::Length {
            found: buf.len(),
            expected: len,
        });
    }
    if buf[..2] != MAGIC {
        return Err(NetError::Magic);
    }
    if buf[2] != kind as u8 {
        return Err(NetError::Kind(buf[2]));
    }
    if u32::from(buf[3]) != WIRE_VERSION {
        return Err(NetError::Version(u32::from(buf[3])));
    }
    Ok(())
}

fn put_header(w: &mut Writer<'_>, h: &StreamHeader) {
    w.u32(h.version);
    w.u8(h.nodes);
    w.u8(h.nx);
    w.u16(h.reserved);
    w.bytes(&h.ny);
    w.u64(h.model);
    w.bytes(&h.scenario);
}

fn get_header(r: &mut Reader<'_>) -> StreamHeader {
    StreamHeader {
        version: r.u32(),
        nodes: r.u8(),
        nx: r.u8(),
        reserved: r.u16(),
        ny: r.take::<MAX_NODES>(),
        model: r.u64(),
        scenario: r.take(),
    }
}

fn put_slot(w: &mut Writer<'_>, s: &Slot) {
    w.u32(s.version);
    w.u32(s.kind);
    w.u64(s.stream_id);
    w.u64(s.seq);
    w.u32(s.k);
    w.u8(s.node);
    w.u8(s.nodes);
    w.u8(s.ny);
    w.u8(s.delivered);
    w.u32(s.flags);
    w.u32(s.tokens);
    w.u64(s.send_ns);
    w.u64(s.period_ns);
    w.u64(s.stream_start_ns);
    w.f64s(&s.y);
}

fn get_slot(r: &mut Reader<'_>) -> Slot {
    Slot {
        version: r.u32(),
        kind: r.u32(),
        stream_id: r.u64(),
        seq: r.u64(),
        k: r.u32(),
        node: r.u8(),
        nodes: r.u8(),
        ny: r.u8(),
        delivered: r.u8(),
        flags: r.u32(),
        tokens: r.u32(),
        send_ns: r.u64(),
        period_ns: r.u64(),
        stream_start_ns: r.u64(),
        y: r.f64s::<MAX_NY>(),
    }
}

/// The message of one slot and the stream header it was sent with.
pub fn encode_slot(h: &StreamHeader, s: &Slot) -> [u8; SLOT_MESSAGE_LEN] {
    let mut buf = [0; SLOT_MESSAGE_LEN];
    let mut w = Writer {
        buf: &mut buf,
        at: 0,
    };
    tag(&mut w, Kind::Slot);
    put_header(&mut w, h);
    put_slot(&mut w, s);
    debug_assert_eq!(w.at, SLOT_MESSAGE_LEN);
    buf
}

/// A slot message back, checked: the tag, the header's own ranges, the slot's ranges, and that
/// the slot agrees with its header (node count; a delivered measurement has the node's `ny`).
pub fn decode_slot(buf: &[u8]) -> Result<(StreamHeader, Slot), NetError> {
    check_tag(buf, Kind::Slot, SLOT_MESSAGE_LEN)?;
    let mut r = Reader {
        buf: &buf[TAG_LEN..],
        at: 0,
    };
    let h = get_header(&mut r);
    let s = get_slot(&mut r);
    if h.version != WIRE_VERSION {
        return Err(NetError::Version(h.version));
    }
    h.validate()
        .map_err(|_| NetError::Invalid("stream header"))?;
    s.validate().map_err(|e| match e {
        crate::WireError::Version { found } => NetError::Version(found),
        crate::WireError::Invalid(what) => NetError::Invalid(what),
    })?;
    if s.kind == SLOT_DATA {
        if s.nodes != h.nodes {
            return Err(NetError::Invalid("slot's nodes ≠ stream header's"));
        }
        if s.delivered == 1 && s.ny != h.ny[usize::from(s.node)] {
            return Err(NetError::Invalid(
                "slot's ny ≠ stream header's ny of its node",
            ));
        }
        if s.delivered == 1 && !s.y[..usize::from(s.ny)].iter().all(|v| v.is_finite()) {
            return Err(NetError::Invalid("non-finite measurement"));
        }
    }
    Ok((h, s))
}

/// The message of one truth sample.
pub fn encode_truth(t: &Truth) -> [u8; TRUTH_MESSAGE_LEN] {
    let mut buf = [0; TRUTH_MESSAGE_LEN];
    let mut w = Writer {
        buf: &mut buf,
        at: 0,
    };
    tag(&mut w, Kind::Truth);
    w.u32(t.version);
    w.u32(t.k);
    w.u64(t.stream_id);
    w.u32(t.nx);
    w.u32(t.reserved);
    w.f64s(&t.x);
    buf
}

/// A truth message back, checked (tag, version, `nx`).
pub fn decode_truth(buf: &[u8]) -> Result<Truth, NetError> {
    check_tag(buf, Kind::Truth, TRUTH_MESSAGE_LEN)?;
    let mut r = Reader {
        buf: &buf[TAG_LEN..],
        at: 0,
    };
    let t = Truth {
        version: r.u32(),
        k: r.u32(),
        stream_id: r.u64(),
        nx: r.u32(),
        reserved: r.u32(),
        x: r.f64s::<MAX_NX>(),
    };
    if t.version != WIRE_VERSION {
        return Err(NetError::Version(t.version));
    }
    if t.nx == 0 || t.nx as usize > MAX_NX {
        return Err(NetError::Invalid("truth nx out of 1..=MAX_NX"));
    }
    Ok(t)
}

/// The message of one estimate.
pub fn encode_estimate(e: &Estimate) -> [u8; ESTIMATE_MESSAGE_LEN] {
    let mut buf = [0; ESTIMATE_MESSAGE_LEN];
    let mut w = Writer {
        buf: &mut buf,
        at: 0,
    };
    tag(&mut w, Kind::Estimate);
    w.u32(e.version);
    w.u32(e.k);
    w.u64(e.stream_id);
    w.u64(e.seq);
    w.u32(e.estimator);
    w.u32(e.nx);
    w.bytes(&e.name);
    w.u32(e.status);
    w.u32(e.cov_kind);
    w.f64s(&e.x);
    w.f64s(&e.p);
    w.u64(e.slot_send_ns);
    w.u64(e.receive_ns);
    w.u64(e.step_done_ns);
    w.u32(e.late_folded);
    w.u32(e.revised_from);
    buf
}

/// An estimate message back, checked (tag, version, `nx`, status and covariance kind).
pub fn decode_estimate(buf: &[u8]) -> Result<Estimate, NetError> {
    check_tag(buf, Kind::Estimate, ESTIMATE_MESSAGE_LEN)?;
    let mut r = Reader {
        buf: &buf[TAG_LEN..],
        at: 0,
    };
    let e = Estimate {
        version: r.u32(),
        k: r.u32(),
        stream_id: r.u64(),
        seq: r.u64(),
        estimator: r.u32(),
        nx: r.u32(),
        name: r.take(),
        status: r.u32(),
        cov_kind: r.u32(),
        x: r.f64s::<MAX_NX>(),
        p: r.f64s::<COV_LEN>(),
        slot_send_ns: r.u64(),
        receive_ns: r.u64(),
        step_done_ns: r.u64(),
        late_folded: r.u32(),
        revised_from: r.u32(),
    };
    if e.version != WIRE_VERSION {
        return Err(NetError::Version(e.version));
    }
    if e.nx as usize > MAX_NX {
        return Err(NetError::Invalid("estimate nx > MAX_NX"));
    }
    if e.status > crate::STATUS_NONE_YET {
        return Err(NetError::Invalid("estimate status"));
    }
    if e.cov_kind > crate::COV_BOUND {
        return Err(NetError::Invalid("estimate cov_kind"));
    }
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::size_of;

    fn header() -> StreamHeader {
        StreamHeader::new("occlusion", 2, 2, &[1, 1], 0x1234_5678_9abc_def0)
    }

    fn slot() -> Slot {
        let mut s = Slot::data(3, 1, 2, 0xfeed);
        s.ny = 1;
        s.delivered = 1;
        s.flags = crate::FLAG_TRIGGERED;
        s.send_ns = 17;
        s.period_ns = 10_000_000;
        s.stream_start_ns = 5;
        s.y[0] = -0.1;
        s
    }

    #[test]
    fn lengths_are_the_in_memory_sizes() {
        assert_eq!(HEADER_LEN, size_of::<StreamHeader>());
        assert_eq!(SLOT_LEN, size_of::<Slot>());
        assert_eq!(TRUTH_LEN, size_of::<Truth>());
        assert_eq!(ESTIMATE_LEN, size_of::<Estimate>());
    }

    #[test]
    fn every_payload_round_trips_bit_for_bit() {
        let (h, s) = (header(), slot());
        assert_eq!(decode_slot(&encode_slot(&h, &s)).unwrap(), (h, s));
        let mut x = [0.0; MAX_NX];
        x[..2].copy_from_slice(&[1.0e-300, -f64::MAX]);
        let t = Truth::new(4, 9, 2, &x);
        assert_eq!(decode_truth(&encode_truth(&t)).unwrap(), t);
        let mut e = Estimate::none_yet(2, *b"adf\0\0\0\0\0\0\0\0\0\0\0\0\0");
        e.k = 7;
        e.nx = 2;
        e.status = crate::STATUS_OK;
        e.cov_kind = crate::COV_ESTIMATE;
        e.x[..2].copy_from_slice(&[0.5, f64::MIN_POSITIVE]);
        e.p[..3].copy_from_slice(&[1.0, 0.25, 2.0]);
        e.slot_send_ns = 1;
        e.receive_ns = 2;
        e.step_done_ns = 3;
        let back = decode_estimate(&encode_estimate(&e)).unwrap();
        // Unused covariance entries are NaN, which PartialEq never equals: compare the bits of
        // every field through the encoding, and the fields that are numbers directly.
        assert_eq!(encode_estimate(&back), encode_estimate(&e));
        assert_eq!(
            (back.k, back.nx, &back.x[..2], &back.p[..3]),
            (7, 2, &e.x[..2], &e.p[..3])
        );
    }

    #[test]
    fn the_encoding_is_little_endian_field_by_field() {
        let m = encode_slot(&header(), &slot());
        assert_eq!(&m[..4], &[b'E', b'S', Kind::Slot as u8, WIRE_VERSION as u8]);
        // Header version, then nodes and nx.
        assert_eq!(&m[4..8], &WIRE_VERSION.to_le_bytes());
        assert_eq!((m[8], m[9]), (2, 2));
        // The slot's k at its offset in the payload (24), node 1 right after it.
        let at = TAG_LEN + HEADER_LEN;
        assert_eq!(&m[at + 24..at + 28], &3u32.to_le_bytes());
        assert_eq!(m[at + 28], 1);
        assert_eq!(&m[at + 64..at + 72], &(-0.1f64).to_bits().to_le_bytes());
    }

    #[test]
    fn damaged_messages_are_refused_with_a_reason() {
        let good = encode_slot(&header(), &slot());
        assert_eq!(
            decode_slot(&good[..good.len() - 1]).unwrap_err().reason(),
            "length"
        );
        let mut m = good;
        m[0] = b'X';
        assert_eq!(decode_slot(&m).unwrap_err(), NetError::Magic);
        let mut m = good;
        m[2] = Kind::Truth as u8;
        assert_eq!(decode_slot(&m).unwrap_err(), NetError::Kind(2));
        let mut m = good;
        m[3] = 99;
        assert_eq!(decode_slot(&m).unwrap_err(), NetError::Version(99));
        // A slot whose measurement is not its node's ny, a node out of range, a NaN: refused.
        let h = header();
        let mut s = slot();
        s.ny = 2;
        assert_eq!(
            decode_slot(&encode_slot(&h, &s)).unwrap_err().reason(),
            "invalid"
        );
        let mut s = slot();
        s.node = 2;
        s.seq += 1;
        assert!(decode_slot(&encode_slot(&h, &s)).is_err());
        let mut s = slot();
        s.y[0] = f64::NAN;
        assert_eq!(
            decode_slot(&encode_slot(&h, &s)).unwrap_err().reason(),
            "invalid"
        );
        let t = Truth::new(1, 1, 0, &[0.0; MAX_NX]);
        assert!(decode_truth(&encode_truth(&t)).is_err());
    }

    #[test]
    fn random_bytes_never_panic() {
        // A fixed xorshift stream: every length up to one past the longest message, random
        // content, and valid tags with random payloads.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut accepted = 0;
        for i in 0..20_000 {
            let len = (next() % (ESTIMATE_MESSAGE_LEN as u64 + 2)) as usize;
            let mut buf: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if len >= TAG_LEN && i % 2 == 0 {
                buf[..2].copy_from_slice(&MAGIC);
                buf[2] = 1 + (i % 3) as u8;
                buf[3] = WIRE_VERSION as u8;
            }
            accepted += usize::from(decode_slot(&buf).is_ok());
            let _ = decode_truth(&buf);
            let _ = decode_estimate(&buf);
        }
        // Random payloads essentially never pass the slot checks (version field of 4 bytes).
        assert_eq!(accepted, 0);
    }
}
