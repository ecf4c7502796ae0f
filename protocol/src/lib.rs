//! Wire format between the rig firmware and the host: the interface control document.
//!
//! The host sends [`Request`]s, the device sends [`DeviceMessage`]s. Every message travels
//! in a [`Frame`] with a sequence number:
//!
//! ```text
//! body  = postcard(seq: u16 varint, msg: Request | DeviceMessage)
//! frame = COBS(body ++ CRC-32/ISO-HDLC(body) as 4 bytes little-endian) ++ 0x00
//! ```
//!
//! * [`encode_frame`] writes a frame into a caller buffer (no heap); sized with
//!   [`MAX_FRAME_SIZE`] it never fails for this crate's messages.
//! * [`Deframer`] is a sans-IO decoder: feed it bytes in chunks of any size, it yields
//!   frames, drops garbage up to the next `0x00`, never panics, and counts errors in
//!   [`DeframerStats`].
//! * [`SeqTracker`] tells the host how many device frames were lost.
//!
//! Each side keeps its own frame counter. Replies ([`DeviceMessage::Ack`],
//! [`DeviceMessage::Nack`]) echo the request's `seq`. After opening a port, send one
//! `0x00` so the peer drops any half-received frame.
//!
//! # A session
//! 1. Host: `Hello { PROTOCOL_VERSION, SCHEMA_HASH }`; device: `Info`, or
//!    `Nack(VersionMismatch)`.
//! 2. Host: `StartTelemetry { rate_hz }`; device streams `Telemetry` until `StopTelemetry`.
//! 3. Host: `Release { on: true, target_hz }`, then a `Heartbeat` every
//!    [`HEARTBEAT_INTERVAL_MS`]. Without a request for [`COMMS_TIMEOUT_MS`] the device
//!    stops vibrating (the safe state) and latches [`FaultFlags::COMMS_TIMEOUT`].
//! 4. Faults arrive unsolicited as `FaultEvent`; `GetFaults` / `ClearFaults` read and clear
//!    the latch.
//!
//! ```
//! use protocol::{DeviceDeframer, DeviceMessage, Frame, MAX_FRAME_SIZE, encode_frame};
//!
//! let mut buf = [0u8; MAX_FRAME_SIZE];
//! let wire = encode_frame(42, &DeviceMessage::Ack { seq: 7 }, &mut buf)?;
//!
//! let mut deframer = DeviceDeframer::new();
//! let mut got = None;
//! // Bytes may arrive split anywhere.
//! for chunk in wire.chunks(3) {
//!     deframer.push(chunk, |frame| got = Some(frame));
//! }
//! assert_eq!(got, Some(Ok(Frame { seq: 42, msg: DeviceMessage::Ack { seq: 7 } })));
//! assert_eq!(deframer.stats().frames_ok, 1);
//! # Ok::<(), protocol::Error>(())
//! ```
//!
//! # Versioning
//! [`PROTOCOL_VERSION`] and [`SCHEMA_HASH`] travel in [`Request::Hello`] and
//! [`DeviceInfo`]. The golden-byte tests (`src/golden.rs`) fail on any layout change;
//! when they do, update [`schema::SCHEMA`] and bump [`PROTOCOL_VERSION`].
//!
//! # Units
//! Telemetry is SI (rad/s, A, N m). [`Calibration`] uses the paper's units (N mm, mm),
//! as in its Table 2.
//!
//! # Fuzzing
//! `protocol/fuzz` is a cargo-fuzz crate (not a workspace member) with one target that
//! feeds arbitrary bytes to the deframers:
//! `cd protocol/fuzz && cargo +nightly fuzz run deframer -- -max_total_time=60`.
#![cfg_attr(not(any(test, feature = "std")), no_std)]

mod calibration;
mod capture;
mod deframer;
mod error;
mod faults;
mod flags;
mod framing;
mod link;
mod messages;
pub mod schema;
mod sequence;
mod sizes;
mod telemetry;

#[cfg(test)]
mod golden;

pub use calibration::Calibration;
pub use capture::{CAPTURE_CHUNK_SAMPLES, CaptureChunk, CaptureSample};
pub use deframer::{Deframer, DeframerStats, DeviceDeframer, RequestDeframer};
pub use error::Error;
pub use faults::FaultFlags;
#[cfg(any(test, feature = "std"))]
pub use framing::encode_frame_vec;
pub use framing::{CRC_LEN, FRAME_DELIMITER, decode_frame, encode_frame};
pub use link::{COMMS_TIMEOUT_MS, DEFAULT_BAUD_RATE, HEARTBEAT_INTERVAL_MS, MAX_TELEMETRY_RATE_HZ};
pub use messages::{
    CalibrationStatus, DeviceInfo, DeviceMessage, FirmwareVersion, Frame, NackCode, Request,
};
pub use schema::SCHEMA_HASH;
pub use sequence::SeqTracker;
pub use sizes::{
    MAX_DEVICE_FRAME_SIZE, MAX_FRAME_SIZE, MAX_MESSAGE_SIZE, MAX_REQUEST_FRAME_SIZE,
    cobs_max_encoded_len,
};
pub use telemetry::{StatusFlags, SupervisorState, TelemetrySample};

/// Version of this wire format; bump it whenever [`SCHEMA_HASH`] changes.
pub const PROTOCOL_VERSION: u16 = 1;

/// Longest board name [`DeviceInfo::board`] can carry, bytes.
pub const BOARD_NAME_LEN: usize = 16;
