//! Human names of the protocol's messages, for error messages (never Rust `Debug` output).
//! Protocol v2 is to carry each request's name in `protocol`; until then they live here,
//! where both the simulator and the host tool reach them.

use protocol::{DeviceMessage, NackCode, Request};

/// Short name of a request, e.g. `Release(on)`.
pub fn request_name(req: &Request) -> &'static str {
    match req {
        Request::Hello { .. } => "Hello",
        Request::GetInfo => "GetInfo",
        Request::Release { on: true, .. } => "Release(on)",
        Request::Release { on: false, .. } => "Release(off)",
        Request::Heartbeat => "Heartbeat",
        Request::GetCalibration => "GetCalibration",
        Request::SetCalibration(_) => "SetCalibration",
        Request::StartTelemetry { .. } => "StartTelemetry",
        Request::StopTelemetry => "StopTelemetry",
        Request::StartCapture { .. } => "StartCapture",
        Request::GetFaults => "GetFaults",
        Request::ClearFaults => "ClearFaults",
        Request::RezeroCurrent => "RezeroCurrent",
        Request::OpenLoop { .. } => "OpenLoop",
        _ => "a request this tool does not know",
    }
}

/// Why the device refused, in words (`bad argument`, not `BadArgument`).
pub fn nack_name(code: NackCode) -> &'static str {
    match code {
        NackCode::UnknownMessage => "unknown request",
        NackCode::BadArgument => "argument out of range",
        NackCode::InFaultHold => "a fault is latched",
        NackCode::VersionMismatch => "protocol version mismatch",
        // A struct pattern, so the field-naming form protocol v2 brings still matches.
        #[allow(clippy::unneeded_struct_pattern)]
        NackCode::CalibrationRejected { .. } => "calibration rejected",
        NackCode::Busy => "busy",
        NackCode::StorageFailed => "flash write failed",
        _ => "a reason this tool does not know",
    }
}

/// A device message, named: `Ack`, `Nack (busy)`, `Telemetry`, ...
pub fn message_name(msg: &DeviceMessage) -> String {
    match msg {
        DeviceMessage::Info(_) => "Info".into(),
        DeviceMessage::Ack { .. } => "Ack".into(),
        DeviceMessage::Nack { code, .. } => format!("Nack ({})", nack_name(*code)),
        DeviceMessage::Telemetry(_) => "Telemetry".into(),
        DeviceMessage::CaptureChunk(_) => "CaptureChunk".into(),
        DeviceMessage::CaptureDone { .. } => "CaptureDone".into(),
        DeviceMessage::FaultEvent { .. } => "FaultEvent".into(),
        DeviceMessage::Faults { .. } => "Faults".into(),
        DeviceMessage::Calibration(_) => "Calibration".into(),
        _ => "a message this tool does not know".into(),
    }
}

/// Tooth counts as the command line takes them: `49,51,50,50`.
pub fn teeth(z: &[u32; 4]) -> String {
    z.map(|v| v.to_string()).join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_words() {
        let nack = DeviceMessage::Nack {
            seq: 3,
            code: NackCode::BadArgument,
        };
        assert_eq!(message_name(&nack), "Nack (argument out of range)");
        assert_eq!(
            request_name(&Request::Release {
                on: true,
                target_hz: 10.0
            }),
            "Release(on)"
        );
        assert_eq!(teeth(&[49, 51, 50, 50]), "49,51,50,50");
    }
}
