//! `rig calibration get|set`: read the device's calibration record into a rig file
//! (`docs/rig-file.md`), or send a rig file's record to the device (checked first: a bad
//! file changes nothing). The older flat calibration file is read too.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Subcommand};
use serde::Serialize;

use super::connect::{DeviceOpts, confirm};
use crate::RigError;
use crate::calibrate::file::{self, Target};
use rigfile::{FileFormat, Loaded};

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
    /// Print the device's calibration as a rig file (TOML), or write it to FILE.
    Get {
        /// Write it here instead of printing it (a rig file already there keeps what the device does not carry: [model], the calibration temperature, other sections).
        file: Option<PathBuf>,
        /// Print JSON instead of TOML.
        #[arg(long)]
        json: bool,
    },
    /// Write the calibration record in rig file FILE to the device: C1-C6, gear, cam,
    /// friction and limits; keys left out take the paper's values (listed before writing).
    Set {
        /// The rig file (docs/rig-file.md; `rig calibration get FILE` writes an example), or an older calibration file.
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
        CalibrationAction::Get { file, json } => get(file, json, dev),
        CalibrationAction::Set { file, yes, json } => set(&file, yes, json, dev),
    }
}

/// What `rig calibration set --json` prints.
#[derive(Debug, Serialize)]
pub struct SetReport {
    /// The changes, one line each (`c1: 62.1 -> 63.0`).
    pub changed: Vec<String>,
    /// Whether the calibration was written (and read back).
    pub written: bool,
    /// The calibration written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<protocol::RigParameters>,
    /// The device's fields the file left out (the paper's values were used).
    pub defaulted: Vec<&'static str>,
}

/// `rig calibration get`: the device's calibration as JSON, to a rig file, or printed.
fn get(path: Option<PathBuf>, json: bool, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut s = dev.connect()?;
    let cal = s.client.calibration()?;
    let mut out = std::io::stdout().lock();
    if json {
        serde_json::to_writer_pretty(&mut out, &cal)?;
        writeln!(out)?;
        return Ok(ExitCode::SUCCESS);
    }
    let comment = format!("Calibration read from the device on {}.", s.port());
    match path {
        Some(p) => {
            let (rig, target) = file::for_record(&cal, Some(&p));
            rig.save_with_comment(&p, &comment)?;
            match target {
                Target::New => writeln!(out, "wrote {}", p.display())?,
                Target::Updated => writeln!(
                    out,
                    "wrote {} (updated: what the device does not carry is kept)",
                    p.display()
                )?,
                Target::Replaced { why } => writeln!(
                    out,
                    "wrote {} (replaced a file that was not a rig file: {why})",
                    p.display()
                )?,
            }
        }
        None => write!(
            out,
            "{}",
            file::for_record(&cal, None)
                .0
                .to_toml_with_comment(&comment)?
        )?,
    }
    Ok(ExitCode::SUCCESS)
}

/// `rig calibration set`: a rig file's calibration to the device, after showing the changes.
fn set(path: &Path, yes: bool, json: bool, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    // A file that cannot be used is refused before the device is opened.
    let loaded = file::read(path)?;
    let new = loaded.rig.to_wire()?;
    board_precheck(&new, path)?;
    let defaulted = loaded.defaulted();
    let defaulted_fields: Vec<&str> = defaulted.iter().filter_map(|k| k.wire).collect();
    let mut s = dev.connect()?;
    let current = s.client.calibration()?;
    let changes: Vec<String> = diff(&current, &new);
    let mut out = std::io::stdout().lock();
    if !json && !defaulted.is_empty() {
        writeln!(
            out,
            "not in {}, so the paper's values (docs/rig-file.md):",
            path.display()
        )?;
        for line in defaulted_lines(&loaded) {
            writeln!(out, "  {line}")?;
        }
    }
    if changes.is_empty() {
        if json {
            let report = SetReport {
                changed: Vec::new(),
                written: false,
                calibration: None,
                defaulted: defaulted_fields,
            };
            writeln!(out, "{}", serde_json::to_string(&report)?)?;
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
    super::calibrate::store(&mut s, &new)?;
    if json {
        let report = SetReport {
            changed: changes,
            written: true,
            calibration: Some(new),
            defaulted: defaulted_fields,
        };
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        writeln!(out, "written and read back")?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The firmware's own rule for a new record (`firmware_core::check_rules`: the model's
/// [`model::BoardLimits::check`] against the board's caps and [`model::Calibration::check`]
/// against its motor), run before the device is opened, so a limit the board cannot honour
/// or constants 36 times off Table 2 are refused here with the field named (the device
/// refuses them too).
fn board_precheck(
    record: &protocol::RigParameters,
    path: &std::path::Path,
) -> Result<(), RigError> {
    let config = firmware_core::CoreConfig::default();
    let (caps, motor) = (config.board_limits(), *config.motor.constants());
    let Err(rejection) = firmware_core::check_rules(record, &caps, &motor) else {
        return Ok(());
    };
    // The model's own wording: the value, the cap or plausible range, in the file's units.
    let requested = model::BoardLimits {
        max_release_load_nm: f64::from(record.max_release_load_nm),
        max_current_a: f64::from(record.max_current_a),
        max_freq_hz: f64::from(record.max_freq_hz),
    };
    let detail = match caps.check(&requested) {
        Err(issue) => issue.to_string(),
        Ok(()) => match model::Calibration::from_paper_units(record.constants()).check(&motor) {
            Err(issue) => format!("{} ({issue})", rejection.field.name()),
            Ok(()) => format!("{} {}", rejection.field.name(), rejection.reason.describe()),
        },
    };
    Err(RigError::CalibrationFile {
        file: path.display().to_string(),
        why: format!("{detail}; the board's firmware refuses it"),
    })
}

/// The keys `loaded` left at their defaults, one line per section, named as the file names
/// them (`[gear] z = [49, 51, 50, 50], module_mm = 1.0`; flat keys for the older file).
fn defaulted_lines(loaded: &Loaded) -> Vec<String> {
    let flat = loaded.format == FileFormat::CalibrationFile;
    let mut lines: Vec<(&str, Vec<String>)> = Vec::new();
    for k in loaded.defaulted() {
        let name = match k.wire {
            Some(wire) if flat => wire,
            _ => k.key,
        };
        let item = format!("{name} = {}", k.default);
        match lines.last_mut() {
            Some((section, items)) if *section == k.section => items.push(item),
            _ => lines.push((k.section, vec![item])),
        }
    }
    lines
        .into_iter()
        .map(|(section, items)| {
            if flat {
                items.join(", ")
            } else {
                format!("[{section}] {}", items.join(", "))
            }
        })
        .collect()
}

/// `field: old -> new` for every field that differs (numbers as a person writes them).
fn diff(old: &protocol::RigParameters, new: &protocol::RigParameters) -> Vec<String> {
    let a = reporting::human_json(serde_json::to_value(old).unwrap_or_default());
    let b = reporting::human_json(serde_json::to_value(new).unwrap_or_default());
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
