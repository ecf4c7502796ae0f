//! The crate's one error type.

use core::fmt;

/// Everything that can go wrong while encoding, decoding or checking wire data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Error {
    /// The output buffer cannot hold the encoded frame.
    BufferTooSmall,
    /// A value could not be serialised (e.g. a string longer than its wire capacity).
    Serialize,
    /// A frame was longer than the deframer's buffer; its bytes were dropped up to the
    /// next delimiter.
    Overflow,
    /// The bytes between two delimiters are not valid COBS or too short to hold a CRC.
    Framing,
    /// The CRC does not match: the frame was corrupted on the line.
    Crc,
    /// The CRC matched but the body is not a message of this schema. `seq` is the
    /// sender's sequence number when it could still be read (so a reply can name it).
    Decode {
        /// Sequence number of the undecodable frame, if its header was readable.
        seq: Option<u16>,
    },
    /// A [`crate::RigParameters`] record failed its checks: the field and why.
    InvalidParameters(crate::ParameterRejection),
    /// The device speaks another protocol version or schema; the message says which side
    /// to update ([`crate::check_peer`]).
    VersionMismatch {
        /// The device's protocol version.
        device_protocol: u16,
        /// The device's schema hash, when it said (a v1 device's refusal does not).
        device_schema_hash: Option<u32>,
    },
}

impl From<crate::ParameterRejection> for Error {
    fn from(r: crate::ParameterRejection) -> Self {
        Self::InvalidParameters(r)
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BufferTooSmall => {
                write!(
                    f,
                    "output buffer too small; size it with protocol::MAX_FRAME_SIZE"
                )
            }
            Self::Serialize => write!(f, "message does not fit its wire format"),
            Self::Overflow => write!(
                f,
                "frame longer than the receive buffer was dropped; check the baud rate and that both sides use the same protocol version"
            ),
            Self::Framing => write!(
                f,
                "bytes between delimiters are not a frame (line noise or a wrong baud rate)"
            ),
            Self::Crc => write!(f, "frame CRC mismatch (corrupted on the line)"),
            Self::Decode { seq } => {
                write!(f, "frame ")?;
                if let Some(seq) = seq {
                    write!(f, "{seq} ")?;
                }
                write!(
                    f,
                    "has a valid CRC but an unknown layout; update host and firmware to the same protocol version"
                )
            }
            Self::InvalidParameters(r) => write!(
                f,
                "rig parameter {r}; fix it in the rig file (the paper's values are RigParameters::paper())"
            ),
            Self::VersionMismatch {
                device_protocol,
                device_schema_hash,
            } => crate::compat::write_mismatch(f, *device_protocol, *device_schema_hash),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for Error {}
