//! The paper's vibrator calibration (Eqs. 15-17, Table 2), run through the device client.
//!
//! 1. No-load sweep: the cam uncoupled from the carrier, the vibrator driven open loop at
//!    V_in = 1.9 down to 1.0 V; mean cam speed and current over 0.5 s at each step give
//!    |i_loss| = C5 w_n + C6. Going down from the top keeps the motor turning at 1.0 V,
//!    just above its break-away voltage.
//! 2. Torque-current steps: an arm on the vibrator shaft presses on a force gauge; at each
//!    voltage the mean current and the gauge reading give |tau_cam| = C1 i_in + C2.
//! 3. C3 = C1 C5 and C4 = C1 C6 + C2 (the loss torque is the torque of the no-load
//!    current), checked against a direct fit of the loss torque C1 i + C2 over the sweep.
//!
//! The operator's part (setting up the rig, reading the gauge) is a [`GaugeOperator`]: a person at
//! a real rig, or the virtual device's plant in `--sim` mode.

mod analysis;
pub mod file;
pub mod fit;
mod gauge;
pub mod operator;
pub mod plot;

use std::io::{Read, Write};
use std::time::Duration;

use protocol::{SupervisorState, TelemetrySample};
use serde::Serialize;

use crate::RigError;
use crate::client::Client;

pub use analysis::{CalibrationResult, Consistency, VersusPaper, analyse, write_points_csv};
pub use gauge::{GaugeUnit, parse_reading, read_gauge_csv, read_points_csv};

/// How the rig must be set up for the next part of the procedure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setup {
    /// The cam uncoupled from the carrier: the vibrator turns freely.
    NoLoad,
    /// An arm on the vibrator shaft resting on the force gauge: the shaft cannot turn.
    Gauge,
    /// The procedure is over: back to normal operation (cam coupled).
    Done,
}

impl Setup {
    /// What the operator has to do.
    pub fn instructions(self) -> &'static str {
        match self {
            Setup::NoLoad => {
                "No-load test: uncouple the cam from the carrier so the vibrator turns freely."
            }
            Setup::Gauge => {
                "Torque test: fix the arm on the vibrator shaft so it presses on the force gauge (the shaft must not turn), and set the gauge to peak hold: the drive presses for about a second per step and is off while you read the held value."
            }
            Setup::Done => {
                "Calibration measured: remove the arm and couple the cam to the carrier again."
            }
        }
    }
}

/// The operator's answer at a torque step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reading {
    /// The gauge's torque, N mm.
    Nmm(f64),
    /// Measure the step again (the operator answered `r`).
    Redo,
}

/// The operator's side of the procedure.
pub trait GaugeOperator {
    /// Puts the rig into `setup` (asks the operator, or changes the simulated rig). The
    /// drive is off and the telemetry stopped meanwhile: a person may take minutes.
    fn prepare(&mut self, setup: Setup) -> Result<(), RigError>;
    /// A telemetry sample inside torque step `step`'s averaging window, while the drive
    /// presses the arm on the gauge: the virtual gauge is read at each, so its reading is
    /// the mean over the same window as the current's (a real gauge and arm average the
    /// PWM's ripple mechanically).
    fn window_sample(&mut self, _step: usize) {}
    /// The end of torque step `step`'s averaging window, while the drive still presses the
    /// arm on the gauge: the moment the gauge's peak hold keeps.
    fn pressed(&mut self, _step: usize) {}
    /// The gauge's held torque reading of torque step `step` (0-based), taken after the
    /// drive stopped (`measured` is what the drive drew), or a request to measure the step
    /// again; `keep_alive` services the link while waiting (and fails once Ctrl-C was
    /// pressed). The drive is off and the gear locked while the operator reads.
    fn gauge_nmm(
        &mut self,
        step: usize,
        measured: &StepMeasurement,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<Reading, RigError>;
}

/// The calibration's schedule: the voltages it drives and how long it waits and averages
/// at each (not a test plan: that is [`rigfile::plan::Plan`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationSchedule {
    /// No-load sweep voltages, V, in the order driven.
    pub sweep_volts: Vec<f64>,
    /// Torque step voltages, V (the shaft is blocked: i = V / R, about 2.4-4.2 A).
    pub torque_volts: Vec<f64>,
    /// Wait after each voltage change before averaging, device seconds.
    pub settle_s: f64,
    /// Extra wait at the first sweep step, while the cam spins up from rest, device seconds.
    pub spin_up_s: f64,
    /// Averaging window, device seconds (the paper: 0.5 s).
    pub average_s: f64,
    /// Telemetry rate while measuring, Hz.
    pub telemetry_hz: u16,
}

impl Default for CalibrationSchedule {
    fn default() -> Self {
        Self {
            sweep_volts: (0..10).map(|k| 1.9 - 0.1 * f64::from(k)).collect(),
            torque_volts: (0..9).map(|k| 1.05 + 0.1 * f64::from(k)).collect(),
            settle_s: 0.5,
            spin_up_s: 1.0,
            average_s: 0.5,
            telemetry_hz: 100,
        }
    }
}

impl CalibrationSchedule {
    /// Number of measured steps.
    pub fn steps(&self) -> usize {
        self.sweep_volts.len() + self.torque_volts.len()
    }
}

/// Means over one averaging window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StepMeasurement {
    /// Drive voltage, V.
    pub volts: f64,
    /// Mean current, A.
    pub current_a: f64,
    /// Standard deviation of the current samples, A.
    pub current_sd_a: f64,
    /// Mean cam speed, rad/s.
    pub cam_speed_rad_s: f64,
    /// Telemetry samples averaged.
    pub samples: usize,
}

/// One torque-current point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TorquePoint {
    /// The drive step.
    #[serde(flatten)]
    pub step: StepMeasurement,
    /// Gauge reading, N mm.
    pub gauge_nmm: f64,
}

/// Everything measured.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Measurements {
    /// No-load sweep, in the order driven.
    pub no_load: Vec<StepMeasurement>,
    /// Torque-current steps.
    pub torque: Vec<TorquePoint>,
}

/// What progress to report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// A step is being measured.
    Step {
        /// Which part.
        setup: Setup,
        /// The drive voltage.
        volts: f64,
    },
    /// A step is done.
    Done,
}

/// Runs the procedure: sweep, then torque steps, into `taken` (every point as it is
/// measured, so an interrupted run keeps them; the steps already in `taken`, from an
/// interrupted run, are not measured again); `progress` sees each step and the points
/// so far. The telemetry runs only while a step is measured: while the operator sets up
/// the rig or reads the gauge the drive is off, the gear locked and nothing piles up. The drive is stopped at the end and on any error; `interrupted` (Ctrl-C) ends
/// the procedure between samples with [`interrupted_error`].
pub fn measure<T: Read + Write>(
    client: &mut Client<T>,
    bench: &mut dyn GaugeOperator,
    plan: &CalibrationSchedule,
    taken: &mut Measurements,
    progress: &mut dyn FnMut(Progress, &Measurements),
    interrupted: &dyn Fn() -> bool,
) -> Result<(), RigError> {
    let result = measure_inner(client, bench, plan, taken, progress, interrupted);
    // Stop the motor whatever happened; the first error is the one to report.
    let stopped = client.open_loop(0.0);
    let _ = client.stop_telemetry();
    result?;
    stopped?;
    bench.prepare(Setup::Done)?;
    Ok(())
}

/// The error of a calibration ended by Ctrl-C.
pub fn interrupted_error() -> RigError {
    RigError::Operator(format!(
        "calibration interrupted ({}): the drive is off and the gear locked; the points measured so far are kept (points.csv): `rig calibrate --resume --out DIR` continues the run, `rig calibrate --from-points FILE` fits them",
        crate::signals::interrupt_name()
    ))
}

fn measure_inner<T: Read + Write>(
    client: &mut Client<T>,
    bench: &mut dyn GaugeOperator,
    plan: &CalibrationSchedule,
    taken: &mut Measurements,
    progress: &mut dyn FnMut(Progress, &Measurements),
    interrupted: &dyn Fn() -> bool,
) -> Result<(), RigError> {
    let check = || {
        if interrupted() {
            Err(interrupted_error())
        } else {
            Ok(())
        }
    };
    let no_load_done = taken.no_load.len().min(plan.sweep_volts.len());
    if no_load_done < plan.sweep_volts.len() {
        bench.prepare(Setup::NoLoad)?;
        check()?;
        client.start_telemetry(plan.telemetry_hz)?;
        for (k, &volts) in plan.sweep_volts.iter().enumerate().skip(no_load_done) {
            progress(
                Progress::Step {
                    setup: Setup::NoLoad,
                    volts,
                },
                taken,
            );
            client.open_loop(volts as f32)?;
            client.discard_telemetry();
            // From rest (the first step, or the first of a resumed run) the cam spins up.
            let extra = if k == no_load_done {
                plan.spin_up_s
            } else {
                0.0
            };
            taken.no_load.push(average(
                client,
                volts,
                plan.settle_s + extra,
                plan,
                interrupted,
                &mut || {},
            )?);
            progress(Progress::Done, taken);
        }
        client.open_loop(0.0)?;
        wait_until_locked(client)?;
        client.stop_telemetry()?;
    }
    let mut k = taken.torque.len();
    if k < plan.torque_volts.len() {
        bench.prepare(Setup::Gauge)?;
        check()?;
    }
    while k < plan.torque_volts.len() {
        let volts = plan.torque_volts[k];
        progress(
            Progress::Step {
                setup: Setup::Gauge,
                volts,
            },
            taken,
        );
        client.start_telemetry(plan.telemetry_hz)?;
        client.open_loop(volts as f32)?;
        client.discard_telemetry();
        let step = average(client, volts, plan.settle_s, plan, interrupted, &mut || {
            bench.window_sample(k)
        })?;
        bench.pressed(k);
        // The blocked motor draws its stall current: off before the operator reads the
        // held gauge value, so the winding does not heat up, the firmware's spin-up limit
        // (3 s, also for a shaft that cannot turn) never runs out however long the person
        // takes, and each step starts from rest.
        client.open_loop(0.0)?;
        wait_until_locked(client)?;
        client.stop_telemetry()?;
        let reading = bench.gauge_nmm(k, &step, &mut || {
            check()?;
            client.tick()
        })?;
        if let Reading::Nmm(gauge_nmm) = reading {
            taken.torque.push(TorquePoint { step, gauge_nmm });
            progress(Progress::Done, taken);
            k += 1;
        }
        check()?;
    }
    Ok(())
}

/// Waits until the supervisor reports the motor off and at rest.
fn wait_until_locked<T: Read + Write>(client: &mut Client<T>) -> Result<(), RigError> {
    // Only what follows the stop counts.
    client.discard_telemetry();
    let wait = Duration::from_secs(2) + client.options().reply_timeout;
    let mut first = None;
    loop {
        let Some(t) = client.next_telemetry(wait)? else {
            return Err(RigError::Protocol(format!(
                "telemetry stopped during the calibration on {}; check the link and `rig faults`",
                client.options().port_name
            )));
        };
        match t.state {
            SupervisorState::Locked => return Ok(()),
            SupervisorState::Fault => {
                return Err(RigError::DeviceFault {
                    what: "calibration stopped between torque steps".into(),
                    faults: t.faults,
                });
            }
            _ => {}
        }
        let start = *first.get_or_insert(t.device_time_us);
        if t.device_time_us - start > 5_000_000 {
            return Err(RigError::Protocol(format!(
                "the motor did not come to rest within 5 s after a torque step (state {})",
                t.state.name()
            )));
        }
    }
}

/// Waits `settle_s` of device time, then averages telemetry over `plan.average_s`.
fn average<T: Read + Write>(
    client: &mut Client<T>,
    volts: f64,
    settle_s: f64,
    plan: &CalibrationSchedule,
    interrupted: &dyn Fn() -> bool,
    in_window: &mut dyn FnMut(),
) -> Result<StepMeasurement, RigError> {
    let wait = Duration::from_secs(2) + client.options().reply_timeout;
    let next = |client: &mut Client<T>| -> Result<TelemetrySample, RigError> {
        if interrupted() {
            return Err(interrupted_error());
        }
        let t = client.next_telemetry(wait)?.ok_or_else(|| {
            RigError::Protocol(format!(
                "telemetry stopped during the calibration on {}; check the link and `rig faults`",
                client.options().port_name
            ))
        })?;
        if !t.faults.is_empty() || t.state == SupervisorState::Fault {
            return Err(RigError::DeviceFault {
                what: format!("calibration stopped at {volts:.2} V"),
                faults: t.faults,
            });
        }
        Ok(t)
    };
    let first = next(client)?;
    let start = first.device_time_us + (settle_s * 1e6) as u64;
    let end = start + (plan.average_s * 1e6) as u64;
    let (mut n, mut sum_i, mut sum_i2, mut sum_w) = (0usize, 0.0, 0.0, 0.0);
    loop {
        let t = next(client)?;
        if t.device_time_us < start {
            continue;
        }
        if t.device_time_us >= end {
            break;
        }
        let i = f64::from(t.current_a);
        n += 1;
        sum_i += i;
        sum_i2 += i * i;
        sum_w += f64::from(t.cam_speed_rad_s).abs();
        in_window();
    }
    if n == 0 {
        return Err(RigError::CalibrationFit(format!(
            "no telemetry sample fell in the averaging window at {volts:.2} V"
        )));
    }
    let nf = n as f64;
    let mean = sum_i / nf;
    Ok(StepMeasurement {
        volts,
        current_a: mean,
        current_sd_a: (sum_i2 / nf - mean * mean).max(0.0).sqrt(),
        cam_speed_rad_s: sum_w / nf,
        samples: n,
    })
}
