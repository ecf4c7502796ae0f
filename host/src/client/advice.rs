//! What to tell the user when the device refuses, stays silent or speaks another version.

use protocol::{NackCode, PeerIdentity, Reply, Request};

use crate::RigError;

/// What to do about a refusal, by its code (the code's own clause says what happened).
pub fn nack_advice(code: NackCode) -> String {
    match code {
        NackCode::VersionMismatch { device_protocol, .. } => {
            protocol::version_advice(device_protocol).to_owned()
        }
        NackCode::UnknownMessage => {
            "the firmware does not know this request: run `rig flash` to put this tool's firmware on the rig".into()
        }
        NackCode::BadArgument => {
            "an argument is out of the device's range (frequency above the calibration's max_freq_hz, telemetry rate, sample count or voltage): use a smaller value".into()
        }
        NackCode::InFaultHold => {
            "a fault is latched and holds the motor off: `rig faults` shows it, `rig clear` clears it once its cause is gone".into()
        }
        NackCode::ParametersRejected(rejection) => format!(
            "the firmware refused the rig parameters: {rejection}; fix that key in the rig file (`rig calibration get` shows the active values)"
        ),
        NackCode::Busy => {
            "the device is busy (a capture is recording, or the motor is running): wait, or `rig release off`, then try again".into()
        }
        NackCode::StorageFailed => {
            "writing to the device's flash failed: try again; if it keeps failing the calibration page may be worn".into()
        }
        NackCode::SimulationOnly => {
            "simulation commands act only on the virtual rig (--sim); on a real rig do this by hand".into()
        }
        NackCode::CurrentZeroPending => format!(
            "the device is still measuring its current sensor's zero with the motor off (100 ms after boot or a re-zero), and it did not finish within {} s of the device's time: check `rig faults` and the sensor's supply, then try again",
            sim::riglink::ZERO_WAIT_S
        ),
        NackCode::StreamRate { fits_hz } => format!(
            "ask for --rate {fits_hz} (or a lower rate that divides 10 kHz; the link carries the stream beside the telemetry only up to the rate the device names)"
        ),
        _ => "the firmware refused it for a reason this tool does not know: update the rig tool".into(),
    }
}

/// The error for request `req` refused with `code`.
pub(super) fn refused(req: &Request, code: NackCode) -> RigError {
    RigError::Refused {
        request: req.name(),
        code,
        advice: nack_advice(code),
    }
}

/// The error for request `req` refused with `code` (`InFaultHold`) while the faults
/// `latched` are latched (when the device said): the advice names them.
pub(super) fn refused_in_fault_hold(
    req: &Request,
    code: NackCode,
    latched: Option<protocol::FaultFlags>,
) -> RigError {
    let names: Vec<&str> = latched.iter().flat_map(|l| l.names()).collect();
    if names.is_empty() {
        return refused(req, code);
    }
    RigError::Refused {
        request: req.name(),
        code,
        advice: format!(
            "latched: {} (it holds the motor off): `rig faults` says what each means, `rig clear` clears it once its cause is gone",
            names.join(", ")
        ),
    }
}

/// The error for request `req` answered with a reply of another kind.
pub(super) fn unexpected(req: &Request, reply: &Reply, port: &str) -> RigError {
    RigError::Protocol(format!(
        "the device answered {} with {} instead of {} on {port}; run `rig flash` so the firmware matches this tool",
        req.name(),
        reply.name(),
        req.reply_kind().name()
    ))
}

/// The error for a device identified as another protocol version.
pub(super) fn version_error(source: protocol::Error) -> RigError {
    RigError::VersionMismatch { source }
}

/// The error for a peer recognised by its frame layout (an older or newer device).
pub(super) fn peer_error(peer: PeerIdentity) -> RigError {
    version_error(protocol::session::peer_error(peer))
}

/// Why the device may be silent, from what arrived instead of a reply.
pub(super) fn silence_hint(bytes: u64, bad_frames: u32) -> String {
    if bytes == 0 {
        "nothing came back: check that the rig is powered, the firmware flashed (`rig flash`) and this is its port (`rig ports` lists them)".into()
    } else if bad_frames > 0 {
        format!(
            "{bytes} bytes came back but {bad_frames} frame(s) were garbled: the baud rate probably differs from the firmware's ({} by default; set it with --baud)",
            protocol::DEFAULT_BAUD_RATE
        )
    } else {
        format!(
            "{bytes} bytes came back but no answer to this request: the device may be busy; try again"
        )
    }
}
