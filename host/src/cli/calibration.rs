//! `rig calibration get|set`: read the device's calibration into a TOML file, or write a
//! TOML file to the device (checked first: a bad file changes nothing).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};

use super::connect::{DeviceOpts, confirm};
use crate::RigError;
use crate::calibrate::file;

/// Arguments of `rig calibration`.
#[derive(Debug, Args)]
pub struct CalibrationArgs {
    /// Read or write.
    #[command(subcommand)]
    action: CalibrationAction,
}

/// `get` or `set`.
#[derive(Debug, Subcommand)]
pub enum CalibrationAction {
    /// Print the device's calibration as TOML, or write it to FILE.
    Get {
        /// Write it here instead of printing it.
        file: Option<PathBuf>,
        /// Print JSON instead of TOML.
        #[arg(long)]
        json: bool,
    },
    /// Write the calibration in FILE (TOML; keys left out keep the device's values) to the
    /// device.
    Set {
        /// The calibration file (`rig calibration get FILE` writes an example).
        file: PathBuf,
        /// Write without asking.
        #[arg(long, short = 'y')]
        yes: bool,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Runs `rig calibration`.
pub fn run(a: CalibrationArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    match a.action {
        CalibrationAction::Get { file: path, json } => {
            let mut s = dev.connect()?;
            let cal = s.client.calibration()?;
            let mut out = std::io::stdout().lock();
            if json {
                serde_json::to_writer_pretty(&mut out, &cal)?;
                writeln!(out)?;
                return Ok(ExitCode::SUCCESS);
            }
            let text = file::to_toml(
                &cal,
                &format!("Calibration read from the device on {}.", s.port()),
                None,
            );
            match path {
                Some(p) => {
                    std::fs::write(&p, text).map_err(|source| RigError::File {
                        action: "write",
                        path: p.display().to_string(),
                        source,
                    })?;
                    writeln!(out, "wrote {}", p.display())?;
                }
                None => write!(out, "{text}")?,
            }
            Ok(ExitCode::SUCCESS)
        }
        CalibrationAction::Set {
            file: path,
            yes,
            json,
        } => {
            // A file that cannot even be parsed is refused before the device is opened.
            let text = std::fs::read_to_string(&path).map_err(|e| RigError::CalibrationFile {
                file: path.display().to_string(),
                why: format!("cannot read it ({e})"),
            })?;
            let name = path.display().to_string();
            file::parse(&text, &name, &protocol::RigParameters::paper())?;
            let mut s = dev.connect()?;
            let current = s.client.calibration()?;
            let parsed = file::parse(&text, &name, &current)?;
            let new = parsed.calibration;
            let changes: Vec<String> = diff(&current, &new);
            let mut out = std::io::stdout().lock();
            if changes.is_empty() {
                if json {
                    writeln!(
                        out,
                        "{}",
                        serde_json::json!({ "changed": [], "written": false })
                    )?;
                } else {
                    writeln!(
                        out,
                        "the device already has this calibration: nothing to write"
                    )?;
                }
                return Ok(ExitCode::SUCCESS);
            }
            if !json {
                writeln!(out, "changes on {}:", s.port())?;
                for c in &changes {
                    writeln!(out, "  {c}")?;
                }
            }
            if !yes && !confirm("Write this calibration to the device?")? {
                return Err(RigError::Operator(
                    "not written: confirm at the prompt, or pass --yes".into(),
                ));
            }
            s.client.set_calibration(&new)?;
            let back = s.client.calibration()?;
            if back != new {
                return Err(RigError::Protocol(format!(
                    "the device stored a different calibration than sent on {}",
                    s.port()
                )));
            }
            if json {
                serde_json::to_writer_pretty(
                    &mut out,
                    &serde_json::json!({ "changed": changes, "written": true, "calibration": new }),
                )?;
                writeln!(out)?;
            } else {
                writeln!(out, "written and read back")?;
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `field: old -> new` for every field that differs.
fn diff(old: &protocol::RigParameters, new: &protocol::RigParameters) -> Vec<String> {
    let a = serde_json::to_value(old).unwrap_or_default();
    let b = serde_json::to_value(new).unwrap_or_default();
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return Vec::new();
    };
    a.iter()
        .filter(|(k, v)| b.get(*k) != Some(v))
        .map(|(k, v)| {
            format!(
                "{k}: {v} -> {}",
                b.get(k).unwrap_or(&serde_json::Value::Null)
            )
        })
        .collect()
}
