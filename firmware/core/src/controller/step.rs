//! One control period: sensor readings in, a bridge command out. In order: timing
//! (overrun), current and encoders, capture recording, release inputs (heartbeat, button),
//! hardware faults, the revolution estimate, the supervisor, the drive (speed loop or open
//! loop), then fault events, the streams and a pending flash write.

use core::f32::consts::TAU;

use protocol::{DeviceMessage, FaultFlags, SupervisorState};

use super::{Core, Inputs, Outputs};
use crate::capture::CapturePhase;
use crate::current::ZeroResult;
use crate::estimator::StepSamples;
use crate::stream::StepRecord;
use crate::supervisor::{RevolutionCheck, SupervisorInputs};

impl Core {
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

        let vdda = self.board.vdda_v;
        if self.current.update_with_vdda(inputs.current_adc, vdda) == Some(ZeroResult::OutOfRange) {
            self.raise(FaultFlags::CURRENT_ZERO_RANGE);
        }
        let prev_position = self.encoder.position();
        self.encoder.update(now, inputs.encoder_count);
        let position = self.encoder.position();
        let dir = self.direction();
        let speed = self.encoder.speed_rad_s() * dir;
        // The output encoder before the capture: the capture holds its reading of this step.
        self.update_output_encoder(now);
        let output = self.output_position_counts().map(low16);
        self.capture.record_step(
            inputs.current_adc,
            low16(prev_position),
            low16(position),
            output,
        );

        let supply = self.bus_supply_v();
        self.speed_loop.set_supply_v(supply);
        self.update_release(now, inputs.release_button);
        self.check_hardware(now, position);

        if self.supervisor.state() == SupervisorState::Vibrating {
            let dir_i: i64 = if dir < 0.0 { -1 } else { 1 };
            let step = StepSamples {
                current_adc: inputs.current_adc,
                prev_us,
                now_us: now,
                prev_position: prev_position * dir_i,
                position: position * dir_i,
            };
            self.estimate_revolution(&step, now);
        }

        let dir_i: i64 = if dir < 0.0 { -1 } else { 1 };
        self.run_supervisor(now, speed, position * dir_i);

        if self.supervisor.drives_motor() && self.faults.latched().is_empty() {
            self.duty = self.drive_duty(speed, dt);
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
        self.send_streams(now, speed);
        self.record_stream_step(inputs.current_adc, prev_position, position, output);
        Outputs {
            duty: self.duty,
            enable: self.enable,
            persist: self.take_persist(now),
            capture: self.capture.phase() == CapturePhase::Recording,
        }
    }

    /// The continuous stream's part of the step: a copy of the readings into its ring (no
    /// packing here; `Core::transmit` packs), and the stream's heartbeat.
    fn record_stream_step(
        &mut self,
        adc: &[u16],
        prev_position: i64,
        position: i64,
        output: Option<u16>,
    ) {
        if !self.stream.on() {
            return;
        }
        if self
            .stream
            .check_timeout(self.now_us, self.config.comms_timeout_us)
        {
            return;
        }
        let mut state = self.supervisor.state() as u8;
        if !self.faults.latched().is_empty() {
            state |= protocol::STREAM_STATE_FAULTED;
        }
        let record = StepRecord {
            cam_prev: low16(prev_position),
            cam_now: low16(position),
            output: output.unwrap_or(0),
            duty: self.duty,
            tau_cam_nm: self.estimator.last().map_or(0.0, |e| e.tau_cam_nm),
            status: self.status_flags().bits(),
            state,
            ..StepRecord::default()
        };
        self.stream.record(adc, record);
    }

    /// Feeds the estimator; a completed revolution goes to the supervisor's load checks.
    fn estimate_revolution(&mut self, step: &StepSamples, now: u64) {
        let dir = self.direction();
        let current = &self.current;
        let estimate = self.estimator.update(step, &self.derived.model, |counts| {
            current.amps(counts) * dir
        });
        if let Some(e) = estimate {
            let check = RevolutionCheck {
                tau_cam: e.tau_cam_nm,
                tau_rot: e.tau_rot_nm,
                required_no_load: e.required_no_load_nm,
                required_max_load: self
                    .derived
                    .model
                    .required(self.derived.max_load_nm, e.cam_speed_rad_s),
                max_load: self.derived.max_load_nm,
                load_cap: self.config.supervisor.max_release_load_nm
                    * (1.0 + self.config.supervisor.load_cap_tolerance),
            };
            let raised = self.supervisor.on_revolution(&check, now);
            self.raise(raised);
        }
    }

    /// The duty of a running motor: the speed loop's, or an open-loop drive's fixed
    /// voltage.
    fn drive_duty(&mut self, speed: f32, dt: f32) -> f32 {
        let dir = self.direction();
        let Some(volts) = self.release.open_loop_volts else {
            let target = TAU * self.supervisor.target_hz();
            return self.speed_loop.update(target, speed, dt) * dir;
        };
        // A bench supply's fixed voltage, reached through the duty slew limit and a soft
        // start: the ramp pauses while the current is above 85 % of the overcurrent limit
        // and the cam is accelerating.
        let m = self.config.motor;
        // max/min, not clamp: clamp's NaN assertion would pull float formatting into the
        // image.
        let goal = (volts / self.bus_supply_v())
            .max(-m.max_duty)
            .min(m.max_duty)
            * dir;
        // Only while the cam turns: a shaft held on the force gauge draws its stall
        // current, which is what the calibration asks for.
        let accelerating = speed.abs() > self.config.supervisor.stop_speed_rad_s;
        let near_limit = self.current.step_mean_a().abs() > 0.85 * self.derived.current_limit_a;
        let step = if accelerating && near_limit && goal.abs() > self.duty.abs() {
            0.0
        } else {
            m.duty_slew_per_s * dt
        };
        goal.max(self.duty - step).min(self.duty + step)
    }

    /// A host release or open-loop drive lapses without an accepted request for the comms
    /// timeout; the button must be let go once before it releases.
    fn update_release(&mut self, now: u64, button: bool) {
        if self
            .release
            .update(now, button, self.config.comms_timeout_us)
        {
            self.raise(FaultFlags::COMMS_TIMEOUT);
        }
    }

    fn check_hardware(&mut self, now: u64, position: i64) {
        // The first layer: the comparator has already cut the bridge through the timer's
        // break; the core learns it here and keeps the motor off.
        if self.board.hw_break {
            self.raise(FaultFlags::HW_OVERCURRENT);
        }
        let f = self.config.faults;
        // A regenerating bridge pumping a supply that cannot sink (or a supply set too high):
        // the bus divider's reading, already averaged over 0.9 ms by its filter.
        if self.bus_overvoltage() {
            self.raise(FaultFlags::BUS_OVERVOLTAGE);
        }
        let i = self.current.step_mean_a();
        if self
            .faults
            .overcurrent(now, i, self.derived.current_limit_a, f.overcurrent_time_us)
        {
            self.raise(FaultFlags::OVERCURRENT);
        }
        // The encoder's own sign (before the drive direction) against the duty's: a
        // reversed or miswired encoder would make the speed loop run away.
        if self.faults.reversed(
            now,
            self.enable,
            self.duty,
            self.encoder.speed_rad_s(),
            self.config.supervisor.stop_speed_rad_s,
            f.reversed_time_us,
        ) {
            self.raise(FaultFlags::REVERSED_ENCODER);
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
            let v = self.duty.abs() * self.bus_supply_v();
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

    /// Whether the measured bridge bus is above its limit (false when not measured).
    pub(crate) fn bus_overvoltage(&self) -> bool {
        let v = self.board.bus_voltage_v;
        v.is_finite() && v > self.config.faults.bus_overvoltage_v
    }

    /// The bridge supply: the measured bus voltage when the board measures one (and it is
    /// plausible, above 1 V), the configured `supply_v` otherwise, V.
    pub(crate) fn bus_supply_v(&self) -> f32 {
        let v = self.board.bus_voltage_v;
        if v.is_finite() && v > 1.0 {
            v
        } else {
            self.config.supply_v
        }
    }

    fn run_supervisor(&mut self, now: u64, speed: f32, position: i64) {
        let before = self.supervisor.state();
        let open_loop_settled = self
            .release
            .open_loop_volts
            .map(|volts| self.open_loop_settled(now, position, volts));
        let r = &self.release;
        let mut inputs = SupervisorInputs {
            now_us: now,
            open_loop_settled,
            release_live: r.host || r.button_held || open_loop_settled.is_some(),
            requested_hz: r
                .requested_hz(self.config.supervisor.default_freq_hz)
                .min(self.derived.max_hz),
            faulted: !self.faults.latched().is_empty(),
            zero_ready: self.zero_ready(),
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

    /// Open-loop drive at `volts`: the voltage ramp is done and two consecutive cam
    /// revolutions took the same time within 2 % (`OpenLoopSettle`).
    fn open_loop_settled(&mut self, now: u64, position: i64, volts: f32) -> bool {
        let goal = volts / self.bus_supply_v() * self.direction();
        let ramp_done = (self.duty - goal).abs() < 1e-3;
        let per_rev = i64::from(self.config.counts_per_rev());
        self.release
            .open_loop
            .update(now, position, per_rev, ramp_done)
    }
}

/// The low 16 bits of an unwrapped encoder count, as the capture keeps them (the capture
/// takes wrapping differences only).
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "keeps the low 16 bits on purpose: wraps modulo 2^16"
)]
fn low16(count: i64) -> u16 {
    count as u16
}
