//! `rig ports`: the serial ports of this machine, ST-LINK virtual COM ports marked.

use std::io::Write;
use std::process::ExitCode;

use clap::Args;

use crate::{RigError, ports};

/// Arguments of `rig ports`.
#[derive(Debug, Args)]
pub struct PortsArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `rig ports`.
pub fn run(a: PortsArgs) -> Result<ExitCode, RigError> {
    let list = ports::list();
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &list)?;
        return Ok(ExitCode::SUCCESS);
    }
    if list.is_empty() {
        writeln!(
            out,
            "no serial ports found: a Nucleo board's ST-LINK shows up as /dev/ttyACM* once plugged in (--sim runs the virtual device)"
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    for p in &list {
        let id = match (p.vid, p.pid) {
            (Some(v), Some(d)) => format!("{v:04x}:{d:04x}"),
            _ => "-".into(),
        };
        let what = [p.manufacturer.as_deref(), p.product.as_deref()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" ");
        let mark = if p.stlink {
            "  <- ST-LINK (Nucleo board)"
        } else {
            ""
        };
        writeln!(out, "{:<16} {:<5} {id:<9} {what}{mark}", p.port, p.kind)?;
    }
    Ok(ExitCode::SUCCESS)
}
