//! `rig release on|off`: vibrate the carrier (the gear becomes backdrivable) for as long
//! as the command runs, keeping the heartbeat; Ctrl-C (or `--for`) locks it again.

use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use protocol::SupervisorState;
use serde::Serialize;

use super::connect::{DeviceOpts, interrupt_flag};
use crate::{RigError, args, limits};

/// On or off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    /// Vibrate: the gear becomes backdrivable and a load on the output can move.
    On,
    /// Stop vibrating: the gear holds its load again.
    Off,
}

/// Arguments of `rig release`.
#[derive(Debug, Args)]
pub struct ReleaseArgs {
    /// `on` to vibrate (the load can move!), `off` to stop.
    #[arg(value_enum)]
    state: OnOff,
    /// Vibration (cam) frequency, Hz; the paper used 5, 10 and 15. At most the
    /// calibration's max_freq_hz (15 Hz for the paper's): a higher one is refused.
    #[arg(long, value_name = "HZ", default_value_t = 10.0, value_parser = args::positive, allow_hyphen_values = true)]
    freq: f64,
    /// Hold the release for this many (device) seconds, then lock; default: until Ctrl-C.
    #[arg(long = "for", value_name = "SECONDS", value_parser = args::positive, allow_hyphen_values = true)]
    hold_for: Option<f64>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// What `rig release on --json` prints.
#[derive(Debug, Serialize)]
pub struct ReleaseReport {
    /// Requested vibration frequency, Hz.
    pub freq_hz: f64,
    /// Device time the release was held, s.
    pub held_s: f64,
    /// Supervisor states in the order seen.
    pub states: Vec<&'static str>,
    /// Mean cam frequency while vibrating, Hz.
    pub mean_vibrating_hz: Option<f64>,
    /// State after locking.
    pub final_state: &'static str,
    /// Why the hold ended: `for`, `interrupt` or `fault`.
    pub ended_by: &'static str,
    /// Faults seen during the hold.
    pub faults: Vec<&'static str>,
    /// The signal that ended an `interrupt`: `Ctrl-C`, `SIGTERM` or `SIGHUP (the terminal
    /// closed)`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signal: Option<&'static str>,
}

/// Telemetry rate while holding, Hz.
const TELEMETRY_HZ: u16 = 20;

/// Runs `rig release`.
pub fn run(a: ReleaseArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let stop = interrupt_flag();
    let mut s = dev.connect()?;
    let mut out = std::io::stdout().lock();
    if a.state == OnOff::Off {
        s.client.release(false, 0.0)?;
        if a.json {
            super::print_json_line(&mut out, &serde_json::json!({ "released": false }))?;
        } else {
            writeln!(out, "vibration off: the gear holds its load")?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    // The firmware would drive a frequency above the calibration's maximum at that maximum.
    let target_hz = limits::check_release_freq("--freq", a.freq, &s.client.calibration()?)?;
    let scale = s.time_scale();
    s.client.start_telemetry(TELEMETRY_HZ)?;
    s.client.release(true, target_hz)?;
    if !a.json {
        let until = match a.hold_for {
            Some(t) => format!("for {t} s"),
            None => "until Ctrl-C".into(),
        };
        writeln!(
            out,
            "released at {} Hz {until}: the gear is backdrivable, a load on the output can move",
            a.freq
        )?;
    }
    let mut report = ReleaseReport {
        freq_hz: a.freq,
        held_s: 0.0,
        states: Vec::new(),
        mean_vibrating_hz: None,
        final_state: "",
        ended_by: "interrupt",
        faults: Vec::new(),
        signal: None,
    };
    let wall_start = Instant::now();
    let mut t0 = None;
    let (mut hz_sum, mut hz_n) = (0.0, 0u32);
    // Whatever ends the loop (a signal, a fault, a terminal gone: writing to it fails),
    // the gear is locked before anything else.
    let watched = (|| -> Result<(), RigError> {
        loop {
            if stop.load(Ordering::SeqCst) {
                break;
            }
            if let Some(limit) = a.hold_for {
                // A bound in wall time too, in case telemetry stops.
                if wall_start.elapsed().as_secs_f64() > limit / scale + 5.0 {
                    report.ended_by = "for";
                    break;
                }
            }
            let Some(t) = s.client.next_telemetry(Duration::from_millis(100))? else {
                continue;
            };
            let start = *t0.get_or_insert(t.device_time_us);
            let since = (t.device_time_us - start) as f64 / 1e6;
            report.held_s = since;
            if report.states.last() != Some(&t.state.name()) {
                report.states.push(t.state.name());
                if !a.json {
                    writeln!(
                        out,
                        "{since:7.2} s  {:<10} cam {:5.1} Hz  current {:5.2} A",
                        t.state.name(),
                        t.cam_speed_rad_s.abs() / std::f32::consts::TAU,
                        t.current_a
                    )?;
                }
            }
            if t.state == SupervisorState::Vibrating {
                hz_sum += f64::from(t.cam_speed_rad_s.abs()) / std::f64::consts::TAU;
                hz_n += 1;
            }
            if !t.faults.is_empty() || t.state == SupervisorState::Fault {
                let latched = s.client.faults().map(|f| f.latched).unwrap_or(t.faults);
                report.faults = (t.faults | latched).names().collect();
                report.ended_by = "fault";
                break;
            }
            if a.hold_for.is_some_and(|limit| since >= limit) {
                report.ended_by = "for";
                break;
            }
        }
        Ok(())
    })();
    let locked = s.client.release(false, 0.0);
    watched?;
    locked?;
    if report.ended_by == "interrupt" {
        report.signal = Some(crate::signals::interrupt_name());
    }
    // Watch the cam come to rest (a few device seconds at most).
    let mut final_state = SupervisorState::Stopping;
    let deadline = Instant::now() + Duration::from_secs_f64(3.0 / scale + 1.0);
    while Instant::now() < deadline {
        if let Some(t) = s.client.next_telemetry(Duration::from_millis(100))? {
            final_state = t.state;
            if matches!(t.state, SupervisorState::Locked | SupervisorState::Fault) {
                break;
            }
        }
    }
    let _ = s.client.stop_telemetry();
    report.final_state = final_state.name();
    report.mean_vibrating_hz = (hz_n > 0).then(|| hz_sum / f64::from(hz_n));
    if a.json {
        super::print_json(&mut out, &report)?;
    } else {
        let mean = report
            .mean_vibrating_hz
            .map(|hz| format!(", mean {hz:.2} Hz while vibrating"))
            .unwrap_or_default();
        let by = report.signal.map(|s| format!(" ({s})")).unwrap_or_default();
        // The terminal may be gone (SIGHUP): the gear is locked whether this prints or not.
        let _ = writeln!(
            out,
            "locked after {:.2} s{by}{mean}; state now {}",
            report.held_s, report.final_state
        );
    }
    if report.ended_by == "fault" {
        return Err(RigError::DeviceFault {
            what: "release ended".into(),
            faults: report.faults.join(" | "),
        });
    }
    Ok(ExitCode::SUCCESS)
}
