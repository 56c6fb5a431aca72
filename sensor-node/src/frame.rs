//! The frames of the serial link between a sensor node and its gateway (docs/sensor-node.md,
//! "Frame format").
//!
//! A frame is one message in postcard's encoding (its serde data model, fixed-width
//! little-endian `f64`, varint integers), followed by the CRC-32 (ISO-HDLC, the Ethernet/zlib
//! polynomial) of those bytes, little-endian, the whole COBS-encoded and ended by one `0x00`.
//! COBS makes `0x00` the only delimiter, so a receiver that lost bytes resynchronises at the next
//! one; the CRC catches flipped bits and truncation; postcard's decoder refuses anything that is
//! not exactly one message. Nothing here allocates or panics, whatever the bytes.

use serde::{Deserialize, Serialize};

/// The version of this frame format, carried by [`ToNode::Configure`] and echoed by
/// [`FromNode::Ready`]: a node refuses a configuration of another version.
pub const LINK_VERSION: u8 = 1;

/// Measurement entries a sample carries (the wire's `MAX_NY`; entries past the node's `ny`
/// are 0).
pub const MAX_NY: usize = 4;

/// The frame delimiter.
pub const DELIMITER: u8 = 0;

/// The longest frame either side writes, delimiter included (a configuration, the largest
/// message, is well under it). A receiver drops a longer one as corrupt.
pub const MAX_FRAME: usize = 192;

/// The bytes a message may take before its CRC and the COBS encoding.
const MAX_MESSAGE: usize = MAX_FRAME - 4 - 4;

/// The CRC of every frame (CRC-32/ISO-HDLC with a 256-entry table, 1 KiB of flash).
const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// What the gateway sends a node.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToNode {
    /// The node's protocol and parameters, before the first sample (answered by
    /// [`FromNode::Ready`] or [`FromNode::Refused`]). A configured node refuses another.
    Configure(NodeConfig),
    /// The raw sample of one instant (what the node's ADC would read), answered by
    /// [`FromNode::Decision`]. Sent again with the same `k` (the gateway received no valid
    /// answer), it is answered with the same decision, the protocol is not stepped twice.
    Sample(Sample),
    /// End of the run: answered by [`FromNode::Stats`], then the node stops.
    Finish,
}

/// One instant's raw sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Sampling instant k (consecutive from the first sample on).
    pub k: u32,
    /// The sensor's raw measurement z_k (entries past `ny` are 0).
    pub z: [f64; MAX_NY],
    /// The shared token bucket's level ξ_k left by the previous instant's update (seed 004,
    /// eq. 17), which the gateway keeps for all nodes; 0 and unused for the other schedules.
    pub level: u32,
}

/// A node's configuration: what it censors and how it schedules its transmissions.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeConfig {
    /// [`LINK_VERSION`] of the gateway.
    pub version: u8,
    /// The node's index (0-based) among the gateway's nodes.
    pub node: u8,
    /// Entries of the measurement (1..=[`MAX_NY`]).
    pub ny: u8,
    /// Tobit censoring thresholds τ (seed 004, eq. 2), entries past `ny` as the simulator
    /// pads them; `None`: no censoring.
    pub censor: Option<[f64; MAX_NY]>,
    /// When a measurement is transmitted.
    pub schedule: Schedule,
}

/// A node's transmission schedule.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Schedule {
    /// Every instant.
    Always,
    /// Seed 003's token bucket (eqs. 2-3): rate `a`, cost `b`, capacity `s`, level `z0`.
    TokenBucket {
        /// Token rate a.
        a: u32,
        /// Transmission cost b.
        b: u32,
        /// Capacity S.
        s: u32,
        /// Initial level z₀.
        z0: u32,
    },
    /// Seed 004's dynamic event trigger (eqs. 11-15) with the node's share of a token bucket
    /// shared by `nodes` nodes (eqs. 16-18; the level arrives with every sample).
    EventTrigger {
        /// σ.
        sigma: f64,
        /// χ.
        chi: f64,
        /// λ.
        lambda: f64,
        /// η₀.
        eta0: f64,
        /// Accept λχ ≤ 1 (the paper's own example needs it; `EventTriggerConfig`).
        allow_paper_violation: bool,
        /// The initial reference ȳ (τ in seed 004), padded as `censor`.
        reference: [f64; MAX_NY],
        /// The node's transmission cost c_m.
        cost: u32,
        /// Nodes sharing the bucket, L.
        nodes: u8,
    },
}

/// What a node sends its gateway.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum FromNode {
    /// Configured, ready for samples: the node's index and [`LINK_VERSION`].
    Ready {
        /// The configured node index.
        node: u8,
        /// The node's frame-format version.
        version: u8,
    },
    /// The node refused a message it could decode (a configuration it cannot run, a sample
    /// out of order or not finite): what and why.
    Refused {
        /// The instant of a refused sample, 0 otherwise.
        k: u32,
        /// Why.
        reason: Refusal,
    },
    /// The decision of instant k.
    Decision(Decision),
    /// The node's own figures, the answer to [`ToNode::Finish`].
    Stats(NodeStats),
}

/// Why a node refused a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Refusal {
    /// A configuration of another [`LINK_VERSION`].
    Version,
    /// Parameters the protocol refuses (estimator-core's validation).
    Config,
    /// A configuration after the node was configured, or a sample before it was.
    State,
    /// A sample whose k is neither the last decided one nor the next.
    OutOfOrder,
    /// A sample the protocol refuses (non-finite).
    Sample,
}

/// One instant's decision, with the measurement as transmitted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    /// Sampling instant k.
    pub k: u32,
    /// The measurement was transmitted.
    pub sent: bool,
    /// The event trigger fired (α = 1, seed 004 eq. 15).
    pub triggered: bool,
    /// Withheld for lack of tokens (seed 003: μ_k < 0; seed 004: fired but β = 0).
    pub blocked: bool,
    /// A component was censored (seed 004, eq. 2).
    pub censored: bool,
    /// The measurement as transmitted (censored components at τ); all 0 when not sent.
    pub y: [f64; MAX_NY],
}

/// A node's counters, reported at the end of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeStats {
    /// Frames received and decoded.
    pub frames: u32,
    /// Frames received that failed COBS, CRC or decoding (counted and skipped).
    pub bad_frames: u32,
    /// Instants decided (each once).
    pub decisions: u32,
    /// Of those, transmitted.
    pub sent: u32,
    /// Decisions repeated for a sample received again.
    pub repeats: u32,
    /// Messages refused ([`FromNode::Refused`]).
    pub refused: u32,
    /// Peak stack use in bytes (0 where not measured).
    pub stack_peak: u32,
}

/// Why bytes are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Not valid COBS (a delimiter inside, a code past the end).
    Cobs,
    /// Too short to hold a CRC, or the CRC does not match.
    Crc,
    /// The CRC matches but the bytes are not exactly one message.
    Decode,
    /// Longer than [`MAX_FRAME`].
    TooLong,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Cobs => "not valid COBS",
            Self::Crc => "CRC mismatch or truncated",
            Self::Decode => "not one message of the link",
            Self::TooLong => "longer than the longest frame",
        })
    }
}

/// Encodes `msg` into `out` as one frame, delimiter included; the frame's length, or
/// `None` if `out` is too short (never with [`MAX_FRAME`] bytes).
pub fn encode<M: Serialize>(msg: &M, out: &mut [u8]) -> Option<usize> {
    let mut raw = [0u8; MAX_MESSAGE + 4];
    let used = postcard::to_slice_crc32(msg, &mut raw, CRC.digest())
        .ok()?
        .len();
    let n = cobs::try_encode(&raw[..used], out).ok()?;
    *out.get_mut(n)? = DELIMITER;
    Some(n + 1)
}

/// Decodes one frame's bytes (without the delimiter) in place.
pub fn decode<'a, M: Deserialize<'a>>(frame: &'a mut [u8]) -> Result<M, FrameError> {
    if frame.len() >= MAX_FRAME {
        return Err(FrameError::TooLong);
    }
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
    let bytes = &frame[..n];
    if bytes.len() < 4 {
        return Err(FrameError::Crc);
    }
    // Check the CRC first, so that a corrupt frame is a CRC error, not a decoding one.
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    if CRC.checksum(body).to_le_bytes() != tail {
        return Err(FrameError::Crc);
    }
    match postcard::take_from_bytes::<M>(body) {
        Ok((m, [])) => Ok(m),
        _ => Err(FrameError::Decode),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> NodeConfig {
        NodeConfig {
            version: LINK_VERSION,
            node: 2,
            ny: 2,
            censor: Some([0.0, 0.0, -f64::MAX, -f64::MAX]),
            schedule: Schedule::EventTrigger {
                sigma: 0.3,
                chi: 5.0,
                lambda: 0.1,
                eta0: 1.5,
                allow_paper_violation: true,
                reference: [0.0, 0.0, -f64::MAX, -f64::MAX],
                cost: 3,
                nodes: 3,
            },
        }
    }

    #[test]
    fn every_message_round_trips_and_fits() {
        let msgs = [
            ToNode::Configure(config()),
            ToNode::Sample(Sample {
                k: u32::MAX,
                z: [f64::MAX, -0.0, f64::MIN_POSITIVE, 1e-300],
                level: u32::MAX,
            }),
            ToNode::Finish,
        ];
        for m in msgs {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(&m, &mut buf).expect("fits");
            assert_eq!(buf[n - 1], DELIMITER);
            assert!(!buf[..n - 1].contains(&DELIMITER), "COBS leaves no zero");
            assert_eq!(decode::<ToNode>(&mut buf[..n - 1]), Ok(m));
        }
        let back = FromNode::Decision(Decision {
            k: 7,
            sent: true,
            triggered: true,
            blocked: false,
            censored: true,
            y: [0.0, 1.25, 0.0, 0.0],
        });
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(&back, &mut buf).unwrap();
        assert_eq!(decode::<FromNode>(&mut buf[..n - 1]), Ok(back));
    }

    #[test]
    fn the_crc_is_the_iso_hdlc_one() {
        // The check value of CRC-32/ISO-HDLC (the catalogue's "123456789" test vector).
        assert_eq!(CRC.checksum(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn every_single_bit_flip_and_every_truncation_is_refused() {
        let m = ToNode::Sample(Sample {
            k: 1234,
            z: [0.5, -2.25, 0.0, 0.0],
            level: 11,
        });
        let mut good = [0u8; MAX_FRAME];
        let n = encode(&m, &mut good).unwrap() - 1;
        for bit in 0..n * 8 {
            let mut f = good;
            f[bit / 8] ^= 1 << (bit % 8);
            // CRC-32 detects every error burst up to 32 bits; COBS may also refuse first.
            assert!(decode::<ToNode>(&mut f[..n]).is_err(), "bit {bit}");
        }
        for len in 0..n {
            let mut f = good;
            assert!(decode::<ToNode>(&mut f[..len]).is_err(), "length {len}");
        }
        let mut long = [1u8; MAX_FRAME + 8];
        assert_eq!(decode::<ToNode>(&mut long), Err(FrameError::TooLong));
    }

    #[test]
    fn a_valid_crc_around_the_wrong_message_is_a_decode_error() {
        let mut buf = [0u8; MAX_FRAME];
        // A FromNode frame is not a ToNode message (variant 3 with a Stats body is no
        // ToNode), and trailing bytes after one message are refused.
        let n = encode(&FromNode::Stats(NodeStats::default()), &mut buf).unwrap();
        assert_eq!(decode::<ToNode>(&mut buf[..n - 1]), Err(FrameError::Decode));
        let n = encode(&(ToNode::Finish, 7u8), &mut buf).unwrap();
        assert_eq!(decode::<ToNode>(&mut buf[..n - 1]), Err(FrameError::Decode));
    }
}

#[cfg(test)]
mod sizes {
    use super::*;

    /// The lengths docs/sensor-node.md gives, delimiter included.
    #[test]
    fn frame_lengths_on_the_line() {
        let mut buf = [0u8; MAX_FRAME];
        let s = |k, level| {
            ToNode::Sample(Sample {
                k,
                z: [1.5, -0.25, 0.0, 0.0],
                level,
            })
        };
        let len = |m: &dyn Fn(&mut [u8]) -> Option<usize>, b: &mut [u8]| m(b).unwrap();
        let small = len(&|b| encode(&s(5, 0), b), &mut buf);
        let large = len(&|b| encode(&s(2000, 30), b), &mut buf);
        let d = |k, sent| {
            FromNode::Decision(Decision {
                k,
                sent,
                triggered: sent,
                blocked: false,
                censored: false,
                y: if sent {
                    [1.5, -0.25, 0.0, 0.0]
                } else {
                    [0.0; 4]
                },
            })
        };
        let dec = len(&|b| encode(&d(2000, true), b), &mut buf);
        let config = len(
            &|b| {
                encode(
                    &ToNode::Configure(NodeConfig {
                        version: LINK_VERSION,
                        node: 7,
                        ny: 4,
                        censor: Some([-f64::MAX; 4]),
                        schedule: Schedule::EventTrigger {
                            sigma: 0.3,
                            chi: 5.0,
                            lambda: 0.1,
                            eta0: 1.5,
                            allow_paper_violation: true,
                            reference: [-f64::MAX; 4],
                            cost: u32::MAX,
                            nodes: 8,
                        },
                    }),
                    b,
                )
            },
            &mut buf,
        );
        assert_eq!((small, large, dec), (41, 42, 45));
        assert!(config < MAX_FRAME, "{config}");
    }
}
