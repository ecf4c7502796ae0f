//! `rig faults`: the device's active and latched faults, with what each means.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;
use protocol::FaultFlags;
use serde::Serialize;

use super::connect::DeviceOpts;
use crate::RigError;
use crate::client::FaultStatus;

/// Arguments of `rig faults`.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Faults as `rig faults --json` prints them.
#[derive(Debug, Serialize)]
pub struct FaultsReport {
    /// Faults whose condition is present now.
    pub active: Vec<&'static str>,
    /// Faults latched since the last clear (they hold the motor off).
    pub latched: Vec<&'static str>,
}

impl From<FaultStatus> for FaultsReport {
    fn from(f: FaultStatus) -> Self {
        Self {
            active: f.active.names().collect(),
            latched: f.latched.names().collect(),
        }
    }
}

/// What a fault means and what to do, one line.
pub fn fault_help(name: &str) -> &'static str {
    match name {
        "OVERCURRENT" => {
            "motor current above the calibration's max_current_a: check for a jammed cam"
        }
        "STALL" => "the cam did not turn although driven: check the cam and the motor wiring",
        "ENCODER_LOSS" => "encoder signal lost or implausible: check the AMT102 cable",
        "CURRENT_ZERO_RANGE" => {
            "current-sensor zero out of range: check the ACS714 supply, then clear"
        }
        "CONTROL_OVERRUN" => "the control loop missed its deadline",
        "CALIBRATION_INVALID" => {
            "the stored calibration failed its check: `rig calibration set FILE` or `rig calibrate`"
        }
        "WATCHDOG_RESET" => "the firmware was reset by its watchdog",
        "COMMS_TIMEOUT" => {
            "no heartbeat while released: the host went away (clear it to release again)"
        }
        "CANNOT_RELEASE" => {
            "the required cam torque (Eq. 10) exceeds what the vibrator delivers: lower the load"
        }
        "JAM" => "the cam or the output is blocked",
        "OVERLOAD" => "load estimate above max_release_load_nm",
        "ESTIMATE_IMPLAUSIBLE" => "a torque or speed estimate is out of physical bounds",
        _ => "unknown fault bit: update the host tool",
    }
}

/// Prints faults with a line of help per fault.
pub fn print_text(out: &mut impl Write, f: FaultStatus) -> std::io::Result<()> {
    if f.active.is_empty() && f.latched.is_empty() {
        return writeln!(out, "no faults");
    }
    writeln!(out, "active:  {}", f.active)?;
    writeln!(out, "latched: {}", f.latched)?;
    for (name, _) in FaultFlags::NAMED
        .iter()
        .filter(|(_, flag)| (f.active | f.latched).contains(*flag))
    {
        writeln!(out, "  {name}: {}", fault_help(name))?;
    }
    Ok(())
}

/// Runs `rig faults`.
pub fn run(a: FaultsArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let f = s.client.faults()?;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &FaultsReport::from(f))?;
    } else {
        print_text(&mut out, f)?;
    }
    Ok(ExitCode::SUCCESS)
}
