//! `rig demo`: command-line front of [`crate::demo`].

use std::io::Write;
use std::process::ExitCode;

use clap::Args;

use crate::{RigError, demo};

/// Arguments of `rig demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `rig demo`.
pub fn run(a: DemoArgs) -> Result<ExitCode, RigError> {
    let summary = demo::run()?;
    let mut out = std::io::stdout().lock();
    if a.json {
        serde_json::to_writer_pretty(&mut out, &summary)?;
        writeln!(out)?;
    } else {
        write!(out, "{}", demo::render_text(&summary))?;
    }
    Ok(if summary.agrees_with_paper {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
