//! `rig info`: the device's identity, versions and calibration source.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;
use protocol::{DeviceInfo, ParametersStatus as CalibrationStatus};
use serde::Serialize;

use super::connect::DeviceOpts;
use crate::RigError;

/// Arguments of `rig info`.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// What `rig info` prints.
#[derive(Debug, Serialize)]
pub struct InfoReport {
    /// The port (or the virtual device's pseudo-terminal).
    pub port: String,
    /// Whether this is the virtual device.
    pub sim: bool,
    /// Firmware version, `major.minor.patch`.
    pub firmware_version: String,
    /// The firmware's protocol version.
    pub protocol_version: u16,
    /// The firmware's schema hash, hex.
    pub schema_hash: String,
    /// This tool's protocol version.
    pub host_protocol_version: u16,
    /// Board name.
    pub board: String,
    /// Where the active calibration came from: `valid`, `defaults` or `invalid`.
    pub calibration_status: &'static str,
    /// The firmware's build: the git commit it was built from (`-dirty` when the tree had
    /// uncommitted changes, `unknown` without git).
    pub firmware_build: String,
    /// Why the device last reset: `power-on`, `pin`, `software`, `watchdog`, `brown-out`,
    /// `lockup` or `other`.
    pub reset_cause: &'static str,
    /// Time since that reset, s.
    pub uptime_s: u32,
    /// Optional hardware the device reports (`OUTPUT_ENCODER`, `BUS_VOLTAGE`, `MOTOR_TEMP`,
    /// `SIMULATION`: the virtual rig).
    pub capabilities: Vec<&'static str>,
    /// Device seconds per wall-clock second: 1 on a board, the `--speed` of a virtual rig.
    pub time_scale: f64,
    /// The bridge's decay mode: `brake` (slow decay, the Pololu G2: power returns) or
    /// `coast` (`Capabilities::BRAKING_DECAY` clear).
    pub decay: &'static str,
    /// The fastest link rate the device agrees to (`--baud`), Bd; every link starts at
    /// 921,600.
    pub max_baud: u32,
}

/// Lower-case name of a calibration status.
pub fn calibration_status_name(s: CalibrationStatus) -> &'static str {
    match s {
        CalibrationStatus::Valid => "valid",
        CalibrationStatus::Defaults => "defaults",
        CalibrationStatus::Invalid => "invalid",
        _ => "unknown",
    }
}

impl InfoReport {
    /// The report for `info` read on `port`.
    pub fn new(info: &DeviceInfo, port: &str, sim: bool) -> Self {
        Self {
            port: port.to_owned(),
            sim,
            firmware_version: info.firmware_version.to_string(),
            protocol_version: info.protocol_version,
            schema_hash: format!("{:#010x}", info.schema_hash),
            host_protocol_version: protocol::PROTOCOL_VERSION,
            board: info.board.to_string(),
            calibration_status: calibration_status_name(info.parameters_status),
            firmware_build: info.firmware_build.to_string(),
            reset_cause: info.reset_cause.name(),
            uptime_s: info.uptime_s,
            capabilities: protocol::Capabilities::NAMED
                .iter()
                .filter(|(_, flag)| info.capabilities.contains(*flag))
                .map(|(name, _)| *name)
                .collect(),
            time_scale: f64::from(info.time_scale),
            decay: if info
                .capabilities
                .contains(protocol::Capabilities::BRAKING_DECAY)
            {
                "brake"
            } else {
                "coast"
            },
            max_baud: info.max_baud,
        }
    }
}

/// Runs `rig info`.
pub fn run(a: InfoArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let info = s.client.info()?;
    let report = InfoReport::new(&info, s.port(), s.device.is_some());
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &report)?;
    } else {
        writeln!(out, "device     {} on {}", report.board, report.port)?;
        writeln!(
            out,
            "firmware   {} (build {})",
            report.firmware_version, report.firmware_build
        )?;
        writeln!(
            out,
            "up         {} s since the last reset ({})",
            report.uptime_s, report.reset_cause
        )?;
        if !report.capabilities.is_empty() {
            writeln!(out, "fitted     {}", report.capabilities.join(", "))?;
        }
        writeln!(
            out,
            "bridge     {} decay{}",
            report.decay,
            if report.decay == "brake" {
                " (PWM low brakes: power returns through the gearhead)"
            } else {
                " (the off-time coasts: no power returns)"
            }
        )?;
        if report.time_scale != 1.0 {
            writeln!(
                out,
                "time       {}x real time (a virtual rig: every timeout in the protocol is device time)",
                report.time_scale
            )?;
        }
        writeln!(
            out,
            "protocol   v{} (schema {}), same as this tool",
            report.protocol_version, report.schema_hash
        )?;
        let note = match info.parameters_status {
            CalibrationStatus::Valid => "stored calibration in use",
            CalibrationStatus::Defaults => {
                "nothing stored: the paper's Table 2 values are in use (rig calibrate)"
            }
            _ => {
                "the stored calibration failed its check: the paper's values are in use (rig calibrate, or rig calibration set FILE)"
            }
        };
        writeln!(out, "calibration {}: {note}", report.calibration_status)?;
    }
    Ok(ExitCode::SUCCESS)
}
