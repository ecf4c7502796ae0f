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

/// Runs `rig clear`: clears what can be cleared; says what was cleared, or that nothing
/// was latched; fails (exit 3) naming what stays latched and why.
pub fn run(a: ClearArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let before = s.client.faults()?;
    let after = s.client.clear_faults()?;
    let cleared = before.latched.difference(after.latched);
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(
            &mut out,
            &ClearReport {
                cleared: cleared.names().collect(),
                faults: FaultsReport::from(after),
            },
        )?;
    } else {
        if before.latched.is_empty() {
            writeln!(out, "no faults were latched; nothing to clear")?;
        } else if !cleared.is_empty() {
            writeln!(out, "cleared: {cleared}")?;
        }
        if !after.latched.is_empty() {
            writeln!(
                out,
                "still latched: {} (the cause is still present: fix it, then `rig clear` again)",
                after.latched
            )?;
            print_text(&mut out, after)?;
        }
    }
    Ok(if after.latched.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(super::faults::EXIT_LATCHED)
    })
}

/// What `rig clear --json` prints: the faults it cleared and the faults now (the
/// `active` and `latched` keys of `rig faults --json`).
#[derive(Debug, serde::Serialize)]
pub struct ClearReport {
    /// Faults this clear removed from the latch.
    pub cleared: Vec<&'static str>,
    /// The faults after the clear.
    #[serde(flatten)]
    pub faults: FaultsReport,
}
