//! Device-to-host messages: replies, each naming the request it answers, and unsolicited
//! streams.
//!
//! Variant order is the wire discriminant: append new variants at the end only. The
//! prefix that answers `Hello` never moves: `DeviceMessage::Reply` is variant 0,
//! `Reply::Info` 0 and `Reply::Nack` 1, `NackCode::VersionMismatch` 0, and `DeviceInfo`
//! starts with `protocol_version, schema_hash`.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::sizes::{TAG, U16, U32};
use crate::{
    CaptureChunk, DeviceInfo, FaultFlags, HealthSample, ParameterRejection, ReplyKind,
    RigParameters, StreamBlock, TelemetrySample,
};

/// Device-to-host messages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// The device has no heap: a capture chunk (`CAPTURE_CHUNK_SAMPLES`, 10 samples, 184 bytes in
// memory) is built in place like every message.
#[allow(clippy::large_enum_variant)]
#[non_exhaustive]
pub enum DeviceMessage {
    /// The answer to the request whose frame carried `request_seq`. Every request gets
    /// exactly one.
    Reply {
        /// The answered request's frame sequence number.
        request_seq: u16,
        /// The answer.
        reply: Reply,
    },
    /// A periodic sample (unsolicited, after `StartTelemetry`).
    Telemetry(TelemetrySample),
    /// Part of a capture upload (unsolicited, after `StartCapture`).
    CaptureChunk(CaptureChunk),
    /// A capture upload is complete.
    CaptureDone {
        /// The capture's id.
        capture_id: u16,
        /// Samples sent in all chunks.
        total_samples: u32,
        /// Sample rate, Hz (the rate `StartCapture` asked: the device never changes it).
        sample_rate_hz: u16,
    },
    /// New faults became active (sent once, when they rise).
    FaultEvent {
        /// The faults that rose.
        flags: FaultFlags,
        /// Device clock when they rose, microseconds since boot.
        device_time_us: u64,
    },
    /// Supply, temperature, control-step timing and link counters, once per second while
    /// telemetry runs (unsolicited).
    Health(HealthSample),
    /// [`crate::STREAM_BLOCK_SAMPLES`] consecutive samples of the continuous stream
    /// (unsolicited, after `StartStream`).
    StreamBlock(StreamBlock),
}

impl DeviceMessage {
    /// Largest serialised size, bytes (a stream block of worst-case samples).
    pub const MAX_WIRE_SIZE: usize = TAG + StreamBlock::MAX_WIRE_SIZE;

    /// A reply to the request with frame sequence number `request_seq`.
    pub const fn reply(request_seq: u16, reply: Reply) -> Self {
        Self::Reply { request_seq, reply }
    }

    /// `Ack` for request `request_seq`.
    pub const fn ack(request_seq: u16) -> Self {
        Self::reply(request_seq, Reply::Ack)
    }

    /// `Nack(code)` for request `request_seq`.
    pub const fn nack(request_seq: u16, code: NackCode) -> Self {
        Self::reply(request_seq, Reply::Nack(code))
    }

    /// The sequence number of the request this message answers; `None` for unsolicited
    /// messages (telemetry, health, capture data, fault events).
    pub const fn reply_to(&self) -> Option<u16> {
        match self {
            Self::Reply { request_seq, .. } => Some(*request_seq),
            _ => None,
        }
    }

    /// The reply, if this message is one.
    pub const fn as_reply(&self) -> Option<&Reply> {
        match self {
            Self::Reply { reply, .. } => Some(reply),
            _ => None,
        }
    }

    /// The answered request's sequence number and the reply, if this message is one.
    pub fn into_reply(self) -> Option<(u16, Reply)> {
        match self {
            Self::Reply { request_seq, reply } => Some((request_seq, reply)),
            _ => None,
        }
    }

    /// The message's name, e.g. `Telemetry`, or the reply's (`Ack`, `Nack`, ...).
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Reply { reply, .. } => reply.name(),
            Self::Telemetry(_) => "Telemetry",
            Self::CaptureChunk(_) => "CaptureChunk",
            Self::CaptureDone { .. } => "CaptureDone",
            Self::FaultEvent { .. } => "FaultEvent",
            Self::Health(_) => "Health",
            Self::StreamBlock(_) => "StreamBlock",
        }
    }
}

/// The answer to one request (inside [`DeviceMessage::Reply`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// The device has no heap: messages are built in place in static buffers.
#[allow(clippy::large_enum_variant)]
#[non_exhaustive]
pub enum Reply {
    /// Identity and versions; answers `Hello` and `GetInfo`.
    Info(DeviceInfo),
    /// The request was refused; it had no effect.
    Nack(NackCode),
    /// The request was accepted.
    Ack,
    /// Fault state; answers `GetFaults` and `ClearFaults` (after clearing).
    Faults {
        /// Faults whose condition is present now.
        active: FaultFlags,
        /// Faults latched since the last clear (the motor stays off while non-empty).
        latched: FaultFlags,
    },
    /// The active rig parameters; answers `GetParameters`.
    Parameters(RigParameters),
}

impl Reply {
    /// Largest serialised size, bytes (a parameter record).
    pub const MAX_WIRE_SIZE: usize = TAG + RigParameters::MAX_WIRE_SIZE;

    /// The kind of an accepting reply; `None` for `Nack`.
    pub const fn kind(&self) -> Option<ReplyKind> {
        match self {
            Self::Info(_) => Some(ReplyKind::Info),
            Self::Nack(_) => None,
            Self::Ack => Some(ReplyKind::Ack),
            Self::Faults { .. } => Some(ReplyKind::Faults),
            Self::Parameters(_) => Some(ReplyKind::Parameters),
        }
    }

    /// The reply's name, e.g. `Ack`.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Info(_) => "Info",
            Self::Nack(_) => "Nack",
            Self::Ack => "Ack",
            Self::Faults { .. } => "Faults",
            Self::Parameters(_) => "Parameters",
        }
    }
}

/// Why a request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum NackCode {
    /// `Hello` named another protocol version or schema; carries the device's own, so the
    /// host can say which side to update ([`crate::check_peer`]).
    VersionMismatch {
        /// The device's [`crate::PROTOCOL_VERSION`].
        device_protocol: u16,
        /// The device's [`crate::SCHEMA_HASH`].
        device_schema_hash: u32,
    },
    /// The frame was intact but its message is unknown to this firmware.
    UnknownMessage,
    /// An argument is out of range (frequency, rate, sample count, voltage).
    BadArgument,
    /// A fault is latched; clear it first.
    InFaultHold,
    /// `SetParameters` failed validation: the field and the reason.
    ParametersRejected(ParameterRejection),
    /// Not now: a capture is running, the motor is on, a flash write is pending, or
    /// [`crate::REQUEST_WINDOW`] replies still wait to be sent. The request had no effect.
    Busy,
    /// Writing the parameters to flash failed.
    StorageFailed,
    /// A `Simulation` command reached real hardware.
    SimulationOnly,
    /// A drive (`Release { on: true }`, `OpenLoop` with volts) before the current sensor's
    /// zero is measured (about 100 ms after boot or a `RezeroCurrent`): the overcurrent trip
    /// is centred on the measured zero, so nothing may drive before it exists. Ask again
    /// once the zero is measured; the request had no effect.
    CurrentZeroPending,
    /// `StartStream` asked a rate the device does not stream at (only 10 kHz divided by a
    /// whole number: [`crate::MAX_STREAM_RATE_HZ`]); names the highest rate at or below the
    /// one asked that it does ([`crate::stream_rate_that_fits`]). `BadArgument` for 0.
    StreamRate {
        /// The rate to ask instead, Hz.
        fits_hz: u16,
    },
}

impl NackCode {
    /// Largest serialised size, bytes (`VersionMismatch`).
    pub const MAX_WIRE_SIZE: usize = TAG + U16 + U32;

    /// The code's name, e.g. `BadArgument`.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::VersionMismatch { .. } => "VersionMismatch",
            Self::UnknownMessage => "UnknownMessage",
            Self::BadArgument => "BadArgument",
            Self::InFaultHold => "InFaultHold",
            Self::ParametersRejected(_) => "ParametersRejected",
            Self::Busy => "Busy",
            Self::StorageFailed => "StorageFailed",
            Self::SimulationOnly => "SimulationOnly",
            Self::CurrentZeroPending => "CurrentZeroPending",
            Self::StreamRate { .. } => "StreamRate",
        }
    }
}

/// What the device said, as a clause: "a fault is latched", "`mu_d` contradicts another
/// field", ... (the host adds what to do).
impl fmt::Display for NackCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::VersionMismatch {
                device_protocol,
                device_schema_hash,
            } => write!(
                f,
                "the device speaks protocol {device_protocol} (schema {device_schema_hash:#010x})"
            ),
            Self::UnknownMessage => f.write_str("the firmware does not know this request"),
            Self::BadArgument => f.write_str("an argument is outside the device's range"),
            Self::InFaultHold => f.write_str("a fault is latched and holds the motor off"),
            Self::ParametersRejected(r) => write!(f, "{r}"),
            Self::Busy => f.write_str(
                "the device is busy (a capture, a flash write, or the motor is running)",
            ),
            Self::StorageFailed => f.write_str("writing the parameters to flash failed"),
            Self::SimulationOnly => f.write_str("simulation commands work only on the virtual rig"),
            Self::CurrentZeroPending => f.write_str(
                "the current sensor's zero is still being measured (the overcurrent trip needs it)",
            ),
            Self::StreamRate { fits_hz } => write!(
                f,
                "the device streams at 10 kHz divided by a whole number; \
                 the highest rate at or below the one asked is {fits_hz} Hz"
            ),
        }
    }
}
