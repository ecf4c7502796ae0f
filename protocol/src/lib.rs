//! Wire format between the rig firmware and the host: the interface control document.
//!
//! The host sends [`Request`]s, the device sends [`DeviceMessage`]s. Every message travels
//! in a [`Frame`] with the sender's sequence number:
//!
//! ```text
//! body  = postcard(seq: u16 varint, msg: Request | DeviceMessage)
//! frame = 0x00 ++ COBS(body ++ CRC-32/ISO-HDLC(body) as 4 bytes little-endian) ++ 0x00
//! ```
//!
//! `LAYOUT.md` next to this crate's manifest gives every byte of every message, for an
//! implementation in another language.
//!
//! * [`encode_frame`] writes a frame into a caller buffer (no heap); sized with
//!   [`MAX_FRAME_SIZE`] it never fails for this crate's messages.
//! * [`Deframer`] is a sans-IO decoder: feed it bytes in chunks of any size, it yields
//!   frames, drops garbage up to the next `0x00`, never panics, and counts errors in
//!   [`DeframerStats`]. A delimiter opens and closes every frame, so a stray byte on the
//!   line costs at most the frame it touches; empty frames are ignored.
//! * [`SeqTracker`] tells the host how many device frames were lost.
//! * `session::Session` (feature `std`) is the host's sans-IO session: request matching
//!   by `seq`, retries of retry-safe requests, heartbeats, peer-version recognition, with
//!   time passed in; the serial client and the simulator's link both drive it.
//!
//! # Replies
//! Each side numbers its own frames. Every request gets exactly one
//! [`DeviceMessage::Reply`], which carries the request's frame `seq` as `request_seq`:
//! the host matches replies by it ([`DeviceMessage::reply_to`]), never by kind. Everything
//! else the device sends is unsolicited: `Telemetry`, `Health` (once a second while
//! telemetry runs), `CaptureChunk`, `CaptureDone` and `FaultEvent`. Each request knows its facts: [`Request::name`], the [`ReplyKind`] it
//! expects ([`Request::reply_kind`]; a [`Reply::Nack`] can always come instead) and
//! whether a retry after a timeout is safe ([`Request::retry_safe`]).
//!
//! After opening a port, send one `0x00` so the peer drops any half-received frame.
//!
//! # A session
//! 1. Host: `Hello { PROTOCOL_VERSION, SCHEMA_HASH }`; device: `Info`, or
//!    `Nack(VersionMismatch { device_protocol, device_schema_hash })` (see [`compat`]).
//! 2. Host: `StartTelemetry { rate_hz }`; device streams `Telemetry`, and a `Health` sample
//!    once a second, until `StopTelemetry`.
//! 3. Host: `Release { on: true, target_hz }`, then a `Heartbeat` every
//!    [`HEARTBEAT_INTERVAL_MS`]. Without an accepted request for [`COMMS_TIMEOUT_MS`] the
//!    device stops vibrating (the safe state) and latches [`FaultFlags::COMMS_TIMEOUT`].
//! 4. Faults arrive unsolicited as `FaultEvent`; `GetFaults` / `ClearFaults` read and clear
//!    the latch.
//!
//! # The release heartbeat
//! Only requests the device accepts (answered with anything but `Nack`) refresh the
//! release's comms timeout. A stream of refused or undecodable requests (a host of another
//! version, a wrong argument repeated, line noise that happens to pass the CRC) must not
//! keep the motor vibrating. The firmware core implements this rule.
//!
//! ```
//! use protocol::{DeviceDeframer, DeviceMessage, Frame, MAX_FRAME_SIZE, encode_frame};
//!
//! let mut buf = [0u8; MAX_FRAME_SIZE];
//! let wire = encode_frame(42, &DeviceMessage::ack(7), &mut buf)?;
//! assert_eq!((wire[0], wire[wire.len() - 1]), (0x00, 0x00));
//!
//! let mut deframer = DeviceDeframer::new();
//! let mut got = None;
//! // Bytes may arrive split anywhere.
//! for chunk in wire.chunks(3) {
//!     deframer.push(chunk, |frame| got = Some(frame));
//! }
//! let frame = got.unwrap()?;
//! assert_eq!(frame, Frame { seq: 42, msg: DeviceMessage::ack(7) });
//! assert_eq!(frame.msg.reply_to(), Some(7));
//! assert_eq!(deframer.stats().frames_ok, 1);
//! # Ok::<(), protocol::Error>(())
//! ```
//!
//! # Versioning
//! [`PROTOCOL_VERSION`] and [`SCHEMA_HASH`] travel in [`Request::Hello`] and
//! [`DeviceInfo`]. The hash is computed at compile time from the golden wire bytes in
//! `golden/wire.snap` ([`schema`]): any layout change fails the golden test until the
//! snapshot is regenerated (`UPDATE_GOLDEN=1 cargo test -p protocol`), and regenerating
//! changes the hash. A released layout change also bumps [`PROTOCOL_VERSION`]. A host
//! that meets another version tells the user which side to update ([`check_peer`],
//! [`version_advice`]).
//!
//! # Units
//! Telemetry is SI (rad/s, A, N m, V, degrees C). [`RigParameters`] uses the paper's units
//! (N mm, mm), as in its Table 2. Quantities a board does not sense are NaN.
//!
//! # Fuzzing
//! The top-level `fuzz/` crate (cargo-fuzz, its own workspace) holds one target per decoder;
//! `frame` feeds arbitrary bytes to the deframers: `cargo xtask fuzz`, or
//! `cd fuzz && cargo +nightly fuzz run frame -- -max_total_time=60`.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// No silent numeric narrowing on the target: every cast that can truncate, lose a sign or
// wrap is written so it cannot, or carries an `allow` with its reason.
#![deny(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

mod capture;
pub mod compat;
pub mod crc32;
mod deframer;
mod device;
mod error;
mod faults;
mod flags;
mod framing;
mod health;
mod info;
mod link;
mod parameters;
mod request;
pub mod schema;
mod sequence;
#[cfg(any(test, feature = "std"))]
pub mod session;
mod sizes;
mod stream;
mod telemetry;

#[cfg(test)]
mod golden;

pub use capture::{CAPTURE_CHUNK_SAMPLES, CaptureChunk, CaptureSample};
pub use compat::{
    HelloAnswer, LegacyV1Nack, PeerIdentity, check_peer, hello_answer, identify_peer,
    version_advice,
};
pub use deframer::{Deframer, DeframerStats, DeviceDeframer, RequestDeframer};
pub use device::{DeviceMessage, NackCode, Reply};
pub use error::Error;
pub use faults::FaultFlags;
pub use flags::FlagInfo;
#[cfg(any(test, feature = "std"))]
pub use framing::encode_frame_vec;
pub use framing::{
    CRC_LEN, FRAME_DELIMITER, FRAME_DELIMITERS, Frame, decode_body, decode_frame, encode_frame,
    frame_body,
};
pub use health::HealthSample;
pub use info::{
    BOARD_NAME_LEN, Capabilities, DeviceInfo, FIRMWARE_BUILD_LEN, FirmwareVersion,
    ParametersStatus, ResetCause,
};
pub use link::{
    BAUD_CONFIRM_MS, COMMS_TIMEOUT_MS, DEFAULT_BAUD_RATE, FAST_BAUD_RATE, FAULT_HOLD_MS,
    HEARTBEAT_INTERVAL_MS, MAX_TELEMETRY_RATE_HZ, REQUEST_WINDOW, UART_BITS_PER_BYTE,
    link_bytes_per_s,
};
pub use parameters::{ParameterField, ParameterRejection, RejectReason, RigParameters};
pub use request::{ReplyKind, Request, SessionId, SimCommand};
pub use schema::SCHEMA_HASH;
pub use sequence::SeqTracker;
pub use sizes::{
    MAX_DEVICE_FRAME_SIZE, MAX_FRAME_SIZE, MAX_MESSAGE_SIZE, MAX_REPLY_FRAME_SIZE,
    MAX_REQUEST_FRAME_SIZE, cobs_max_encoded_len, stream_rate_for_link, varint_len,
};
pub use stream::{
    MAX_STREAM_RATE_HZ, STREAM_BLOCK_SAMPLES, STREAM_DUTY_SCALE, STREAM_PACKED_MAX,
    STREAM_STATE_FAULTED, STREAM_TAU_SCALE, StreamBlock, StreamDecoder, StreamEvent, StreamSample,
    UnpackError, stream_rate_that_fits,
};
pub use telemetry::{StatusFlags, SupervisorState, TelemetrySample};

/// Version of this wire format; bump it with every released layout change (every change
/// of [`SCHEMA_HASH`] that reaches a user). v2: replies carry the request's `seq`, frames
/// open with a delimiter, rig parameters name a refused field, and identity, output-shaft,
/// supply, temperature and timing fields. v3: `DeviceInfo::time_scale`, the request window
/// ([`REQUEST_WINDOW`]), and a device that refuses
/// (never silently replaces) a value it cannot use. v4: capture samples carry the output
/// encoder (`CaptureSample::output_count`), at most 18 samples per chunk.
/// v5: drive requests carry the host session ([`SessionId`]); only the owner's requests keep a
/// release alive. v6: a drive before the current sensor's zero is measured is refused with
/// [`NackCode::CurrentZeroPending`]; a capture chunk holds at most 10 samples, what the
/// firmware sends ([`CAPTURE_CHUNK_SAMPLES`], stated once). v7: the parameter record ends
/// with the gears' profile shifts (`RigParameters::profile_shift`,
/// [`ParameterField::ProfileShift`]), so a shifted gear with Z1 + Z2 != Z3 + Z4 is stored;
/// and the continuous stream (`StartStream`, `StopStream`, [`DeviceMessage::StreamBlock`],
/// [`NackCode::StreamRate`]). v8: the link's rate is agreed after `Hello`
/// ([`DeviceInfo::max_baud`], `Request::SetBaud`, [`FAST_BAUD_RATE`]), and a stream the link
/// cannot carry beside the telemetry is refused with `StreamRate` naming the rate that fits.
pub const PROTOCOL_VERSION: u16 = 8;
