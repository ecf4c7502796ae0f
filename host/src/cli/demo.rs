//! `rig demo`: command-line front of [`crate::demo`].

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use crate::cli::connect::DeviceOpts;
use crate::{RigError, demo};

/// Arguments of `rig demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Report folder (CSV, JSON, SVG plots, calibration TOML).
    #[arg(long, default_value = "report/demo")]
    pub out: PathBuf,
    /// A shorter torque sweep (3 loads, 1 repeat) for a quick look.
    #[arg(long)]
    pub quick: bool,
    /// Seed of the simulated noise and test order.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `rig demo`: the simulated rig by default; with `--port` (or $RIG_PORT) the parts
/// that cannot move a load on a real rig.
pub fn run(a: DemoArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let real = dev.port.is_some() && !dev.sim;
    let chatty = !a.json && std::io::stderr().is_terminal();
    let summary = if real {
        demo::run_on_device(dev, &a.out)?
    } else {
        let opts = demo::DemoOptions {
            out: a.out.clone(),
            quick: a.quick,
            seed: a.seed,
        };
        demo::run_simulated(&opts, &mut |step| {
            if chatty {
                eprintln!("... {step}");
            }
        })?
    };
    let mut out = std::io::stdout().lock();
    if a.json {
        serde_json::to_writer_pretty(&mut out, &summary)?;
        writeln!(out)?;
    } else {
        write!(out, "{}", demo::render_text(&summary))?;
    }
    Ok(if summary.all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
