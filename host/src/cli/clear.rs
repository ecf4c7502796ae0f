//! `rig clear`: clears the latched faults whose cause is gone.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;

use super::connect::DeviceOpts;
use super::faults::{FaultsReport, print_text};
use crate::RigError;

/// Arguments of `rig clear`.
#[derive(Debug, Args)]
pub struct ClearArgs {
    /// Print JSON (the faults left) instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `rig clear`: clears what can be cleared; fails when faults stay latched.
pub fn run(a: ClearArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let f = s.client.clear_faults()?;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &FaultsReport::from(f))?;
    } else if f.latched.is_empty() {
        writeln!(out, "faults cleared")?;
    } else {
        print_text(&mut out, f)?;
    }
    if f.latched.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        Err(RigError::DeviceFault {
            what: "clear".into(),
            faults: format!(
                "{} (their cause is still present, so they stay latched)",
                f.latched
            ),
        })
    }
}
