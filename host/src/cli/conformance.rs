//! `rig conformance --port PORT`: the device-contract suite ([`crate::conformance`])
//! against any device: a board, a served virtual rig, another implementation.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;

use super::connect::DeviceOpts;
use crate::RigError;
use crate::client::open_serial;
use crate::conformance::{Options, run as run_suite};

/// Arguments of `rig conformance`.
#[derive(Debug, Args)]
pub struct ConformanceArgs {
    /// Requests sent in windows under 1 kHz telemetry and a capture.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    requests: usize,
    /// Print JSON: every check with `pass`, `fail` or `skip` and what was seen.
    #[arg(long)]
    json: bool,
}

/// Runs `rig conformance`: exit 0 when every check passed (skipped ones aside), 1 when
/// any failed. Checks that vibrate the carrier run on a simulation, or on a board with
/// `RIG_ALLOW_MOTION=1` (rig unloaded and clear).
pub fn run(a: ConformanceArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    if dev.sim {
        return Err(RigError::BadValue {
            what: "--sim".into(),
            why: "the suite checks a device it did not start: serve one with `rig sim serve` and give its port with --port".into(),
        });
    }
    if a.requests == 0 {
        return Err(RigError::BadValue {
            what: "--requests 0".into(),
            why: "give at least 1 request for the window check".into(),
        });
    }
    let port = dev.resolve_port()?;
    let io = open_serial(&port, dev.baud)?;
    let allow_motion = std::env::var("RIG_ALLOW_MOTION").is_ok_and(|v| v.trim() == "1");
    let report = run_suite(
        io,
        &Options {
            port: port.clone(),
            allow_motion,
            window_requests: a.requests,
        },
    )?;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &report)?;
    } else {
        for c in &report.checks {
            writeln!(out, "{:<4}  {:<34} {}", c.status, c.name, c.detail)?;
        }
        let failed = report.checks.iter().filter(|c| c.status == "fail").count();
        let skipped = report.checks.iter().filter(|c| c.status == "skip").count();
        writeln!(
            out,
            "{}: {} checks, {failed} failed, {skipped} skipped",
            port,
            report.checks.len()
        )?;
    }
    Ok(if report.passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
