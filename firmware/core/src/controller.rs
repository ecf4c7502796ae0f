//! The control core: one [`Core::step`] per control period turns sensor readings into a
//! bridge command, and the host link goes through [`Core::receive`] and
//! [`Core::transmit`]. Time is passed in; there is no I/O, no heap and no hardware here.
//!
//! Per step, in order: timing (overrun), current and encoder, capture recording, release
//! inputs (heartbeat, button), hardware faults, the revolution estimate, the supervisor,
//! the speed loop, then fault events, telemetry and a pending flash write.

use core::f32::consts::TAU;

use protocol::{
    Calibration, CalibrationStatus, DeviceMessage, FaultFlags, NackCode, StatusFlags,
    SupervisorState, TelemetrySample,
};

use crate::capture::{Capture, CapturePhase};
use crate::config::CoreConfig;
use crate::current::{CurrentSense, ZeroResult};
use crate::encoder::CamEncoder;
use crate::estimator::{EstimatorModel, StepSamples, TorqueEstimator};
use crate::faults::FaultMonitor;
use crate::speed_loop::{FeedForward, SpeedLoop};
use crate::supervisor::{RevolutionCheck, Supervisor, SupervisorInputs};
use crate::tx_queue::{CAPTURE_IN_FLIGHT, REPLY_RESERVE, TxQueue};

/// How long the binary may take to report a flash write before it counts as failed, us.
const PERSIST_TIMEOUT_US: u64 = 5_000_000;

/// What the binary knows at boot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BootInfo {
    /// The last reset was the independent watchdog's.
    pub watchdog_reset: bool,
    /// Calibration loaded from flash (the paper's defaults when none or invalid).
    pub calibration: Calibration,
    /// Where `calibration` came from.
    pub calibration_status: CalibrationStatus,
}

impl Default for BootInfo {
    /// A clean boot with nothing stored: the paper's calibration.
    fn default() -> Self {
        Self {
            watchdog_reset: false,
            calibration: Calibration::paper(),
            calibration_status: CalibrationStatus::Defaults,
        }
    }
}

/// One control step's sensor readings.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Now, microseconds since boot.
    pub now_us: u64,
    /// Current ADC samples since the last step, oldest first (normally `samples_per_step`).
    pub current_adc: &'a [u16],
    /// Raw, wrapping 16-bit encoder timer count.
    pub encoder_count: u16,
    /// The physical release input is held.
    pub release_button: bool,
}

/// One control step's commands to the hardware.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outputs {
    /// PWM duty, -1..=1; the sign is the direction pin.
    pub duty: f32,
    /// Bridge enable; false is the safe state (vibration off).
    pub enable: bool,
    /// A calibration to write to flash; report the outcome with [`Core::persist_result`].
    pub persist: Option<Calibration>,
    /// A capture is recording (informational: the core records from `current_adc`).
    pub capture: bool,
}

impl Outputs {
    /// Bridge off, nothing to do.
    pub const SAFE: Self = Self {
        duty: 0.0,
        enable: false,
        persist: None,
        capture: false,
    };
}

/// A snapshot of the core for logs, simulation and tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    /// Supervisor state.
    pub state: SupervisorState,
    /// Latched faults (the motor stays off while any is latched).
    pub latched_faults: FaultFlags,
    /// Faults whose condition is present now.
    pub active_faults: FaultFlags,
    /// Telemetry status bits.
    pub flags: StatusFlags,
    /// Cam speed in the drive direction, rad/s.
    pub cam_speed_rad_s: f32,
    /// Cam angle, rad.
    pub cam_angle_rad: f32,
    /// Filtered motor current, A.
    pub current_a: f32,
    /// Commanded duty, -1..=1.
    pub duty: f32,
    /// Bridge enabled.
    pub enabled: bool,
    /// Vibration frequency being driven (possibly raised), Hz.
    pub target_hz: f32,
    /// Ramped speed reference of the loop, rad/s.
    pub speed_reference_rad_s: f32,
    /// Last revolution's mean cam torque, N m (0 before the first).
    pub tau_cam_nm: f32,
    /// Last revolution's load estimate, N m (0 before the first).
    pub tau_rot_nm: f32,
    /// Whether `tau_cam_nm` and `tau_rot_nm` come from a revolution.
    pub estimate_valid: bool,
    /// Revolutions estimated since vibration started.
    pub revolutions: u32,
    /// mu_d * Lambda < 1: the output keeps moving after vibration stops.
    pub keeps_moving_after_stop: bool,
    /// mu_s * Lambda > 1: the gear holds its load without vibration.
    pub holds_at_rest: bool,
    /// A host release (kept alive by requests) is live.
    pub host_release: bool,
    /// The bridge voltage of a live open-loop drive, V.
    pub open_loop_volts: Option<f32>,
    /// The release button is held (and armed).
    pub button_release: bool,
    /// Current-sensor zero, ADC counts.
    pub current_zero_adc: f32,
    /// A zero measurement is running.
    pub zeroing: bool,
    /// The active calibration.
    pub calibration: Calibration,
    /// Where it came from.
    pub calibration_status: CalibrationStatus,
    /// Receiver counters (garbled frames included).
    pub deframer: protocol::DeframerStats,
    /// Outgoing frames dropped for lack of queue room.
    pub tx_dropped: u32,
    /// Steps that came late (`CONTROL_OVERRUN` events).
    pub control_overruns: u32,
    /// A capture is recording.
    pub capture_recording: bool,
    /// A capture is uploading.
    pub capture_uploading: bool,
}

/// Quantities derived from the calibration (recomputed when it changes).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Derived {
    pub(crate) model: EstimatorModel,
    pub(crate) feed_forward: FeedForward,
    pub(crate) current_limit_a: f32,
    pub(crate) max_hz: f32,
    pub(crate) max_load_nm: f32,
    pub(crate) keeps_moving: bool,
    pub(crate) holds_at_rest: bool,
}

impl Derived {
    /// `None` when the model rejects the gear set or the vibrator constants.
    pub(crate) fn new(cal: &Calibration, config: &CoreConfig) -> Option<Self> {
        cal.validate().ok()?;
        let z = cal.z.map(u32::from);
        let gear = model::GearSet::new(
            z,
            f64::from(cal.module_mm) * 1e-3,
            f64::from(cal.pressure_angle_deg).to_radians(),
        )
        .ok()?;
        let vibrator = model::Calibration::from_paper_units(cal.constants());
        if !vibrator.is_plausible() {
            return None;
        }
        let drive = model::CamDrive {
            gear,
            eccentricity: f64::from(cal.eccentricity_mm) * 1e-3,
            carrier_mass: f64::from(cal.carrier_mass_kg),
        };
        let big_lambda = gear.big_lambda();
        Some(Self {
            model: EstimatorModel {
                drive,
                vibrator,
                mu: f64::from(cal.mu_s),
                carrier_power_returned: config.estimator.carrier_power_returned,
            },
            feed_forward: FeedForward {
                resistance_ohm: config.motor.resistance_ohm,
                ke: config.motor.ke_cam_v_s_per_rad,
                c5: cal.c5_a_s_per_rad,
                c6: cal.c6_a,
                supply_v: config.supply_v,
            },
            current_limit_a: cal.max_current_a.min(config.faults.overcurrent_a),
            max_hz: cal.max_freq_hz.min(config.supervisor.max_freq_hz),
            max_load_nm: cal.max_release_load_nm,
            keeps_moving: f64::from(cal.mu_d) * big_lambda < 1.0,
            holds_at_rest: f64::from(cal.mu_s) * big_lambda > 1.0,
        })
    }
}

/// A calibration on its way to flash.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Persist {
    Idle,
    /// Handed to the binary at the next step.
    Requested {
        calibration: Calibration,
        seq: u16,
    },
    /// Handed over at `since_us`; waiting for [`Core::persist_result`].
    Writing {
        calibration: Calibration,
        seq: u16,
        since_us: u64,
    },
}

/// The control core. See the crate documentation.
pub struct Core {
    pub(crate) config: CoreConfig,
    pub(crate) calibration: Calibration,
    pub(crate) calibration_status: CalibrationStatus,
    pub(crate) derived: Derived,
    pub(crate) current: CurrentSense,
    encoder: CamEncoder,
    speed_loop: SpeedLoop,
    estimator: TorqueEstimator,
    pub(crate) supervisor: Supervisor,
    pub(crate) faults: FaultMonitor,
    pub(crate) deframer: protocol::RequestDeframer,
    pub(crate) tx: TxQueue,
    pub(crate) now_us: u64,
    last_step_us: Option<u64>,
    pub(crate) host_release: bool,
    pub(crate) host_target_hz: f32,
    /// A live open-loop drive (`Request::OpenLoop`): the bridge voltage asked for, V.
    pub(crate) open_loop_volts: Option<f32>,
    /// Open-loop settle check: position and time of the last revolution start, and the
    /// period of the revolution before it (0: none yet).
    open_loop_rev: (i64, u64, u64),
    open_loop_steady: bool,
    pub(crate) last_request_us: u64,
    pub(crate) button_held: bool,
    button_armed: bool,
    duty: f32,
    enable: bool,
    pub(crate) persist: Persist,
    pub(crate) telemetry_period: u32,
    telemetry_countdown: u32,
    telemetry_seq: u32,
    overruns: u32,
    pub(crate) capture: Capture,
}

impl Core {
    /// A core in `Locked`, measuring the current zero. A watchdog reset or an invalid
    /// calibration latches its fault from the start.
    pub fn new(config: CoreConfig, boot: BootInfo) -> Self {
        let (calibration, status, derived) = match Derived::new(&boot.calibration, &config) {
            Some(d) if boot.calibration_status != CalibrationStatus::Invalid => {
                (boot.calibration, boot.calibration_status, d)
            }
            _ => {
                let paper = Calibration::paper();
                let d = Derived::new(&paper, &config)
                    .expect("the paper's calibration is valid (tested)");
                (paper, CalibrationStatus::Invalid, d)
            }
        };
        let step_s = config.period_us() as f32 * 1e-6;
        let mut core = Self {
            current: CurrentSense::new(&config.current, step_s),
            encoder: CamEncoder::new(config.counts_per_rev()),
            speed_loop: SpeedLoop::new(config.speed_loop, &config.motor, derived.feed_forward),
            estimator: TorqueEstimator::new(
                config.counts_per_rev(),
                config.estimator.max_revolution_us,
            ),
            supervisor: Supervisor::new(config.supervisor, derived.max_hz),
            faults: FaultMonitor::new(config.supervisor.fault_hold_us),
            deframer: protocol::RequestDeframer::new(),
            tx: TxQueue::new(),
            now_us: 0,
            last_step_us: None,
            host_release: false,
            host_target_hz: config.supervisor.default_freq_hz,
            open_loop_volts: None,
            open_loop_rev: (0, 0, 0),
            open_loop_steady: false,
            last_request_us: 0,
            button_held: false,
            button_armed: false,
            duty: 0.0,
            enable: false,
            persist: Persist::Idle,
            telemetry_period: 0,
            telemetry_countdown: 0,
            telemetry_seq: 0,
            overruns: 0,
            capture: Capture::new(),
            config,
            calibration,
            calibration_status: status,
            derived,
        };
        core.current.begin_zero();
        let mut boot_faults = FaultFlags::empty();
        boot_faults.set(FaultFlags::WATCHDOG_RESET, boot.watchdog_reset);
        boot_faults.set(
            FaultFlags::CALIBRATION_INVALID,
            status == CalibrationStatus::Invalid,
        );
        core.raise(boot_faults);
        core
    }

    /// The configuration.
    pub fn config(&self) -> &CoreConfig {
        &self.config
    }

    /// The active calibration.
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    fn direction(&self) -> f32 {
        if self.config.motor.reverse { -1.0 } else { 1.0 }
    }

    /// Latches `flags`; any fault also drops the release requests (a held button must be
    /// let go once, a host must ask again).
    pub(crate) fn raise(&mut self, flags: FaultFlags) {
        if flags.is_empty() {
            return;
        }
        self.faults.raise(flags, self.now_us);
        self.host_release = false;
        self.open_loop_volts = None;
        self.button_armed = false;
        self.button_held = false;
        self.estimator.stop();
    }

    /// Runs one control period. Call at `control_hz`.
    pub fn step(&mut self, inputs: &Inputs) -> Outputs {
        let now = inputs.now_us;
        let period = self.config.period_us();
        let prev_us = self.last_step_us.unwrap_or(now.saturating_sub(period));
        let elapsed = now.saturating_sub(prev_us);
        self.last_step_us = Some(now);
        self.now_us = now;
        if elapsed > u64::from(self.config.faults.overrun_periods) * period {
            self.overruns = self.overruns.saturating_add(1);
            self.raise(FaultFlags::CONTROL_OVERRUN);
        }
        // A late step must not kick the integrator.
        let dt = elapsed.max(1).min(4 * period) as f32 * 1e-6;

        if self.current.update(inputs.current_adc) == Some(ZeroResult::OutOfRange) {
            self.raise(FaultFlags::CURRENT_ZERO_RANGE);
        }
        let prev_position = self.encoder.position();
        self.encoder.update(now, inputs.encoder_count);
        let position = self.encoder.position();
        let dir = self.direction();
        let speed = self.encoder.speed_rad_s() * dir;
        self.capture
            .record_step(inputs.current_adc, prev_position as u16, position as u16);

        self.update_release(now, inputs.release_button);
        self.check_hardware(now, position);

        if self.supervisor.state() == SupervisorState::Vibrating {
            let dir_i = dir as i64;
            let step = StepSamples {
                current_adc: inputs.current_adc,
                prev_us,
                now_us: now,
                prev_position: prev_position * dir_i,
                position: position * dir_i,
            };
            let current = &self.current;
            let estimate = self.estimator.update(&step, &self.derived.model, |counts| {
                current.amps(counts) * dir
            });
            if let Some(e) = estimate {
                let check = RevolutionCheck {
                    tau_cam: e.tau_cam_nm,
                    tau_rot: e.tau_rot_nm,
                    required_no_load: e.required_no_load_nm,
                    required_max_load: self.derived.model.required(
                        f64::from(self.derived.max_load_nm),
                        f64::from(e.cam_speed_rad_s),
                    ) as f32,
                    max_load: self.derived.max_load_nm,
                };
                let raised = self.supervisor.on_revolution(&check, now);
                self.raise(raised);
            }
        }

        self.run_supervisor(now, speed, position * dir as i64);

        if self.supervisor.drives_motor() && self.faults.latched().is_empty() {
            self.duty = match self.open_loop_volts {
                Some(volts) => {
                    // A bench supply's fixed voltage, reached through the duty slew limit
                    // and a soft start: the ramp pauses while the current is above 85 %
                    // of the overcurrent limit and the cam is accelerating.
                    let m = self.config.motor;
                    // max/min, not clamp: clamp's NaN assertion would pull float formatting
                    // into the image.
                    let goal = (volts / self.config.supply_v)
                        .max(-m.max_duty)
                        .min(m.max_duty)
                        * dir;
                    // Only while the cam turns: a shaft held on the force gauge draws its
                    // stall current, which is what the calibration asks for.
                    let accelerating = speed.abs() > self.config.supervisor.stop_speed_rad_s;
                    let near_limit =
                        self.current.step_mean_a().abs() > 0.85 * self.derived.current_limit_a;
                    let step = if accelerating && near_limit && goal.abs() > self.duty.abs() {
                        0.0
                    } else {
                        m.duty_slew_per_s * dt
                    };
                    goal.max(self.duty - step).min(self.duty + step)
                }
                None => {
                    let target = TAU * self.supervisor.target_hz();
                    self.speed_loop.update(target, speed, dt) * dir
                }
            };
            self.enable = true;
        } else {
            self.duty = 0.0;
            self.enable = false;
        }

        let risen = self.faults.take_unreported();
        if !risen.is_empty() {
            self.tx.push(
                &DeviceMessage::FaultEvent {
                    flags: risen,
                    device_time_us: now,
                },
                0,
            );
        }
        self.send_telemetry(now, speed);
        Outputs {
            duty: self.duty,
            enable: self.enable,
            persist: self.take_persist(now),
            capture: self.capture.phase() == CapturePhase::Recording,
        }
    }

    fn update_release(&mut self, now: u64, button: bool) {
        let lapsed = now.saturating_sub(self.last_request_us) > self.config.comms_timeout_us;
        if (self.host_release || self.open_loop_volts.is_some()) && lapsed {
            self.host_release = false;
            self.open_loop_volts = None;
            self.raise(FaultFlags::COMMS_TIMEOUT);
        }
        // A button already held (at boot, or through a fault) must be let go once first.
        if !button {
            self.button_armed = true;
        }
        self.button_held = button && self.button_armed;
    }

    fn check_hardware(&mut self, now: u64, position: i64) {
        let f = self.config.faults;
        let i = self.current.step_mean_a();
        if self
            .faults
            .overcurrent(now, i, self.derived.current_limit_a, f.overcurrent_time_us)
        {
            self.raise(FaultFlags::OVERCURRENT);
        }
        // The duty of the last step is the one that drove the bridge since then.
        let driven = self.enable && self.duty.abs() > f.stall_duty;
        if self
            .faults
            .no_motion(now, driven, position, f.stall_min_counts, f.stall_window_us)
        {
            // Not turning by the encoder. If the back-EMF implied by V = R i + ke w says
            // the motor does turn, the encoder is lost; otherwise the cam is stalled.
            let m = self.config.motor;
            let v = self.duty.abs() * self.config.supply_v;
            let i = self.current.filtered_a().abs();
            let w_implied = (v - m.resistance_ohm * i) / m.ke_cam_v_s_per_rad;
            let w_free = v / m.ke_cam_v_s_per_rad;
            let near_limit = i >= 0.9 * self.derived.current_limit_a;
            let flag = if !near_limit && w_implied > 0.5 * w_free {
                FaultFlags::ENCODER_LOSS
            } else {
                FaultFlags::STALL
            };
            self.raise(flag);
        }
    }

    fn requested_hz(&self) -> f32 {
        if self.host_release {
            self.host_target_hz
        } else {
            self.config.supervisor.default_freq_hz
        }
    }

    fn run_supervisor(&mut self, now: u64, speed: f32, position: i64) {
        let before = self.supervisor.state();
        let open_loop_settled = self
            .open_loop_volts
            .map(|_| self.open_loop_settled(now, position));
        let mut inputs = SupervisorInputs {
            now_us: now,
            open_loop_settled,
            release_live: self.host_release || self.button_held || open_loop_settled.is_some(),
            requested_hz: self.requested_hz().min(self.derived.max_hz),
            faulted: !self.faults.latched().is_empty(),
            zero_ready: self.current.zero_valid() && !self.current.zeroing(),
            cam_speed_rad_s: speed,
        };
        let raised = self.supervisor.update(&inputs);
        if !raised.is_empty() {
            self.raise(raised);
            inputs.faulted = true;
            self.supervisor.update(&inputs);
        }
        let after = self.supervisor.state();
        if after == before {
            return;
        }
        if after == SupervisorState::SpinUp && before != SupervisorState::Vibrating {
            self.speed_loop.reset(speed);
        }
        if after == SupervisorState::Vibrating {
            self.estimator.start(now, position);
        } else if before == SupervisorState::Vibrating {
            self.estimator.stop();
        }
    }

    /// Open-loop drive: the voltage ramp is done and two consecutive cam revolutions took
    /// the same time within 2 % (a revolution mean: the cam's speed ripples within a turn).
    fn open_loop_settled(&mut self, now: u64, position: i64) -> bool {
        let goal = self.open_loop_volts.unwrap_or(0.0) / self.config.supply_v * self.direction();
        let ramp_done = (self.duty - goal).abs() < 1e-3;
        let per_rev = i64::from(self.config.counts_per_rev());
        let (start_pos, start_us, last_period) = self.open_loop_rev;
        if !ramp_done {
            self.open_loop_rev = (position, now, 0);
            self.open_loop_steady = false;
        } else if (position - start_pos).abs() >= per_rev {
            let period = now.saturating_sub(start_us);
            let diff = period.abs_diff(last_period);
            self.open_loop_steady = last_period > 0 && diff * 50 <= last_period;
            self.open_loop_rev = (position, now, period);
        }
        self.open_loop_steady
    }

    fn status_flags(&self) -> StatusFlags {
        let mut s = StatusFlags::empty();
        s.set(StatusFlags::COASTS_AFTER_STOP, self.derived.keeps_moving);
        s.set(StatusFlags::NOT_SELF_LOCKING, !self.derived.holds_at_rest);
        s.set(StatusFlags::HOST_RELEASE, self.host_release);
        s.set(StatusFlags::BUTTON_RELEASE, self.button_held);
        s.set(
            StatusFlags::CAPTURE_RUNNING,
            self.capture.phase() == CapturePhase::Recording,
        );
        s.set(
            StatusFlags::CALIBRATION_DEFAULTS,
            self.calibration_status != CalibrationStatus::Valid,
        );
        s
    }

    fn send_telemetry(&mut self, now: u64, speed: f32) {
        if self.telemetry_period == 0 {
            return;
        }
        self.telemetry_countdown = self.telemetry_countdown.saturating_sub(1);
        if self.telemetry_countdown > 0 {
            return;
        }
        self.telemetry_countdown = self.telemetry_period;
        let estimate = self.estimator.last();
        let sample = TelemetrySample {
            seq: self.telemetry_seq,
            device_time_us: now,
            cam_speed_rad_s: speed,
            current_a: self.current.filtered_a(),
            pwm_duty: self.duty,
            tau_cam_nm: estimate.map_or(0.0, |e| e.tau_cam_nm),
            tau_rot_nm: estimate.map_or(0.0, |e| e.tau_rot_nm),
            state: self.supervisor.state(),
            faults: self.faults.latched(),
            status: self.status_flags(),
        };
        // Sequence numbers advance even for a dropped sample: the host sees the gap.
        self.telemetry_seq = self.telemetry_seq.wrapping_add(1);
        self.tx
            .push(&DeviceMessage::Telemetry(sample), REPLY_RESERVE);
    }

    fn take_persist(&mut self, now: u64) -> Option<Calibration> {
        match self.persist {
            Persist::Requested { calibration, seq } => {
                self.persist = Persist::Writing {
                    calibration,
                    seq,
                    since_us: now,
                };
                Some(calibration)
            }
            Persist::Writing { seq, since_us, .. }
                if now.saturating_sub(since_us) > PERSIST_TIMEOUT_US =>
            {
                self.persist = Persist::Idle;
                self.reply_nack(seq, NackCode::StorageFailed);
                None
            }
            _ => None,
        }
    }

    /// The binary's report of the flash write handed out in [`Outputs::persist`]: on
    /// success the calibration becomes active and the request is acknowledged, otherwise
    /// it is refused with `StorageFailed` and the old calibration stays.
    pub fn persist_result(&mut self, ok: bool) {
        let Persist::Writing {
            calibration, seq, ..
        } = self.persist
        else {
            return;
        };
        self.persist = Persist::Idle;
        if !ok {
            self.reply_nack(seq, NackCode::StorageFailed);
            return;
        }
        match Derived::new(&calibration, &self.config) {
            Some(derived) => {
                self.calibration = calibration;
                self.calibration_status = CalibrationStatus::Valid;
                self.derived = derived;
                self.speed_loop.set_feed_forward(derived.feed_forward);
                self.supervisor.set_max_hz(derived.max_hz);
                self.tx.push(&DeviceMessage::Ack { seq }, 0);
            }
            None => self.reply_nack(seq, NackCode::CalibrationRejected),
        }
    }

    pub(crate) fn reply_nack(&mut self, seq: u16, code: NackCode) {
        self.tx.push(&DeviceMessage::Nack { seq, code }, 0);
    }

    /// Faults whose condition is present now.
    pub(crate) fn active_faults(&self) -> FaultFlags {
        let mut a = FaultFlags::empty();
        a.set(
            FaultFlags::OVERCURRENT,
            self.current.step_mean_a().abs() > self.derived.current_limit_a,
        );
        a.set(
            FaultFlags::CURRENT_ZERO_RANGE,
            !self.current.zero_in_range(),
        );
        a.set(
            FaultFlags::CALIBRATION_INVALID,
            self.calibration_status == CalibrationStatus::Invalid,
        );
        a
    }

    /// Drains pending outgoing frame bytes into `out`; returns the count (0: nothing pending).
    /// Capture chunks are generated here, a few at a time, so replies and telemetry
    /// still go out while a capture uploads.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        while self.capture.phase() == CapturePhase::Uploading
            && self.tx.len() < CAPTURE_IN_FLIGHT
            && self.tx.free() >= protocol::MAX_DEVICE_FRAME_SIZE + REPLY_RESERVE
        {
            match self.capture.next_message() {
                Some(msg) => {
                    self.tx.push(&msg, REPLY_RESERVE);
                }
                None => break,
            }
        }
        self.tx.drain(out)
    }

    /// A snapshot of the core.
    pub fn status(&self) -> Status {
        let estimate = self.estimator.last();
        Status {
            state: self.supervisor.state(),
            latched_faults: self.faults.latched(),
            active_faults: self.active_faults(),
            flags: self.status_flags(),
            cam_speed_rad_s: self.encoder.speed_rad_s() * self.direction(),
            cam_angle_rad: self.encoder.angle_rad(),
            current_a: self.current.filtered_a(),
            duty: self.duty,
            enabled: self.enable,
            target_hz: self.supervisor.target_hz(),
            speed_reference_rad_s: self.speed_loop.reference(),
            tau_cam_nm: estimate.map_or(0.0, |e| e.tau_cam_nm),
            tau_rot_nm: estimate.map_or(0.0, |e| e.tau_rot_nm),
            estimate_valid: estimate.is_some(),
            revolutions: self.estimator.revolutions(),
            keeps_moving_after_stop: self.derived.keeps_moving,
            holds_at_rest: self.derived.holds_at_rest,
            host_release: self.host_release,
            open_loop_volts: self.open_loop_volts,
            button_release: self.button_held,
            current_zero_adc: self.current.zero_counts(),
            zeroing: self.current.zeroing(),
            calibration: self.calibration,
            calibration_status: self.calibration_status,
            deframer: self.deframer.stats(),
            tx_dropped: self.tx.dropped(),
            control_overruns: self.overruns,
            capture_recording: self.capture.phase() == CapturePhase::Recording,
            capture_uploading: self.capture.phase() == CapturePhase::Uploading,
        }
    }
}
