//! The host's error type: every message says what went wrong and what to do next.

use thiserror::Error;

/// Everything that can go wrong in the `rig` tool.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RigError {
    /// Gear parameters that do not make a 2K-H gear.
    #[error("invalid gear set {}: {source}", sim::names::teeth(z))]
    Gear {
        /// The tooth counts given.
        z: [u32; 4],
        /// Why they were rejected.
        source: model::GearError,
    },
    /// A command-line or file value outside its meaningful range.
    #[error("{what}: {why}")]
    BadValue {
        /// Which value.
        what: String,
        /// What is wrong with it and what to give instead.
        why: String,
    },
    /// Writing the output failed.
    #[error("cannot write output: {0}")]
    Output(#[from] std::io::Error),
    /// JSON serialisation failed.
    #[error("cannot format JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// Measured data that is not readable as CSV with a header.
    #[error("{file}: {why}")]
    MeasuredFile {
        /// The data file.
        file: String,
        /// What is wrong and what to do.
        why: String,
    },
    /// A rig (model) file that cannot be used.
    #[error("rig file {file}: {why}")]
    RigFile {
        /// The rig file.
        file: String,
        /// What is wrong and what to write instead.
        why: String,
    },
    /// A file or folder that cannot be read or written.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// What was tried ("read", "write", "create folder").
        action: &'static str,
        /// The path.
        path: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A plot of a report that cannot be drawn.
    #[error("cannot draw {path}: {why}")]
    Plot {
        /// The plot file.
        path: String,
        /// The drawing backend's reason.
        why: String,
    },
    /// The device (real or simulated) broke the protocol or did not answer.
    #[error("device protocol: {0}")]
    Protocol(String),
    /// A test point the rig could not reach (the cam never came to constant rotation).
    #[error("{what}: {why}")]
    Unmeasurable {
        /// The point.
        what: String,
        /// What happened and what it suggests.
        why: String,
    },
    /// A serial port that would not open.
    #[error(
        "cannot open serial port {port}: {why}; `rig ports` lists the serial ports of this machine (or use --sim for the virtual device)"
    )]
    PortOpen {
        /// The port asked for.
        port: String,
        /// The operating system's reason, with what to do.
        why: String,
    },
    /// A serial port another program holds (another `rig`, a serial terminal, a modem
    /// manager): the port is there, but this client may not drive the rig through it.
    #[error(
        "serial port {port} is busy: {why}; close that program (or end the other `rig`), then try again"
    )]
    PortBusy {
        /// The port asked for.
        port: String,
        /// The operating system's reason, and who holds the port when that can be found.
        why: String,
    },
    /// No device was named.
    #[error(
        "no device given: pass --port PORT (`rig ports` lists them; RIG_PORT also works) or --sim for the virtual device"
    )]
    NoDevice,
    /// The device did not answer a request.
    #[error(
        "no reply from the device on {port} to {request} within {waited_ms} ms ({tries} tries): {hint}"
    )]
    NoReply {
        /// The port.
        port: String,
        /// The request.
        request: &'static str,
        /// Total time waited, ms.
        waited_ms: u64,
        /// How often it was sent.
        tries: u32,
        /// What came back instead and what to check.
        hint: String,
    },
    /// The device refused a request.
    #[error("the device refused {request}: {code}; {advice}")]
    Refused {
        /// The request.
        request: &'static str,
        /// The device's reason.
        code: protocol::NackCode,
        /// What the device said and what to do.
        advice: String,
    },
    /// Host tool and firmware speak different protocol versions or message layouts; the
    /// message says which side to update ([`protocol::check_peer`]).
    #[error("{source}")]
    VersionMismatch {
        /// The protocol's verdict, with its advice.
        source: protocol::Error,
    },
    /// Reading or writing the port failed after it was open.
    #[error("lost the link to {port}: {source}; check the cable and that the board is powered")]
    Link {
        /// The port.
        port: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A fault latched on the device stopped what was asked.
    #[error(
        "{what}: the device latched {faults}; `rig faults` shows them, `rig clear` clears them once the cause is gone"
    )]
    DeviceFault {
        /// What was running.
        what: String,
        /// The faults (their names and help: `protocol::FaultFlags::TABLE`).
        faults: protocol::FaultFlags,
    },
    /// A calibration file that cannot be used; nothing was sent to the device.
    #[error("calibration file {file}: {why}; nothing was written to the device")]
    CalibrationFile {
        /// The file.
        file: String,
        /// What is wrong and what to write instead.
        why: String,
    },
    /// Calibration measurements that cannot be fitted.
    #[error("calibration: {0}")]
    CalibrationFit(String),
    /// The operator's input ended or could not be used.
    #[error("{0}")]
    Operator(String),
    /// The virtual rig or a scenario failed.
    #[error(transparent)]
    Sim(#[from] sim::SimError),
    /// The discrepancy workflow failed.
    #[error(transparent)]
    Explain(#[from] explain::ExplainError),
    /// A rig file that cannot be read, used or written.
    #[error(transparent)]
    RigFileInvalid(#[from] rigfile::RigFileError),
    /// A report file or plot that cannot be written.
    #[error(transparent)]
    Report(#[from] reporting::ReportError),
    /// The virtual device could not start.
    #[error("cannot start the virtual device: {0}")]
    VirtualDevice(String),
}

impl RigError {
    /// The device's reason when this is its refusal (a `Nack`, from the device link or the
    /// in-process virtual rig), `None` for any other error.
    pub fn refusal(&self) -> Option<protocol::NackCode> {
        match self {
            Self::Refused { code, .. } | Self::Sim(sim::SimError::Refused { code, .. }) => {
                Some(*code)
            }
            _ => None,
        }
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_things_in_words() {
        let e = RigError::Refused {
            request: "Release(on)",
            code: protocol::NackCode::BadArgument,
            advice: "use a smaller value".into(),
        };
        assert_eq!(
            e.to_string(),
            "the device refused Release(on): an argument is outside the device's range; use a smaller value"
        );
        let e = RigError::Gear {
            z: [49, 51, 50, 51],
            source: model::GearSet::new([49, 51, 50, 51], 1e-3, 0.35).unwrap_err(),
        };
        assert!(
            e.to_string().starts_with("invalid gear set 49,51,50,51: "),
            "{e}"
        );
    }
}
