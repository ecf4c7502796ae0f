//! `rig demo`: command-line front of [`crate::demo`].

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use crate::connection::DeviceOpts;
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
    /// The figures' format and printed size; report.md shows them in this format.
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
}

/// Runs `rig demo`: the simulated rig by default; with `--port` the parts that cannot move
/// a load on a real rig. `given`: the device options on the command line (the simulated
/// demo runs in virtual time and has no serial line, so `--speed` and `--baud` without
/// `--port` do not apply).
pub fn run(a: DemoArgs, dev: &DeviceOpts, given: &[&str]) -> Result<ExitCode, RigError> {
    let real = dev.port.is_some() && !dev.sim;
    if given.contains(&"--speed") {
        return Err(RigError::BadValue {
            what: "--speed".into(),
            why: "`rig demo` runs the simulated rig in virtual time (and a real rig in real time): leave --speed out".into(),
        });
    }
    if !real && given.contains(&"--baud") {
        return Err(RigError::BadValue {
            what: "--baud".into(),
            why: "applies to `rig demo` only with --port (the simulated demo has no serial line)"
                .into(),
        });
    }
    if real && let Some(option) = a.figures.given() {
        return Err(RigError::BadValue {
            what: option.into(),
            why: "`rig demo --port` draws no figures (it runs only what cannot move a load): leave it out".into(),
        });
    }
    let chatty = !a.json && std::io::stderr().is_terminal();
    let summary = if real {
        demo::run_on_device(dev, &a.out)?
    } else {
        let opts = demo::DemoOptions {
            out: a.out.clone(),
            quick: a.quick,
            seed: a.seed,
            figures: a.figures.options(),
        };
        let size = a.figures.size();
        let writer = |dir: &std::path::Path,
                      result: &crate::calibrate::CalibrationResult,
                      measurements: &crate::calibrate::Measurements,
                      base: &protocol::RigParameters,
                      port: &str| {
            write_calibration(dir, result, measurements, base, port, size)
        };
        demo::run_simulated(&opts, &writer, &mut |step| {
            if chatty {
                eprintln!("... {step}");
            }
        })?
    };
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &summary)?;
    } else {
        write!(out, "{}", demo::render_text(&summary))?;
    }
    Ok(if summary.all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// `rig calibrate`'s file writer, for the demo's calibration step.
fn write_calibration(
    dir: &std::path::Path,
    result: &crate::calibrate::CalibrationResult,
    measurements: &crate::calibrate::Measurements,
    base: &protocol::RigParameters,
    port: &str,
    size: reporting::figure::FigureSize,
) -> Result<Vec<String>, RigError> {
    let w = super::calibrate::write_files(dir, result, measurements, base, port, size)?;
    Ok(vec![w.calibration, w.torque_plot, w.no_load_plot, w.points])
}
