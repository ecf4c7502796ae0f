//! `rig faults`: the device's active and latched faults, with what each means.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;
use protocol::FaultFlags;
use serde::Serialize;

use super::connect::DeviceOpts;
use crate::RigError;
use crate::client::FaultStatus;

/// Arguments of `rig faults`. Exit status: 0 with no fault latched, 3 while one is.
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

/// What a fault means and what to do, one line: the protocol's table
/// ([`FaultFlags::TABLE`]), which the firmware raises from too.
pub fn fault_help(name: &str) -> &'static str {
    FaultFlags::help_of(name).unwrap_or(
        "a fault bit this host tool has no name for: the firmware is newer; update the host tool (`cargo install` from the firmware's source)",
    )
}

/// Prints faults with a line of help per fault.
pub fn print_text(out: &mut impl Write, f: FaultStatus) -> std::io::Result<()> {
    if f.active.is_empty() && f.latched.is_empty() {
        return writeln!(out, "no faults");
    }
    writeln!(out, "active:  {}", f.active)?;
    writeln!(out, "latched: {}", f.latched)?;
    let all = f.active | f.latched;
    for row in all.explained() {
        writeln!(out, "  {}: {}", row.name, row.help)?;
    }
    if !all.unknown().is_empty() {
        writeln!(out, "  {:#x}: {}", all.unknown().bits(), fault_help(""))?;
    }
    Ok(())
}

/// Exit status of `rig faults` (and of `rig clear`) when faults stay latched: the motor
/// is held off until they are cleared.
pub const EXIT_LATCHED: u8 = 3;

/// Runs `rig faults`: exits 0 with nothing latched, [`EXIT_LATCHED`] while a fault is
/// latched (the motor stays off), so scripts can test it.
pub fn run(a: FaultsArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let f = s.client.faults()?;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &FaultsReport::from(f))?;
    } else {
        print_text(&mut out, f)?;
    }
    Ok(if f.latched.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_LATCHED)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The host explains every bit the firmware can raise: both read the protocol's table,
    /// so a bit without help fails here and in `protocol`.
    #[test]
    fn every_fault_the_firmware_raises_is_explained() {
        for row in FaultFlags::TABLE {
            assert_eq!(fault_help(row.name), row.help);
            assert!(!fault_help(row.name).contains("no name"), "{}", row.name);
        }
        let all = FaultStatus {
            active: FaultFlags::empty(),
            latched: FaultFlags::all(),
        };
        let mut text = Vec::new();
        print_text(&mut text, all).unwrap();
        let text = String::from_utf8(text).unwrap();
        for row in FaultFlags::TABLE {
            assert!(
                text.contains(&format!("  {}: {}", row.name, row.help)),
                "{text}"
            );
        }
        assert!(!text.contains("update the host tool"), "{text}");
        // A bit from a newer firmware is named as such, with what to do.
        let newer = FaultStatus {
            active: FaultFlags::empty(),
            latched: FaultFlags::from_bits_retain(1 << 20),
        };
        let mut text = Vec::new();
        print_text(&mut text, newer).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(
            text.contains("0x100000") && text.contains("update the host tool"),
            "{text}"
        );
    }
}
