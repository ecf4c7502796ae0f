//! `rig capture`: a 10 kHz burst of raw current and encoder samples from the device's
//! buffer, checked for continuity, converted to amps and radians and written as CSV; the
//! output encoder, when fitted, rides along (read at a control step and held).

use std::fs::File;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Args;
use protocol::SupervisorState;
use serde::Serialize;

use super::connect::{Connection, DeviceOpts, interrupt_flag};
use crate::client::{CAPTURE_RATE_HZ, Capture};
use crate::{RigError, args, limits};

/// Arguments of `rig capture`.
#[derive(Debug, Args)]
pub struct CaptureArgs {
    /// Length of the burst, seconds (the device's buffer holds 10 000 samples, 1 s at
    /// 10 kHz: a longer burst is refused, naming the longest).
    #[arg(long, value_name = "S", default_value_t = 0.5, value_parser = args::positive, allow_hyphen_values = true)]
    seconds: f64,
    /// Write the samples to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Sample rate, Hz (the paper logged at 10 kHz): 10 kHz divided by a whole number, at
    /// least 100 (10000, 5000, 2500, 2000, 1250, 1000, ...).
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
    /// Mean output-shaft speed, rad/s (`null` without an output encoder).
    pub mean_output_speed_rad_s: Option<f64>,
    /// The CSV written.
    pub csv: Option<String>,
    /// What the device did differently from what was asked (fewer samples than
    /// `--seconds` asked for: its buffer is full at that).
    pub warnings: Vec<String>,
    /// The signal that stopped the burst (`Ctrl-C`, `SIGTERM`, ...; absent when it ran to
    /// its end): the gear was locked at once and the samples recorded until then are kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interrupted_by: Option<&'static str>,
}

/// Releases at `hz` and waits until the cam runs at speed (the supervisor says vibrating).
/// A signal (`stop`) during the spin-up locks the gear and ends it as an interruption.
fn spin_up(s: &mut Connection, hz: f32, stop: &AtomicBool) -> Result<(), RigError> {
    s.client.start_telemetry(20)?;
    s.client.release(true, hz)?;
    let deadline = Instant::now() + Duration::from_secs_f64(5.0 / s.time_scale() + 2.0);
    let result = loop {
        if stop.load(Ordering::SeqCst) {
            break Err(RigError::Operator(format!(
                "capture stopped by {} before the burst: the gear is locked, nothing recorded",
                crate::signals::interrupt_name()
            )));
        }
        if Instant::now() > deadline {
            break Err(RigError::Protocol(format!(
                "the cam did not reach {hz} Hz within 5 s on {}; check `rig faults`",
                s.port()
            )));
        }
        match s.client.next_telemetry(Duration::from_millis(20))? {
            Some(t) if t.state == SupervisorState::Vibrating => break Ok(()),
            Some(t) if t.state == SupervisorState::Fault || !t.faults.is_empty() => {
                break Err(RigError::DeviceFault {
                    what: "capture: the release failed".into(),
                    faults: t.faults,
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

/// Records the burst on the device (released at `--release` first, locked after).
/// A signal (`stop`) locks the gear at once; the samples recorded until the upload ends
/// are kept.
fn record(
    a: &CaptureArgs,
    dev: &DeviceOpts,
    samples: u32,
    stop: &AtomicBool,
) -> Result<Capture, RigError> {
    let mut s = dev.connect()?;
    let show = !a.json && std::io::stderr().is_terminal();
    if let Some(hz) = a.release {
        // The firmware would drive a frequency above the calibration's maximum at that maximum.
        let hz = limits::check_release_freq("--release", hz, &s.client.calibration()?)?;
        spin_up(&mut s, hz, stop)?;
    }
    if !a.json {
        // Said before the burst, so a person (and a test) knows the recording has begun.
        eprintln!(
            "recording {samples} samples at {} Hz; Ctrl-C locks the gear and keeps what was recorded",
            a.rate
        );
    }
    let captured = s.client.capture_until(
        a.rate,
        samples,
        |p| {
            if show {
                eprint!("\ruploading {} / {} samples", p.received, p.total);
            }
        },
        stop,
    );
    if a.release.is_some() {
        // Whatever ended the burst (its end, an error, a signal): the gear is locked.
        let locked = s.client.release(false, 0.0);
        let capture = captured?;
        locked?;
        if show {
            eprintln!();
        }
        return Ok(capture);
    }
    let capture = captured?;
    if show {
        eprintln!();
    }
    Ok(capture)
}

/// The number of samples `--seconds` at `--rate` asks for, or the error naming the range.
fn samples_asked(a: &CaptureArgs) -> Result<u32, RigError> {
    limits::check_capture_rate("--rate", a.rate)?;
    let rate = f64::from(a.rate);
    let samples = (a.seconds * rate).round();
    if samples < 1.0 {
        return Err(RigError::BadValue {
            what: format!("--seconds {}", a.seconds),
            why: format!(
                "shorter than one sample at {} Hz: give at least {} s",
                a.rate,
                1.0 / rate
            ),
        });
    }
    if samples > f64::from(limits::capture_capacity()) {
        return Err(RigError::BadValue {
            what: format!("--seconds {}", a.seconds),
            why: format!(
                "too long for one capture: the device's buffer holds {} samples ({} s at {} Hz); give at most that, or a lower --rate",
                limits::capture_capacity(),
                f64::from(limits::capture_capacity()) / rate,
                a.rate
            ),
        });
    }
    Ok(samples as u32)
}

/// What the device did differently from what was asked, one sentence each.
fn warnings(a: &CaptureArgs, c: &Capture) -> Vec<String> {
    let mut w = Vec::new();
    if c.total_samples < c.requested {
        w.push(format!(
            "the device recorded {} of the {} samples asked for (--seconds {}): its buffer holds {} samples, {} s at {} Hz",
            c.total_samples,
            c.requested,
            a.seconds,
            limits::capture_capacity(),
            f64::from(limits::capture_capacity()) / f64::from(c.sample_rate_hz.max(1)),
            c.sample_rate_hz
        ));
    }
    if c.sample_rate_hz != a.rate {
        w.push(format!(
            "the device recorded at {} Hz, not the {} Hz asked for (--rate): the CSV's t_s column uses {} Hz",
            c.sample_rate_hz, a.rate, c.sample_rate_hz
        ));
    }
    w
}

/// Records the capture; with `--csv`, atomically: the file is created (beside the target)
/// before the device records, so a bad path fails first, and an existing file is replaced
/// only by a full capture.
fn record_to_file(
    a: &CaptureArgs,
    dev: &DeviceOpts,
    samples: u32,
    stop: &AtomicBool,
) -> Result<Capture, RigError> {
    let Some(path) = &a.csv else {
        return record(a, dev, samples, stop);
    };
    let mut recorded = None;
    reporting::write_atomic_with(path, |tmp| -> Result<(), RigError> {
        let file = File::create(tmp).map_err(|source| RigError::File {
            action: "create",
            path: path.display().to_string(),
            source,
        })?;
        let capture = record(a, dev, samples, stop)?;
        capture
            .write_csv(std::io::BufWriter::new(file))
            .map_err(|e| RigError::MeasuredFile {
                file: path.display().to_string(),
                why: format!("cannot write the capture: {e}"),
            })?;
        recorded = Some(capture);
        Ok(())
    })?;
    recorded.ok_or_else(|| RigError::Protocol("the capture was not recorded".into()))
}

/// Prints the capture's summary as text.
fn print_text(out: &mut impl Write, report: &CaptureReport) -> Result<(), RigError> {
    let c = &report.capture;
    writeln!(
        out,
        "capture {}: {} samples at {} Hz ({} s), {} received",
        c.capture_id,
        c.total_samples,
        c.sample_rate_hz,
        reporting::human(report.duration_s),
        report.received
    )?;
    for w in &report.warnings {
        writeln!(out, "  warning: {w}")?;
    }
    if let (Some(i), Some(w)) = (report.mean_current_a, report.mean_cam_speed_rad_s) {
        writeln!(out, "  mean current {i:.3} A, mean cam speed {w:.2} rad/s")?;
    }
    if let Some(w) = report.mean_output_speed_rad_s {
        writeln!(out, "  mean output speed {w:.4} rad/s")?;
    }
    if let Some(p) = &report.csv {
        writeln!(out, "  written to {p}")?;
    }
    Ok(())
}

/// Runs `rig capture`.
pub fn run(a: CaptureArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let samples = samples_asked(&a)?;
    let stop = interrupt_flag();
    let capture = match record_to_file(&a, dev, samples, &stop) {
        // Stopped before the burst began: the gear is locked, there is nothing to keep.
        Err(e) if stop.load(Ordering::SeqCst) => {
            eprintln!("{e}");
            return Ok(crate::signals::interrupt_exit_code());
        }
        captured => captured?,
    };
    let interrupted = stop.load(Ordering::SeqCst);
    let report = CaptureReport {
        received: capture.samples.len(),
        duration_s: capture.duration_s(),
        mean_current_a: capture.mean_current_a(),
        mean_cam_speed_rad_s: capture.mean_cam_speed_rad_s(),
        mean_output_speed_rad_s: capture.mean_output_speed_rad_s(),
        csv: a.csv.as_ref().map(|p| p.display().to_string()),
        warnings: warnings(&a, &capture),
        interrupted_by: interrupted.then(crate::signals::interrupt_name),
        capture,
    };
    let c = &report.capture;
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &report)?;
    } else {
        print_text(&mut out, &report)?;
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
    if let Some(signal) = report.interrupted_by {
        eprintln!(
            "capture stopped by {signal}: the gear was locked at once; the {} samples recorded are kept",
            report.received
        );
        return Ok(crate::signals::interrupt_exit_code());
    }
    Ok(ExitCode::SUCCESS)
}
