//! The messages: [`Request`] (host to device) and [`DeviceMessage`] (device to host).
//!
//! Variant order is the wire discriminant: append new variants at the end only.

use core::fmt;

use heapless::String;
use serde::{Deserialize, Serialize};

use crate::sizes::{TAG, U8, U16, U32};
use crate::{BOARD_NAME_LEN, Calibration, CaptureChunk, FaultFlags, TelemetrySample};

/// A message with the sender's frame sequence number (wraps at `u16::MAX`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Frame<M> {
    /// Sender's frame counter; replies echo the request's value.
    pub seq: u16,
    /// The message.
    pub msg: M,
}

/// Host-to-device requests. Each is answered by a reply message, an `Ack` or a `Nack`.
///
/// Data replies (`Info`, `Calibration`, `Faults`) do not echo the request's `seq`: the
/// host keeps one request outstanding and matches them by type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Request {
    /// Opens a session; answered by `Info`, or `Nack(VersionMismatch)`.
    Hello {
        /// The host's [`crate::PROTOCOL_VERSION`].
        protocol_version: u16,
        /// The host's [`crate::SCHEMA_HASH`].
        schema_hash: u32,
    },
    /// Asks for `Info`.
    GetInfo,
    /// Starts (`on`) or stops vibration. A release stays live only while heartbeats
    /// (or any request) keep arriving within the comms timeout.
    Release {
        /// True to vibrate (make the gear backdrivable), false to lock.
        on: bool,
        /// Vibration (cam) frequency, Hz; ignored when `on` is false.
        target_hz: f32,
    },
    /// Keeps a release alive; answered by `Ack`.
    Heartbeat,
    /// Asks for the active `Calibration`.
    GetCalibration,
    /// Validates, stores and activates a calibration; `Ack` or
    /// `Nack(CalibrationRejected)`. Refused while released.
    SetCalibration(Calibration),
    /// Streams `Telemetry` at `rate_hz` (at most [`crate::MAX_TELEMETRY_RATE_HZ`]).
    StartTelemetry {
        /// Samples per second.
        rate_hz: u16,
    },
    /// Stops the telemetry stream.
    StopTelemetry,
    /// Records a raw capture, then sends it as `CaptureChunk`s and a `CaptureDone`.
    StartCapture {
        /// Sample rate, Hz (the paper logged at 10 kHz).
        sample_rate_hz: u16,
        /// Number of samples to record (the device may clamp to its buffer).
        samples: u32,
    },
    /// Asks for `Faults`.
    GetFaults,
    /// Clears latched faults whose condition is gone; answered by `Faults`.
    ClearFaults,
    /// Re-measures the current-sensor zero (motor must be off); `Ack` or `Nack`.
    RezeroCurrent,
    /// Drives the vibrator at a fixed bridge voltage without the speed loop, as the paper's
    /// bench supply did for the calibration and the required-torque tests. Kept alive by
    /// heartbeats like a release; `volts` 0 ends it. `Nack(InFaultHold)` with a fault
    /// latched, `Nack(Busy)` while a release runs, `Nack(BadArgument)` beyond the supply.
    OpenLoop {
        /// Mean voltage across the motor, V (sign: direction).
        volts: f32,
    },
}

impl Request {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = TAG + Calibration::MAX_WIRE_SIZE;
}

/// Device-to-host messages: replies and unsolicited streams.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// The device has no heap: messages are built in place in static buffers.
#[allow(clippy::large_enum_variant)]
#[non_exhaustive]
pub enum DeviceMessage {
    /// Identity and versions; reply to `Hello` and `GetInfo`.
    Info(DeviceInfo),
    /// The request `seq` was accepted.
    Ack {
        /// Sequence number of the accepted request.
        seq: u16,
    },
    /// The request `seq` was refused.
    Nack {
        /// Sequence number of the refused request.
        seq: u16,
        /// Why.
        code: NackCode,
    },
    /// A periodic sample.
    Telemetry(TelemetrySample),
    /// Part of a capture upload.
    CaptureChunk(CaptureChunk),
    /// A capture upload is complete.
    CaptureDone {
        /// The capture's id.
        capture_id: u16,
        /// Samples sent in all chunks.
        total_samples: u32,
        /// Actual sample rate, Hz (may differ from the request after clamping).
        sample_rate_hz: u16,
    },
    /// New faults became active (sent once, when they rise).
    FaultEvent {
        /// The faults that rose.
        flags: FaultFlags,
        /// Device clock when they rose, microseconds since boot.
        device_time_us: u64,
    },
    /// Reply to `GetFaults` and `ClearFaults`.
    Faults {
        /// Faults whose condition is present now.
        active: FaultFlags,
        /// Faults latched since the last clear (the motor stays off while non-empty).
        latched: FaultFlags,
    },
    /// Reply to `GetCalibration`: the active calibration.
    Calibration(Calibration),
}

impl DeviceMessage {
    /// Largest serialised size, bytes (a full capture chunk).
    pub const MAX_WIRE_SIZE: usize = TAG + CaptureChunk::MAX_WIRE_SIZE;
}

/// Why a request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum NackCode {
    /// The frame was intact but its message is unknown to this firmware.
    UnknownMessage,
    /// An argument is out of range (frequency, rate, sample count).
    BadArgument,
    /// A fault is latched; clear it first.
    InFaultHold,
    /// `Hello` named another protocol version or schema hash.
    VersionMismatch,
    /// `SetCalibration` failed validation.
    CalibrationRejected,
    /// Not now (e.g. a capture is running, or the motor is on).
    Busy,
    /// Writing the calibration to flash failed.
    StorageFailed,
}

/// Firmware version, semantic-versioning style.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct FirmwareVersion {
    /// Incompatible changes.
    pub major: u8,
    /// Compatible additions.
    pub minor: u8,
    /// Fixes.
    pub patch: u8,
}

impl fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// Where the active calibration came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum CalibrationStatus {
    /// A stored calibration passed its checks and is in use.
    Valid,
    /// Nothing stored: the paper's values are in use.
    Defaults,
    /// The stored calibration failed its checks: the paper's values are in use.
    Invalid,
}

/// Device identity, reply to `Hello` and `GetInfo`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// Firmware version.
    pub firmware_version: FirmwareVersion,
    /// The firmware's [`crate::PROTOCOL_VERSION`].
    pub protocol_version: u16,
    /// The firmware's [`crate::SCHEMA_HASH`].
    pub schema_hash: u32,
    /// Board name, e.g. `nucleo-g474re` or `virtual`.
    pub board: String<BOARD_NAME_LEN>,
    /// Source of the active calibration.
    pub calibration_status: CalibrationStatus,
}

impl DeviceInfo {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = 3 * U8 + U16 + U32 + TAG + BOARD_NAME_LEN + TAG;
}
