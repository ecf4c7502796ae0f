//! `rig capture`: a 10 kHz burst of raw current and encoder samples from the device's
//! buffer, checked for continuity, converted to amps and radians and written as CSV.

use std::fs::File;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Args;
use protocol::SupervisorState;
use serde::Serialize;

use super::connect::{DeviceOpts, Session};
use crate::client::{CAPTURE_RATE_HZ, Capture};
use crate::{RigError, args};

/// Arguments of `rig capture`.
#[derive(Debug, Args)]
pub struct CaptureArgs {
    /// Length of the burst, seconds (the device's buffer holds 1 s at 10 kHz).
    #[arg(long, value_name = "S", default_value_t = 0.5, value_parser = args::positive, allow_hyphen_values = true)]
    seconds: f64,
    /// Write the samples to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Sample rate, Hz (the paper logged at 10 kHz; at least 100).
    #[arg(long, value_name = "HZ", default_value_t = CAPTURE_RATE_HZ, value_parser = clap::value_parser!(u16).range(100..))]
    rate: u16,
    /// Vibrate at this frequency (Hz) during the burst: released first, locked after.
    #[arg(long, value_name = "HZ", value_parser = args::positive, allow_hyphen_values = true)]
    release: Option<f64>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// What `rig capture` prints.
#[derive(Debug, Serialize)]
pub struct CaptureReport {
    /// The capture's bookkeeping.
    #[serde(flatten)]
    pub capture: Capture,
    /// Samples received.
    pub received: usize,
    /// Recording length, s.
    pub duration_s: f64,
    /// Mean current, A.
    pub mean_current_a: Option<f64>,
    /// Mean cam speed, rad/s.
    pub mean_cam_speed_rad_s: Option<f64>,
    /// The CSV written.
    pub csv: Option<String>,
}

/// Releases at `hz` and waits until the cam runs at speed (the supervisor says vibrating).
fn spin_up(s: &mut Session, hz: f64) -> Result<(), RigError> {
    s.client.start_telemetry(20)?;
    s.client.release(true, hz as f32)?;
    let deadline = Instant::now() + Duration::from_secs_f64(5.0 / s.time_scale() + 2.0);
    let result = loop {
        if Instant::now() > deadline {
            break Err(RigError::Protocol(format!(
                "the cam did not reach {hz} Hz within 5 s on {}; check `rig faults`",
                s.port()
            )));
        }
        match s.client.next_telemetry(Duration::from_millis(100))? {
            Some(t) if t.state == SupervisorState::Vibrating => break Ok(()),
            Some(t) if t.state == SupervisorState::Fault || !t.faults.is_empty() => {
                break Err(RigError::DeviceFault {
                    what: "capture: the release failed".into(),
                    faults: t.faults.to_string(),
                });
            }
            _ => {}
        }
    };
    s.client.stop_telemetry()?;
    if result.is_err() {
        let _ = s.client.release(false, 0.0);
    }
    result
}

/// Runs `rig capture`.
pub fn run(a: CaptureArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let samples = (a.seconds * f64::from(a.rate)).round().max(1.0);
    if samples > f64::from(u32::MAX) {
        return Err(RigError::BadValue {
            what: format!("--seconds {}", a.seconds),
            why: "too long for one capture: the device's buffer holds about 1 s".into(),
        });
    }
    // Create the file first, so a bad path fails before the device records anything.
    let file = match &a.csv {
        Some(path) => Some(File::create(path).map_err(|source| RigError::File {
            action: "create",
            path: path.display().to_string(),
            source,
        })?),
        None => None,
    };
    let mut s = dev.connect()?;
    let show = !a.json && std::io::stderr().is_terminal();
    if let Some(hz) = a.release {
        spin_up(&mut s, hz)?;
    }
    let captured = s.client.capture(a.rate, samples as u32, |p| {
        if show {
            eprint!("\ruploading {} / {} samples", p.received, p.total);
        }
    });
    if a.release.is_some() {
        s.client.release(false, 0.0)?;
    }
    let capture = captured?;
    if show {
        eprintln!();
    }
    if let (Some(file), Some(path)) = (file, &a.csv) {
        capture
            .write_csv(std::io::BufWriter::new(file))
            .map_err(|e| RigError::MeasuredFile {
                file: path.display().to_string(),
                why: format!("cannot write the capture: {e}"),
            })?;
    }
    let report = CaptureReport {
        received: capture.samples.len(),
        duration_s: capture.duration_s(),
        mean_current_a: capture.mean_current_a(),
        mean_cam_speed_rad_s: capture.mean_cam_speed_rad_s(),
        csv: a.csv.as_ref().map(|p| p.display().to_string()),
        capture,
    };
    let c = &report.capture;
    let mut out = std::io::stdout().lock();
    if a.json {
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        writeln!(
            out,
            "capture {}: {} samples at {} Hz ({:.3} s), {} received",
            c.capture_id, c.total_samples, c.sample_rate_hz, report.duration_s, report.received
        )?;
        if c.total_samples < c.requested {
            writeln!(
                out,
                "  the device recorded {} of the {} samples asked for (its buffer is full at that)",
                c.total_samples, c.requested
            )?;
        }
        if let (Some(i), Some(w)) = (report.mean_current_a, report.mean_cam_speed_rad_s) {
            writeln!(out, "  mean current {i:.3} A, mean cam speed {w:.2} rad/s")?;
        }
        if let Some(p) = &report.csv {
            writeln!(out, "  written to {p}")?;
        }
    }
    if c.dropped > 0 || c.duplicates > 0 || !c.completed {
        eprintln!(
            "warning: {} samples dropped in {} gap(s), {} duplicated{}: the CSV's index column shows where",
            c.dropped,
            c.gaps,
            c.duplicates,
            if c.completed {
                ""
            } else {
                ", and the upload never finished"
            }
        );
    } else if !a.json {
        writeln!(out, "  no samples dropped")?;
    }
    Ok(ExitCode::SUCCESS)
}
