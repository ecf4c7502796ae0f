//! `rig bringup`: the guided first power-up of a board, in the style of odrivetool's and
//! VESC Tool's setup checks. Each step checks one thing the rig needs before a
//! measurement, says pass or fail with what it saw, and on a failure what to check. The
//! steps run in order and stop at the first failure (a later step would drive the motor
//! on a board that is not ready for it).
//!
//! The person's part (remove the load, block the cam, hang a small weight) is a
//! [`Hands`]: the operator at a real rig (prompts on stderr), or the virtual rig's plant.
//! docs/bench.md is the bench guide around it: parts, wiring, mechanical set-up, and what
//! only hardware can confirm.

use std::time::{Duration, Instant};

use model::plant::CamSetup;
use protocol::{
    Capabilities, DeviceMessage, FaultFlags, HealthSample, ParametersStatus, SupervisorState,
    TelemetrySample,
};
use serde::Serialize;

use crate::RigError;
use crate::connection::Connection;
use crate::experiment::bench::{Go, MOTION_RAD, Operator};
use crate::virtual_device::VirtualDevice;

/// The steps, in the order they run.
pub const STEPS: [&str; 8] = [
    "identity",
    "faults",
    "bus_voltage",
    "current_zero",
    "encoder",
    "output_encoder",
    "overcurrent_trip",
    "first_release",
];

/// Telemetry rate during the checks, Hz.
const TELEMETRY_HZ: u16 = 100;
/// The bus may differ from the bench supply's nominal by this fraction (a bench supply set
/// to 12 V, its leads' drop under a stalled motor, the divider's 1 % resistors).
pub const BUS_TOLERANCE: f64 = 0.10;
/// Largest mean current with the motor off after the firmware's zeroing, A: 0.1 A is
/// 18.5 mV of the ACS714 (its total output error at 25 deg C is about 1.5 % of 5 A).
pub const ZERO_TOLERANCE_A: f64 = 0.1;
/// Open-loop drive of the encoder check, V: the cam turns slowly (about 2 Hz no-load).
pub const ENCODER_CHECK_V: f64 = 2.0;
/// Open-loop drive of the virtual rig's overcurrent trip test, V: the cam spins at about
/// 10 Hz, then jams, and the current jumps to about 14 A (V / R) within the winding's
/// 0.45 ms, past the comparator's 6 A (`model::hardware::comparator::TRIP_A`) before the
/// firmware's 1 ms software limit (4.8 A) acts. A stalled start cannot show the trip: the
/// firmware slews the duty, so the current rises slowly and the software limit comes first.
pub const TRIP_TEST_V: f64 = 6.2;
/// How long a real rig's trip test watches for the operator's test current, s.
pub const TRIP_WATCH_S: f64 = 10.0;
/// Release frequency of the first release, Hz (the paper's lowest).
pub const FIRST_RELEASE_HZ: f64 = 5.0;
/// Load hung for the output-encoder check, N m: Fig. 5's 1.0 kg on the 75 mm pulley,
/// which the paper saw fall once released at 3.6 V (about 5 Hz); a lighter one can stay put
/// on the linear bush's friction (the paper's 0.368 N m at 3.6 and 6.2 V).
pub const OUTPUT_CHECK_LOAD_NM: f64 = 0.735_498_75;
/// How long the output-encoder check releases, s.
pub const OUTPUT_CHECK_RELEASE_S: f64 = 2.5;

/// A step's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// The check passed.
    Pass,
    /// The check failed: see `check`.
    Fail,
    /// Nothing to check on this board (a part not fitted, a sensor not reported).
    Skip,
    /// Not run: an earlier step failed.
    NotRun,
}

/// One step of the bring-up.
#[derive(Debug, Clone, Serialize)]
pub struct Step {
    /// The step's name ([`STEPS`]).
    pub name: &'static str,
    /// Its outcome.
    pub status: Status,
    /// What was measured or seen.
    pub detail: String,
    /// What to check when it fails (empty when it passed).
    pub check: String,
}

/// Everything `rig bringup` found.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// True when no step failed.
    pub passed: bool,
    /// The steps, in order.
    pub steps: Vec<Step>,
}

/// A fault to build into the virtual rig before the bring-up (`--inject`), to rehearse a
/// failed step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Injection {
    /// Encoder channels A and B swapped (or the motor wired backwards).
    ReversedEncoder,
    /// The encoder cable cut: the count never changes.
    FrozenEncoder,
    /// The current sensor's output stuck (a tripped or dead sensor): the reading never
    /// changes, about 1.5 A off its zero.
    StuckCurrentSensor,
}

impl Injection {
    /// Builds the fault into `device`'s rig.
    pub fn apply(self, device: &VirtualDevice) {
        let injections = match self {
            Injection::ReversedEncoder => sim::Injections {
                encoder_reversed: true,
                ..Default::default()
            },
            Injection::FrozenEncoder => sim::Injections {
                encoder_frozen: true,
                ..Default::default()
            },
            Injection::StuckCurrentSensor => sim::Injections {
                // The zero (2.5 V through the 2/3 divider) is about 2070 counts; 153 per A.
                current_adc_stuck: Some(2300),
                ..Default::default()
            },
        };
        device.with_rig(|r| r.inject(injections));
    }
}

/// The person's part of the bring-up.
pub trait Hands {
    /// Asks for `action` (or does it on a virtual rig); false when the person skips it.
    fn set_up(&mut self, action: Action) -> Result<bool, RigError>;
    /// Whether the rig is the virtual one (its cam can be jammed at speed safely).
    fn virtual_rig(&self) -> bool;
}

/// What the person does between checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// No load on the output, the cam coupled to the carrier.
    NoLoad,
    /// Hang a small load (N m) on the output pulley.
    HangLoad(f64),
    /// Jam the spinning cam (the virtual rig only: at a real rig that is no job for hands).
    JamCam,
    /// Free the cam shaft again.
    FreeCam,
    /// Pass a test current through the current sensor (a real rig's trip test).
    TestCurrent,
}

impl Action {
    /// The instruction for a person.
    pub fn instruction(self) -> String {
        match self {
            Action::NoLoad => {
                "Remove every load from the output and couple the cam to the carrier".into()
            }
            Action::HangLoad(nm) => format!(
                "Hang {} (the gear will be released for {} s and the load falls: keep clear)",
                crate::experiment::load_text(nm),
                reporting::human(OUTPUT_CHECK_RELEASE_S)
            ),
            Action::JamCam => {
                "Jam the spinning cam (rehearsal on the virtual rig: a real rig's trip test uses a test current)".into()
            }
            Action::FreeCam => "Free the cam shaft: it turns freely again".into(),
            Action::TestCurrent => format!(
                "Trip test: disconnect the motor from the bridge; after Enter, within {} s, pass a test current of 7-8 A through the ACS714 (IP+ to IP-) from a second, current-limited supply for under a second",
                reporting::human(TRIP_WATCH_S)
            ),
        }
    }
}

/// The virtual rig's hands: the set-up happens in its plant.
pub struct VirtualHands<'a>(pub &'a VirtualDevice);

impl Hands for VirtualHands<'_> {
    fn set_up(&mut self, action: Action) -> Result<bool, RigError> {
        self.0.with_plant(|p| match action {
            Action::NoLoad => {
                p.set_load(model::plant::Load::Torque(0.0));
                p.set_cam(CamSetup::Coupled);
            }
            Action::HangLoad(nm) => p.set_load(model::plant::Load::Torque(nm)),
            Action::JamCam => p.set_cam(CamSetup::Blocked),
            Action::FreeCam => p.set_cam(CamSetup::Coupled),
            // The virtual rig has no second supply: its trip test jams the cam instead.
            Action::TestCurrent => {}
        });
        Ok(true)
    }

    fn virtual_rig(&self) -> bool {
        true
    }
}

/// A person at the rig: the instruction on stderr, Enter when done (`s` skips the step).
/// With a virtual device (`--operator` on `--sim`) the set-up also happens in its plant.
pub struct OperatorHands<'a> {
    /// The person.
    pub operator: Operator,
    /// The virtual rig rehearsed on, if any.
    pub device: Option<&'a VirtualDevice>,
}

impl Hands for OperatorHands<'_> {
    fn set_up(&mut self, action: Action) -> Result<bool, RigError> {
        let go = self.operator.before(&action.instruction())?;
        if go == Go::Run
            && let Some(d) = self.device
        {
            VirtualHands(d).set_up(action)?;
        }
        Ok(go == Go::Run)
    }

    fn virtual_rig(&self) -> bool {
        self.device.is_some()
    }
}

/// What the telemetry showed over a window.
#[derive(Debug, Default)]
struct Window {
    samples: Vec<TelemetrySample>,
    health: Option<HealthSample>,
}

impl Window {
    fn faults(&self) -> FaultFlags {
        self.samples
            .iter()
            .fold(FaultFlags::empty(), |f, t| f | t.faults)
    }

    fn mean(&self, value: impl Fn(&TelemetrySample) -> f32) -> Option<f64> {
        let n = self.samples.len();
        (n > 0).then(|| {
            self.samples
                .iter()
                .map(|t| f64::from(value(t)))
                .sum::<f64>()
                / n as f64
        })
    }
}

/// Reads telemetry for `seconds` of device time (and the health report that comes with
/// it), servicing heartbeats; stops early when `done` says so.
fn watch(
    session: &mut Connection,
    seconds: f64,
    done: impl Fn(&Window) -> bool,
) -> Result<Window, RigError> {
    let scale = session.time_scale().max(1e-9);
    let deadline = Instant::now() + Duration::from_secs_f64(seconds / scale + 2.0);
    let mut w = Window::default();
    let mut first = None;
    while Instant::now() < deadline {
        match session.client.recv(Duration::from_millis(50))? {
            Some(DeviceMessage::Telemetry(t)) => {
                let start = *first.get_or_insert(t.device_time_us);
                let elapsed = t.device_time_us.saturating_sub(start) as f64 * 1e-6;
                w.samples.push(t);
                if elapsed >= seconds || done(&w) {
                    return Ok(w);
                }
            }
            Some(DeviceMessage::Health(h)) => w.health = Some(h),
            _ => {}
        }
    }
    if w.samples.is_empty() {
        return Err(RigError::Protocol(format!(
            "no telemetry from {} during the bring-up: check the link (`rig info`)",
            session.port()
        )));
    }
    Ok(w)
}

/// Runs the bring-up on `session` with `hands`; `progress` gets a line per step.
pub fn run(
    session: &mut Connection,
    hands: &mut dyn Hands,
    progress: &mut dyn FnMut(&Step),
) -> Result<Report, RigError> {
    let mut steps: Vec<Step> = Vec::new();
    session.client.start_telemetry(TELEMETRY_HZ)?;
    let result = (|| -> Result<(), RigError> {
        for name in STEPS {
            let step = run_step(name, session, hands)?;
            progress(&step);
            let failed = step.status == Status::Fail;
            steps.push(step);
            if failed {
                break;
            }
        }
        Ok(())
    })();
    // Whatever happened: drive off, gear locked.
    let _ = session.client.open_loop(0.0);
    let _ = session.client.release(false, 0.0);
    let _ = session.client.stop_telemetry();
    result?;
    let failed_at = steps.len();
    for &name in STEPS.iter().skip(failed_at) {
        steps.push(Step {
            name,
            status: Status::NotRun,
            detail: format!("not run: step {} failed", steps[failed_at - 1].name),
            check: String::new(),
        });
    }
    Ok(Report {
        passed: steps.iter().all(|s| s.status != Status::Fail),
        steps,
    })
}

fn step(name: &'static str, ok: bool, detail: String, check: &str) -> Step {
    Step {
        name,
        status: if ok { Status::Pass } else { Status::Fail },
        detail,
        check: if ok { String::new() } else { check.into() },
    }
}

fn skip(name: &'static str, detail: String) -> Step {
    Step {
        name,
        status: Status::Skip,
        detail,
        check: String::new(),
    }
}

fn run_step(
    name: &'static str,
    session: &mut Connection,
    hands: &mut dyn Hands,
) -> Result<Step, RigError> {
    match name {
        "identity" => identity(session),
        "faults" => faults(session),
        "bus_voltage" => bus_voltage(session),
        "current_zero" => current_zero(session),
        "encoder" => encoder(session, hands),
        "output_encoder" => output_encoder(session, hands),
        "overcurrent_trip" => overcurrent_trip(session, hands),
        _ => first_release(session, hands),
    }
}

fn identity(session: &mut Connection) -> Result<Step, RigError> {
    let info = session.client.info()?;
    let detail = format!(
        "firmware {}, calibration {}",
        crate::provenance::identity(&info),
        info.parameters_status.name()
    );
    let ok = info.parameters_status != ParametersStatus::Invalid;
    Ok(step(
        "identity",
        ok,
        detail,
        "the stored calibration failed its check and the paper's defaults are in use: write a rig file with `rig calibration set FILE` (or run `rig calibrate`)",
    ))
}

fn faults(session: &mut Connection) -> Result<Step, RigError> {
    let status = session.client.faults()?;
    let all = status.active | status.latched;
    Ok(step(
        "faults",
        all.is_empty(),
        if all.is_empty() {
            "no fault active or latched".into()
        } else {
            format!("faults: {all}")
        },
        "`rig faults` names each fault and what to do; fix the cause, then `rig clear`",
    ))
}

fn bus_voltage(session: &mut Connection) -> Result<Step, RigError> {
    // The health report comes once a device second.
    let w = watch(session, 2.5, |w| w.health.is_some())?;
    let Some(h) = w.health else {
        return Ok(step(
            "bus_voltage",
            false,
            "no health report within 2.5 s".into(),
            "the firmware sends one a second while telemetry runs: check the firmware version (`rig info`)",
        ));
    };
    let v = f64::from(h.bus_voltage_v);
    if !v.is_finite() {
        return Ok(skip(
            "bus_voltage",
            "not sensed (no bus divider fitted): check the bench supply with a meter".into(),
        ));
    }
    let nominal = model::hardware::board::BRIDGE_SUPPLY_V;
    let (lo, hi) = (
        nominal * (1.0 - BUS_TOLERANCE),
        nominal * (1.0 + BUS_TOLERANCE),
    );
    Ok(step(
        "bus_voltage",
        (lo..=hi).contains(&v),
        format!(
            "bus {} V (the bench supply's {} V +- {} %: {} to {} V)",
            reporting::human((v * 100.0).round() / 100.0),
            reporting::human(nominal),
            reporting::human(BUS_TOLERANCE * 100.0),
            reporting::human(reporting::significant(lo, 4)),
            reporting::human(reporting::significant(hi, 4))
        ),
        "set the bench supply to 12 V and check its current limit (at least 10 A), the bridge's supply leads and the bus divider (docs/bench.md, wiring)",
    ))
}

fn current_zero(session: &mut Connection) -> Result<Step, RigError> {
    let w = watch(session, 0.5, |_| false)?;
    let faults = w.faults();
    let mean = w.mean(|t| t.current_a).unwrap_or(f64::NAN);
    let n = w.samples.len() as f64;
    let sd = (w
        .samples
        .iter()
        .map(|t| (f64::from(t.current_a) - mean).powi(2))
        .sum::<f64>()
        / n.max(1.0))
    .sqrt();
    let zero_fault = faults.contains(FaultFlags::CURRENT_ZERO_RANGE);
    let stuck = w.samples.len() >= 20 && sd == 0.0;
    let ok = !zero_fault && !stuck && mean.abs() <= ZERO_TOLERANCE_A;
    Ok(step(
        "current_zero",
        ok,
        format!(
            "motor off: mean {:.4} A, spread {:.4} A over {} samples{}{}",
            mean,
            sd,
            w.samples.len(),
            if zero_fault {
                "; CURRENT_ZERO_RANGE latched (the sensor's zero is outside its range)"
            } else {
                ""
            },
            if stuck {
                "; the reading never changes (a live hall sensor always shows some noise)"
            } else {
                ""
            }
        ),
        "the ACS714's 5 V supply and ground, its output through the 2/3 divider to PA0 (docs/bench.md), and that nothing drives the motor; within 0.1 A is expected",
    ))
}

fn encoder(session: &mut Connection, hands: &mut dyn Hands) -> Result<Step, RigError> {
    if !hands.set_up(Action::NoLoad)? {
        return Ok(skip("encoder", "skipped by the operator".into()));
    }
    session.client.discard_telemetry();
    if let Err(e) = session.client.open_loop(ENCODER_CHECK_V as f32) {
        // A fault latched since the last step holds the motor off: name it.
        let latched = session.client.faults()?.latched;
        return Ok(step(
            "encoder",
            false,
            format!("the drive was refused ({e})"),
            encoder_advice(latched, 0.0),
        ));
    }
    let w = watch(session, 1.5, |w| !w.faults().is_empty());
    stop_drive(session)?;
    let w = w?;
    let faults = w.faults();
    // The last half second, once the cam runs.
    let tail: Vec<f64> = w
        .samples
        .iter()
        .rev()
        .take(usize::from(TELEMETRY_HZ / 2))
        .map(|t| f64::from(t.cam_speed_rad_s))
        .collect();
    let speed = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
    let ok = faults.is_empty() && speed > 1.0;
    let _ = wait_locked(session);
    Ok(step(
        "encoder",
        ok,
        format!(
            "open loop {} V, no load: cam {:+.2} rad/s ({:+.2} Hz){}",
            reporting::human(ENCODER_CHECK_V),
            speed,
            speed / std::f64::consts::TAU,
            if faults.is_empty() {
                String::new()
            } else {
                format!("; faults {faults}")
            }
        ),
        encoder_advice(faults, speed),
    ))
}

/// What to check when the encoder step fails with `faults` and cam `speed`, rad/s.
fn encoder_advice(faults: FaultFlags, speed: f64) -> &'static str {
    if faults.contains(FaultFlags::REVERSED_ENCODER) || speed < -1.0 {
        "the encoder counts against the drive: swap its A and B wires (or the motor's two leads), then `rig clear`"
    } else if faults.contains(FaultFlags::ENCODER_LOSS) || speed.abs() <= 1.0 {
        "no count while the motor turns: the AMT102-V's 5 V, ground and A/B wires to the timer pins (docs/bench.md), its DIP switches at 2048 PPR; then `rig clear`"
    } else {
        "`rig faults` names the fault; check the wiring in docs/bench.md, then `rig clear`"
    }
}

fn output_encoder(session: &mut Connection, hands: &mut dyn Hands) -> Result<Step, RigError> {
    let info = session.client.info()?;
    if !info.capabilities.contains(Capabilities::OUTPUT_ENCODER) {
        return Ok(skip(
            "output_encoder",
            "no output encoder fitted (the device does not report one): the procedures ask the operator whether the output moved".into(),
        ));
    }
    if !hands.set_up(Action::HangLoad(OUTPUT_CHECK_LOAD_NM))? {
        return Ok(skip("output_encoder", "skipped by the operator".into()));
    }
    let before = watch(session, 0.2, |_| false)?;
    let from = before.samples.last().map(|t| f64::from(t.output_angle_rad));
    session.client.release(true, FIRST_RELEASE_HZ as f32)?;
    let w = watch(session, OUTPUT_CHECK_RELEASE_S, |w| !w.faults().is_empty());
    stop_drive(session)?;
    let w = w?;
    let _ = wait_locked(session);
    hands.set_up(Action::NoLoad)?;
    let to = w.samples.last().map(|t| f64::from(t.output_angle_rad));
    let moved = match (from, to) {
        (Some(a), Some(b)) if a.is_finite() && b.is_finite() => Some(b - a),
        _ => None,
    };
    let ok = moved.is_some_and(|m| m.abs() > MOTION_RAD) && w.faults().is_empty();
    Ok(step(
        "output_encoder",
        ok,
        match moved {
            Some(m) => format!(
                "{} released {} s at {} Hz: the output turned {:+.4} rad",
                crate::experiment::load_text(OUTPUT_CHECK_LOAD_NM),
                reporting::human(OUTPUT_CHECK_RELEASE_S),
                reporting::human(FIRST_RELEASE_HZ),
                m
            ),
            None => "the output angle is not a number".into(),
        },
        "the output encoder's supply and wires (docs/bench.md); the load must hang free of the frame",
    ))
}

fn overcurrent_trip(session: &mut Connection, hands: &mut dyn Hands) -> Result<Step, RigError> {
    let virtual_rig = hands.virtual_rig();
    let action = if virtual_rig {
        Action::JamCam
    } else {
        Action::TestCurrent
    };
    let w = if virtual_rig {
        // Spin the cam up (no load), then jam it.
        session.client.discard_telemetry();
        session.client.open_loop(TRIP_TEST_V as f32)?;
        let spun = watch(session, 2.5, |w| !w.faults().is_empty());
        let jammed = spun.and_then(|spun| {
            if !spun.faults().is_empty() || !hands.set_up(action)? {
                return Ok(spun);
            }
            watch(session, 0.5, |w| !w.faults().is_empty())
        });
        let stopped = session.client.open_loop(0.0);
        let w = jammed?;
        stopped.or_else(|e| match e {
            // A latched fault may refuse the drive's stop: the bridge is off anyway.
            RigError::Refused { .. } => Ok(()),
            e => Err(e),
        })?;
        w
    } else {
        if !hands.set_up(action)? {
            return Ok(skip(
                "overcurrent_trip",
                "skipped by the operator: the hardware trip is untested".into(),
            ));
        }
        session.client.discard_telemetry();
        watch(session, TRIP_WATCH_S, |w| {
            w.faults().contains(FaultFlags::HW_OVERCURRENT)
        })?
    };
    let latched = session.client.faults()?.latched | w.faults();
    let peak = w
        .samples
        .iter()
        .map(|t| f64::from(t.current_a))
        .fold(0.0, f64::max);
    let _ = wait_locked(session);
    hands.set_up(Action::FreeCam)?;
    let tripped = latched.contains(FaultFlags::HW_OVERCURRENT);
    let _ = session.client.clear_faults()?;
    // The device's word right after the clear, then whether it stays cleared with the
    // bridge armed again. Samples the control steps took before the clear can still follow
    // its reply (the core frames telemetry at its next transmit), so once the device says
    // cleared, the watch counts from its first sample without a fault: a trip after that is
    // a trip after the clear.
    let right_after = session.client.faults()?;
    session.client.discard_telemetry();
    let after = watch(session, 0.5, |_| false)?;
    let after_faults = if (right_after.latched | right_after.active).is_empty() {
        after
            .samples
            .iter()
            .skip_while(|t| !t.faults.is_empty())
            .fold(FaultFlags::empty(), |f, t| f | t.faults)
    } else {
        after.faults()
    };
    let cleared = session.client.faults()?;
    let left = right_after.latched | cleared.latched | cleared.active | after_faults;
    let ok = tripped && left.is_empty();
    Ok(step(
        "overcurrent_trip",
        ok,
        format!(
            "{}: {}, peak mean current {:.2} A; faults after clearing: {}",
            if virtual_rig {
                format!(
                    "cam jammed at speed, open loop {} V",
                    reporting::human(TRIP_TEST_V)
                )
            } else {
                "test current through the sensor".to_string()
            },
            if tripped {
                "the hardware break tripped (HW_OVERCURRENT)".to_string()
            } else if latched.is_empty() {
                "no trip".to_string()
            } else {
                format!("{latched} but no hardware break")
            },
            peak,
            if left.is_empty() {
                "none".to_string()
            } else {
                left.to_string()
            }
        ),
        if tripped {
            "the trip did not clear: `rig faults`; is the cam free again?"
        } else {
            "the comparator path: ACS714 output on PA0 (COMP3 input), the DAC threshold (2.41 V for 6 A), COMP3 into TIM1's break input (docs/bench.md); and that the test current really passed the sensor"
        },
    ))
}

fn first_release(session: &mut Connection, hands: &mut dyn Hands) -> Result<Step, RigError> {
    if !hands.set_up(Action::NoLoad)? {
        return Ok(skip("first_release", "skipped by the operator".into()));
    }
    session.client.discard_telemetry();
    session.client.release(true, FIRST_RELEASE_HZ as f32)?;
    let w = watch(session, 2.5, |w| !w.faults().is_empty());
    stop_drive(session)?;
    let w = w?;
    let locked = wait_locked(session)?;
    let vibrating: Vec<f64> = w
        .samples
        .iter()
        .filter(|t| t.state == SupervisorState::Vibrating)
        .map(|t| f64::from(t.cam_speed_rad_s.abs()) / std::f64::consts::TAU)
        .collect();
    let mean_hz =
        (!vibrating.is_empty()).then(|| vibrating.iter().sum::<f64>() / vibrating.len() as f64);
    let faults = w.faults();
    let on_target =
        mean_hz.is_some_and(|hz| (hz - FIRST_RELEASE_HZ).abs() <= 0.15 * FIRST_RELEASE_HZ);
    let ok = faults.is_empty() && on_target && locked;
    Ok(step(
        "first_release",
        ok,
        format!(
            "released at {} Hz, no load: {}{}; {}",
            reporting::human(FIRST_RELEASE_HZ),
            match mean_hz {
                Some(hz) => format!("vibrating at {hz:.2} Hz"),
                None => "never reached constant vibration".into(),
            },
            if faults.is_empty() {
                String::new()
            } else {
                format!(", faults {faults}")
            },
            if locked {
                "locked again"
            } else {
                "did not lock within 3 s"
            }
        ),
        "the speed loop's gains and the cam's coupling; `rig monitor --release 5` shows the spin-up; `rig faults` names a fault",
    ))
}

/// Stops the drive (release off stops an open-loop drive too). A latched fault already
/// holds the motor off, and the device then refuses the request: that is not an error.
fn stop_drive(session: &mut Connection) -> Result<(), RigError> {
    match session.client.release(false, 0.0) {
        Ok(()) | Err(RigError::Refused { .. }) => Ok(()),
        Err(e) => Err(e),
    }
}

/// Waits up to 3 device seconds for `Locked`.
fn wait_locked(session: &mut Connection) -> Result<bool, RigError> {
    session.client.discard_telemetry();
    let w = watch(session, 3.0, |w| {
        w.samples
            .last()
            .is_some_and(|t| matches!(t.state, SupervisorState::Locked | SupervisorState::Fault))
    })?;
    Ok(w.samples
        .last()
        .is_some_and(|t| t.state == SupervisorState::Locked))
}
