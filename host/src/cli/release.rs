//! `rig release on|off`: vibrate the carrier (the gear becomes backdrivable) for as long
//! as the command runs, keeping the heartbeat; Ctrl-C (or `--for`) locks it again.

use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use protocol::SupervisorState;
use serde::Serialize;

use super::connect::{DeviceOpts, interrupt_flag};
use crate::connection::Connection;
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

/// What `rig release off --json` prints.
#[derive(Debug, Serialize)]
pub struct LockReport {
    /// Always false: vibration is off.
    pub released: bool,
    /// Supervisor state after the lock.
    pub state: &'static str,
    /// Whether the output still moves (null without an output encoder).
    pub output_moving: Option<bool>,
    /// Whether the gear coasts after the vibration stops (mu_d Lambda < 1).
    pub coasts_after_stop: bool,
}

/// Runs `rig release`.
pub fn run(a: ReleaseArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let stop = interrupt_flag();
    let mut s = dev.connect()?;
    let mut out = std::io::stdout().lock();
    if a.state == OnOff::Off {
        return lock(&a, &mut s, &mut out);
    }
    // The firmware would drive a frequency above the calibration's maximum at that maximum.
    let target_hz = limits::check_release_freq("--freq", a.freq, &s.client.calibration()?)?;
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
    let mut held = Held::default();
    // Whatever ends the hold (a signal, a fault, a terminal gone: writing to it fails),
    // the gear is locked before anything else.
    let watched = hold(&a, &mut s, &stop, &mut held, &mut out);
    let locked = s.client.release(false, 0.0);
    watched?;
    locked?;
    let report = held.report(&a, come_to_rest(&mut s)?);
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
            faults: held.faults,
        });
    }
    // Stopped by SIGTERM, SIGHUP or Ctrl-C: 128 + the signal's number.
    Ok(crate::signals::exit_code())
}

/// `rig release off`: locks and reports how the output behaves after.
fn lock(a: &ReleaseArgs, s: &mut Connection, out: &mut impl Write) -> Result<ExitCode, RigError> {
    s.client.release(false, 0.0)?;
    let scale = s.time_scale();
    let after = after_lock(&mut s.client, scale)?;
    if a.json {
        let report = LockReport {
            released: false,
            state: after.state.name(),
            output_moving: after.output_moving,
            coasts_after_stop: after.coasts,
        };
        super::print_json_line(out, &report)?;
    } else {
        writeln!(out, "vibration off: {}", after.verdict())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What a hold saw.
#[derive(Debug, Default)]
struct Held {
    /// Device seconds held.
    held_s: f64,
    /// Supervisor states in the order seen.
    states: Vec<&'static str>,
    /// Sum and count of the cam frequency while vibrating.
    hz_sum: f64,
    hz_n: u32,
    /// Why it ended (`for`, `fault`; None: an interrupt).
    ended_by: Option<&'static str>,
    /// Faults seen (active and latched).
    faults: protocol::FaultFlags,
}

impl Held {
    /// The report of this hold, ending in `final_state`.
    fn report(&self, a: &ReleaseArgs, final_state: SupervisorState) -> ReleaseReport {
        let ended_by = self.ended_by.unwrap_or("interrupt");
        ReleaseReport {
            freq_hz: a.freq,
            held_s: self.held_s,
            states: self.states.clone(),
            mean_vibrating_hz: (self.hz_n > 0).then(|| self.hz_sum / f64::from(self.hz_n)),
            final_state: final_state.name(),
            ended_by,
            faults: self.faults.names().collect(),
            signal: (ended_by == "interrupt").then(crate::signals::interrupt_name),
        }
    }
}

/// Holds the release until `--for` passes, a fault or a signal, recording into `held`.
fn hold(
    a: &ReleaseArgs,
    s: &mut Connection,
    stop: &AtomicBool,
    held: &mut Held,
    out: &mut impl Write,
) -> Result<(), RigError> {
    let scale = s.time_scale();
    let wall_start = Instant::now();
    let mut t0 = None;
    while !stop.load(Ordering::SeqCst) {
        if let Some(limit) = a.hold_for {
            // A bound in wall time too, in case telemetry stops.
            if wall_start.elapsed().as_secs_f64() > limit / scale + 5.0 {
                held.ended_by = Some("for");
                break;
            }
        }
        // Short waits: a signal locks the gear within one of them.
        let Some(t) = s.client.next_telemetry(Duration::from_millis(20))? else {
            continue;
        };
        let start = *t0.get_or_insert(t.device_time_us);
        let since = (t.device_time_us - start) as f64 / 1e6;
        held.held_s = since;
        if held.states.last() != Some(&t.state.name()) {
            held.states.push(t.state.name());
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
            held.hz_sum += f64::from(t.cam_speed_rad_s.abs()) / std::f64::consts::TAU;
            held.hz_n += 1;
        }
        if !t.faults.is_empty() || t.state == SupervisorState::Fault {
            let latched = s.client.faults().map(|f| f.latched).unwrap_or(t.faults);
            held.faults = t.faults | latched;
            held.ended_by = Some("fault");
            break;
        }
        if a.hold_for.is_some_and(|limit| since >= limit) {
            held.ended_by = Some("for");
            break;
        }
    }
    Ok(())
}

/// Watches the cam come to rest after the lock (a few device seconds at most); the state
/// it ends in.
fn come_to_rest(s: &mut Connection) -> Result<SupervisorState, RigError> {
    let scale = s.time_scale();
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
    Ok(final_state)
}

/// What the device reports once a release ends: whether the gear holds what hangs on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AfterLock {
    /// The supervisor state at the end of the watch.
    pub state: SupervisorState,
    /// Whether the output shaft turned in the last samples (`None`: no output encoder).
    pub output_moving: Option<bool>,
    /// The gear set keeps moving once moving (mu_d Lambda < 1, `COASTS_AFTER_STOP`).
    pub coasts: bool,
}

impl AfterLock {
    /// One clause for the user; never "holds" while the output moves or is not measured
    /// on a gear set that coasts.
    pub fn verdict(&self) -> String {
        let state = self.state.name();
        match (self.output_moving, self.coasts) {
            (Some(true), _) => format!(
                "the output is still moving (state {state}){}: the gear does not hold it yet; keep clear of the load",
                if self.coasts {
                    ", as this gear set coasts after a stop (mu_d Lambda < 1)"
                } else {
                    ""
                }
            ),
            (Some(false), _) if self.state == SupervisorState::Locked => {
                "the gear holds its load (output at rest)".into()
            }
            (Some(false), _) => format!("the output is at rest (state {state})"),
            (None, true) => format!(
                "state {state}; this gear set coasts after a stop (mu_d Lambda < 1), so a moving load may keep moving (the board measures no output shaft)"
            ),
            (None, false) => format!("state {state} (the board measures no output shaft)"),
        }
    }
}

/// Watches telemetry after a lock: waits (up to 3 device seconds) for the cam to stop,
/// then reads the output's motion over 0.2 device seconds.
pub fn after_lock<T: std::io::Read + std::io::Write>(
    client: &mut crate::client::Client<T>,
    scale: f64,
) -> Result<AfterLock, RigError> {
    use protocol::StatusFlags;
    client.start_telemetry(TELEMETRY_HZ)?;
    let mut last = None;
    let mut locked_at = None;
    let mut moving = false;
    let deadline = Instant::now() + Duration::from_secs_f64(3.2 / scale.max(1e-3) + 1.0);
    while Instant::now() < deadline {
        let Some(t) = client.next_telemetry(Duration::from_millis(100))? else {
            continue;
        };
        last = Some(t);
        if !matches!(t.state, SupervisorState::Locked | SupervisorState::Fault) {
            locked_at = None;
            moving = false;
            continue;
        }
        let start = *locked_at.get_or_insert(t.device_time_us);
        moving |= t.status.contains(StatusFlags::OUTPUT_MOVING);
        if t.device_time_us.saturating_sub(start) >= 200_000 {
            break;
        }
    }
    let _ = client.stop_telemetry();
    let Some(t) = last else {
        return Err(RigError::Protocol(format!(
            "{} sent no telemetry after the lock: check the link (`rig info`), then `rig faults`",
            client.options().port_name
        )));
    };
    let encoder = t.output_speed_rad_s.is_finite();
    Ok(AfterLock {
        state: t.state,
        output_moving: encoder.then_some(moving || t.status.contains(StatusFlags::OUTPUT_MOVING)),
        coasts: t.status.contains(StatusFlags::COASTS_AFTER_STOP),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// "The gear holds" only with the output measured at rest and the gear locked.
    #[test]
    fn the_verdict_never_says_holds_while_the_output_moves_or_is_unmeasured() {
        let states = [
            SupervisorState::Locked,
            SupervisorState::Stopping,
            SupervisorState::Fault,
        ];
        for state in states {
            for output_moving in [Some(true), Some(false), None] {
                for coasts in [true, false] {
                    let v = AfterLock {
                        state,
                        output_moving,
                        coasts,
                    }
                    .verdict();
                    let holds = v.contains("holds");
                    assert_eq!(
                        holds,
                        output_moving == Some(false) && state == SupervisorState::Locked,
                        "{v}"
                    );
                    if output_moving == Some(true) {
                        assert!(v.contains("still moving"), "{v}");
                    }
                    if output_moving.is_none() && coasts {
                        assert!(v.contains("coasts"), "{v}");
                    }
                }
            }
        }
    }
}
