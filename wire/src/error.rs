//! Two kinds of failure: a payload that cannot be used ([`WireError`]) and a peer that does
//! not follow the contract at all ([`ContractError`]).

use crate::WIRE_VERSION;

/// Why a received payload cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireError {
    /// The writer uses another contract version.
    Version {
        /// Version found in the payload.
        found: u32,
    },
    /// A field is out of range (names the field).
    Invalid(&'static str),
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Version { found } => write!(
                f,
                "wire format version {found} received, but this binary speaks version \
                 {WIRE_VERSION}: build channel-sim and ipc-runner from the same source \
                 (`cargo build --release`), or make a foreign client write version \
                 {WIRE_VERSION} (docs/wire.md, Versioning)"
            ),
            Self::Invalid(what) => write!(f, "malformed slot: {what}"),
        }
    }
}

impl std::error::Error for WireError {}

/// A service or a stream that does not follow the contract, or iceoryx2 failing underneath.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ContractError {
    /// The peer does not follow the contract (QoS, types, version, the stream's shape), or
    /// the caller asked for something the contract does not allow (a bad service prefix).
    /// One line that says what differs; a process exits with [`ContractError::EXIT_REFUSED`].
    Refused(String),
    /// iceoryx2 failed for a reason of its own (no shared memory, …).
    Transport(String),
}

impl ContractError {
    /// Exit code of a process that refuses its peer (the code of a bad command line).
    pub const EXIT_REFUSED: i32 = 2;

    /// [`ContractError::EXIT_REFUSED`] for a refusal, 1 for a transport failure.
    pub fn exit_code(&self) -> i32 {
        match self {
            Self::Refused(_) => Self::EXIT_REFUSED,
            Self::Transport(_) => 1,
        }
    }
}

impl core::fmt::Display for ContractError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Refused(m) | Self::Transport(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for ContractError {}
