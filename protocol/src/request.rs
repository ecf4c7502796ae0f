//! Host-to-device requests and the facts each one carries: its name, the reply it
//! expects and whether sending it again after a timeout is safe.
//!
//! Variant order is the wire discriminant: append new variants at the end only, and keep
//! `Hello` first.

use serde::{Deserialize, Serialize};

use crate::sizes::TAG;
use crate::{Reply, RigParameters};

/// Host-to-device requests. Each is answered by exactly one [`crate::DeviceMessage::Reply`]
/// carrying the request's frame `seq`: the reply of its [`Request::reply_kind`], or a
/// [`Reply::Nack`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Request {
    /// Opens a session; answered by `Info`, or `Nack(VersionMismatch)` naming the device's
    /// version. Its layout never changes, so a device recognises any host's `Hello`.
    Hello {
        /// The host's [`crate::PROTOCOL_VERSION`].
        protocol_version: u16,
        /// The host's [`crate::SCHEMA_HASH`].
        schema_hash: u32,
    },
    /// Asks for `Info`.
    GetInfo,
    /// Starts (`on`) or stops vibration. A release belongs to the session that started it
    /// and stays live only while that session's `Release`, `OpenLoop` or `Heartbeat`
    /// requests keep arriving within [`crate::COMMS_TIMEOUT_MS`]; another session's
    /// `Release { on: true }` is refused with `Busy` while it is live. Any session may lock
    /// (`on` false).
    Release {
        /// True to vibrate (make the gear backdrivable), false to lock.
        on: bool,
        /// Vibration (cam) frequency, Hz: from the board's minimum up to the active
        /// parameters' `max_freq_hz` (at most the board's cap); outside it `BadArgument`,
        /// never clamped. Ignored when `on` is false.
        target_hz: f32,
        /// The sending host session ([`SessionId`]): the release's owner.
        session: SessionId,
    },
    /// Keeps the sending session's release or open-loop drive alive; answered by `Ack`
    /// (another session's heartbeat is answered too, but keeps nothing alive).
    Heartbeat {
        /// The sending host session.
        session: SessionId,
    },
    /// Asks for the active [`RigParameters`]; answered by `Parameters`.
    GetParameters,
    /// Validates, stores and activates a parameter record; `Ack` once stored, or
    /// `Nack(ParametersRejected)` naming the field, or `Nack(Busy)` while the motor runs.
    SetParameters(RigParameters),
    /// Streams `Telemetry` at `rate_hz`: the control rate (1 kHz) divided by a whole
    /// number, at most [`crate::MAX_TELEMETRY_RATE_HZ`]; any other rate is refused with
    /// `BadArgument`, never rounded.
    StartTelemetry {
        /// Samples per second.
        rate_hz: u16,
    },
    /// Stops the telemetry stream.
    StopTelemetry,
    /// Records a raw capture, then sends it as `CaptureChunk`s and a `CaptureDone`.
    StartCapture {
        /// Sample rate, Hz: the ADC rate (10 kHz, as the paper logged) divided by a whole
        /// number, at least 100 Hz; any other rate is refused with `BadArgument`.
        sample_rate_hz: u16,
        /// Number of samples to record, 1 up to the device's buffer (10 000 on the
        /// Nucleo firmware); more is refused with `BadArgument`, never capped.
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
        /// The sending host session: the drive's owner, as for `Release`.
        session: SessionId,
    },
    /// An operator action on the virtual rig (hang a load, change a supply). Real firmware
    /// answers `Nack(SimulationOnly)`; the virtual rig `Ack`.
    Simulation(SimCommand),
    /// Starts the continuous stream of raw samples ([`crate::DeviceMessage::StreamBlock`])
    /// at `rate_hz`: [`crate::MAX_STREAM_RATE_HZ`] (10 kHz, every ADC sample) divided by a
    /// whole number; another rate is refused with `Nack(StreamRate { fits_hz })`, 0 with
    /// `BadArgument`. Sample numbers start at 0; asking the running rate again changes
    /// nothing. The stream stops on `StopStream`, and when no request is accepted for
    /// [`crate::COMMS_TIMEOUT_MS`] (a host keeps it with `Heartbeat`s).
    StartStream {
        /// Samples per second.
        rate_hz: u16,
    },
    /// Stops the continuous stream.
    StopStream,
    /// Switches the link to `baud` (8N1), at most the device's [`crate::DeviceInfo::max_baud`]
    /// and either that or [`crate::DEFAULT_BAUD_RATE`]; another rate is refused with
    /// `BadArgument`. The device sends its `Ack` at the old rate, then switches; a device
    /// that accepts no request at the new rate within [`crate::BAUD_CONFIRM_MS`] goes back
    /// to the default rate.
    SetBaud {
        /// The new rate, Bd.
        baud: u32,
    },
}

/// A host session's identity on a link shared by several processes: a number the host
/// picks at random when it opens the session. The device keeps a release or open-loop drive
/// alive only on requests carrying its owner's id, so a second process on the same port
/// cannot keep a dead host's release vibrating (`protocol/LAYOUT.md`, "State rules").
pub type SessionId = u32;

/// The simulated operator's and bench's actions, for procedures that run unchanged on the
/// real and the virtual rig (on a real rig the operator does them by hand).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum SimCommand {
    /// Hangs a load torque on the output shaft, N m (0 removes it; the sign is the
    /// direction the load pulls).
    SetLoad {
        /// Load torque on the output, N m.
        tau_rot_nm: f32,
    },
    /// Sets the bench supply feeding the motor bridge, V.
    SetSupplyVoltage {
        /// Supply voltage, V.
        volts: f32,
    },
    /// Sets the current sensor's supply (the ACS714 is ratiometric to it), V; nominal 5.0.
    SetSensorSupply {
        /// Sensor supply voltage, V.
        volts: f32,
    },
}

impl SimCommand {
    /// The command's name, e.g. `SetLoad`.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::SetLoad { .. } => "SetLoad",
            Self::SetSupplyVoltage { .. } => "SetSupplyVoltage",
            Self::SetSensorSupply { .. } => "SetSensorSupply",
        }
    }
}

/// The kind of [`Reply`] a request expects when the device accepts it. Any request may
/// instead be refused with [`Reply::Nack`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReplyKind {
    /// [`Reply::Info`].
    Info,
    /// [`Reply::Ack`].
    Ack,
    /// [`Reply::Faults`].
    Faults,
    /// [`Reply::Parameters`].
    Parameters,
}

impl ReplyKind {
    /// The reply's name, e.g. `Info`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Info => "Info",
            Self::Ack => "Ack",
            Self::Faults => "Faults",
            Self::Parameters => "Parameters",
        }
    }
}

/// Variants of [`Request`] in this version (tags `0..REQUEST_VARIANTS`).
const REQUEST_VARIANTS: u32 = 17;
/// Tag of [`Request::Simulation`], and the commands of [`SimCommand`] it carries.
const SIMULATION_TAG: u32 = 13;
const SIM_COMMANDS: u32 = 3;

impl Request {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = TAG + RigParameters::MAX_WIRE_SIZE;

    /// Whether the CRC-checked body (`seq` and message, as [`crate::Deframer::last_body`]
    /// gives it) of a request that did not decode names a request this version knows.
    /// Then one of its fields is out of its type's range (a bool of 2, an enum tag past
    /// the last, a truncated field, trailing bytes) and the device answers
    /// `Nack(BadArgument)`; otherwise the request is unknown (`Nack(UnknownMessage)`).
    pub fn names_known_request(body: &[u8]) -> bool {
        let Ok((_seq, rest)) = postcard::take_from_bytes::<u16>(body) else {
            return false;
        };
        match postcard::take_from_bytes::<u32>(rest) {
            Ok((SIMULATION_TAG, rest)) => {
                matches!(postcard::take_from_bytes::<u32>(rest), Ok((c, _)) if c < SIM_COMMANDS)
            }
            Ok((tag, _)) => tag < REQUEST_VARIANTS,
            Err(_) => false,
        }
    }

    /// The session a drive request (`Release`, `Heartbeat`, `OpenLoop`) carries; `None` for
    /// the others.
    pub const fn session(&self) -> Option<SessionId> {
        match self {
            Self::Release { session, .. }
            | Self::Heartbeat { session }
            | Self::OpenLoop { session, .. } => Some(*session),
            _ => None,
        }
    }

    /// The request with `id` as the session of a drive request (the others unchanged): how
    /// a host session stamps its own id on what it sends.
    #[must_use]
    pub fn with_session(mut self, id: SessionId) -> Self {
        if let Self::Release { session, .. }
        | Self::Heartbeat { session }
        | Self::OpenLoop { session, .. } = &mut self
        {
            *session = id;
        }
        self
    }

    /// The request's name for messages: the variant, with `Release(on)` / `Release(off)`
    /// and `Simulation(SetLoad)` etc. spelled out.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Hello { .. } => "Hello",
            Self::GetInfo => "GetInfo",
            Self::Release { on: true, .. } => "Release(on)",
            Self::Release { on: false, .. } => "Release(off)",
            Self::Heartbeat { .. } => "Heartbeat",
            Self::GetParameters => "GetParameters",
            Self::SetParameters(_) => "SetParameters",
            Self::StartTelemetry { .. } => "StartTelemetry",
            Self::StopTelemetry => "StopTelemetry",
            Self::StartCapture { .. } => "StartCapture",
            Self::GetFaults => "GetFaults",
            Self::ClearFaults => "ClearFaults",
            Self::RezeroCurrent => "RezeroCurrent",
            Self::OpenLoop { .. } => "OpenLoop",
            Self::Simulation(SimCommand::SetLoad { .. }) => "Simulation(SetLoad)",
            Self::Simulation(SimCommand::SetSupplyVoltage { .. }) => "Simulation(SetSupplyVoltage)",
            Self::Simulation(SimCommand::SetSensorSupply { .. }) => "Simulation(SetSensorSupply)",
            Self::StartStream { .. } => "StartStream",
            Self::StopStream => "StopStream",
            Self::SetBaud { .. } => "SetBaud",
        }
    }

    /// The reply the device sends when it accepts this request.
    pub const fn reply_kind(&self) -> ReplyKind {
        match self {
            Self::Hello { .. } | Self::GetInfo => ReplyKind::Info,
            Self::GetFaults | Self::ClearFaults => ReplyKind::Faults,
            Self::GetParameters => ReplyKind::Parameters,
            Self::Release { .. }
            | Self::Heartbeat { .. }
            | Self::SetParameters(_)
            | Self::StartTelemetry { .. }
            | Self::StopTelemetry
            | Self::StartCapture { .. }
            | Self::RezeroCurrent
            | Self::OpenLoop { .. }
            | Self::Simulation(_)
            | Self::StartStream { .. }
            | Self::StopStream
            | Self::SetBaud { .. } => ReplyKind::Ack,
        }
    }

    /// Whether `reply` answers this request: a `Nack`, or the reply of its
    /// [`Request::reply_kind`]. Match the reply's `request_seq` first.
    pub fn is_answered_by(&self, reply: &Reply) -> bool {
        match reply.kind() {
            None => true,
            Some(kind) => kind == self.reply_kind(),
        }
    }

    /// Whether the host may send this request again when its reply did not arrive.
    ///
    /// The reply may have been lost after the device acted, so a retry is safe only when
    /// acting twice ends the same as acting once and the second reply tells the truth:
    ///
    /// * Queries (`Hello`, `GetInfo`, `GetParameters`, `GetFaults`) and `Heartbeat`: yes.
    /// * State assignments (`Release`, `OpenLoop`, `StartTelemetry`, `StopTelemetry`,
    ///   `StartStream`, `StopStream`, `Simulation`): yes. Each sets a state rather than stepping it, so a repeat lands in
    ///   the same state, and a repeat that the device now refuses (a fault latched in
    ///   between) reports that refusal truthfully. Repeating a lock (`Release(off)`,
    ///   `OpenLoop` 0 V) is the safe direction; a repeated release is still only live while
    ///   heartbeats arrive, so it cannot outlast the host.
    /// * `ClearFaults`: yes. It clears only faults whose condition is gone, and any fault
    ///   that rose between the tries was announced by its own `FaultEvent`.
    /// * `SetParameters`: no. Its reply comes after the flash write, so a retry can find the
    ///   first write still running (`Nack(Busy)`) and report a failure for a record that was
    ///   stored; read it back with `GetParameters` instead.
    /// * `StartCapture`: no. A second start discards the first capture and records anew.
    /// * `RezeroCurrent`: no. A second re-zero restarts the measurement; ask `GetFaults`.
    /// * `SetBaud`: no. A device that switched no longer hears the old rate; ask `GetInfo`
    ///   at the new one, and go back to the default when it does not answer.
    pub const fn retry_safe(&self) -> bool {
        !matches!(
            self,
            Self::SetParameters(_)
                | Self::StartCapture { .. }
                | Self::RezeroCurrent
                | Self::SetBaud { .. }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(seq: u16, request: &Request) -> std::vec::Vec<u8> {
        let mut buf = crate::encode_frame_vec(seq, request).unwrap();
        crate::frame_body(&mut buf).unwrap().to_vec()
    }

    #[test]
    fn known_requests_are_told_from_unknown_ones() {
        let examples = crate::golden::examples::requests();
        let mut tags = std::collections::BTreeSet::new();
        for (name, request) in &examples {
            let b = body(7, request);
            assert!(Request::names_known_request(&b), "{name}");
            tags.insert(b[1]);
        }
        // Every variant has an example, so the constant cannot fall behind the enum.
        assert_eq!(
            u32::try_from(tags.len()).unwrap(),
            REQUEST_VARIANTS,
            "{tags:?}"
        );
        // `Release { on: 2 }`: a known request with a bad field.
        assert!(Request::names_known_request(&[7, 2, 2, 0, 0, 0x20, 0x41]));
        // Tags past the last request, and a simulation command past the last.
        assert!(!Request::names_known_request(&[7, 17]));
        assert!(Request::names_known_request(&[7, 16]));
        assert!(!Request::names_known_request(&[7, 0x80, 0x01]));
        assert!(!Request::names_known_request(&[7, 13, 3]));
        assert!(Request::names_known_request(&[7, 13, 2]));
        assert!(!Request::names_known_request(&[]));
    }
}
