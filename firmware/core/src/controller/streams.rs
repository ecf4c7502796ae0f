//! The unsolicited streams: telemetry at the host's rate, a health sample once a second
//! while telemetry runs, and the control step's CPU-cycle statistics that health reports.
//!
//! The control step only takes the samples; [`Core::transmit`] frames them (postcard,
//! CRC, COBS) when the link asks for bytes, so framing stays out of the 1 kHz step. A
//! sample the link did not take before the next one is superseded and counted as dropped.

use protocol::{
    Capabilities, DeviceMessage, HealthSample, ParametersStatus, StatusFlags, TelemetrySample,
};

use super::Core;
use crate::capture::CapturePhase;
use crate::tx_queue::REPLY_RESERVE;

/// Health sample period, us.
const HEALTH_PERIOD_US: u64 = HealthSample::PERIOD_MS as u64 * 1000;

/// Telemetry pacing, in control steps.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Streams {
    /// Steps between samples; 0: telemetry off.
    pub(crate) telemetry_period: u32,
    countdown: u32,
    telemetry_seq: u32,
    /// Device time the next health sample is due (telemetry on).
    health_due_us: Option<u64>,
    /// Taken by the step, framed by `transmit`.
    pending_telemetry: Option<TelemetrySample>,
    pending_health: Option<HealthSample>,
}

impl Streams {
    /// Starts telemetry every `period` steps (at least 1), a health sample at once and
    /// then every second.
    pub(crate) fn start(&mut self, period: u32) {
        self.telemetry_period = period.max(1);
        self.countdown = 0;
        self.health_due_us.get_or_insert(0);
    }

    /// Stops telemetry and health.
    pub(crate) fn stop(&mut self) {
        self.telemetry_period = 0;
        self.health_due_us = None;
    }
}

/// CPU cycles of the control step, summarised per second of device time.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct StepTiming {
    window_start_us: u64,
    sum: u64,
    count: u32,
    max: u32,
    /// Mean and largest of the last full second (0 until one has passed).
    last: (u32, u32),
}

impl StepTiming {
    fn record(&mut self, now_us: u64, cycles: u32) {
        if now_us.saturating_sub(self.window_start_us) >= HEALTH_PERIOD_US {
            if self.count > 0 {
                // In 32 bits when the sum fits (a second's steps on a 170 MHz core always
                // do: no 64-bit division in the image); a larger sum, which only a test can
                // report, to f32's precision.
                let mean = match u32::try_from(self.sum) {
                    Ok(sum) => sum.checked_div(self.count),
                    Err(_) => Some(clamp_to_u32(self.sum as f32 / self.count as f32)),
                };
                self.last = (mean.unwrap_or(0), self.max);
            }
            *self = Self {
                window_start_us: now_us,
                last: self.last,
                ..Self::default()
            };
        }
        self.sum = self.sum.saturating_add(u64::from(cycles));
        self.count = self.count.saturating_add(1);
        self.max = self.max.max(cycles);
    }
}

/// `v` rounded toward zero into `u32` (saturating).
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "float-to-int `as` saturates, which is the intent"
)]
fn clamp_to_u32(v: f32) -> u32 {
    v as u32
}

impl Core {
    /// The binary's measurement of the step that just ran, in CPU cycles (DWT CYCCNT on
    /// the Cortex-M4); the health sample reports their mean and maximum per second. A
    /// core nobody reports to (the virtual rig) reports 0.
    pub fn record_step_cycles(&mut self, cycles: u32) {
        self.step_timing.record(self.now_us, cycles);
    }

    pub(super) fn status_flags(&self) -> StatusFlags {
        let mut s = StatusFlags::empty();
        s.set(StatusFlags::COASTS_AFTER_STOP, self.derived.keeps_moving);
        s.set(StatusFlags::NOT_SELF_LOCKING, !self.derived.holds_at_rest);
        s.set(StatusFlags::HOST_RELEASE, self.release.host);
        s.set(StatusFlags::BUTTON_RELEASE, self.release.button_held);
        s.set(
            StatusFlags::CAPTURE_RUNNING,
            self.capture.phase() == CapturePhase::Recording,
        );
        s.set(
            StatusFlags::CALIBRATION_DEFAULTS,
            self.parameters_status != ParametersStatus::Valid,
        );
        s.set(
            StatusFlags::OPEN_LOOP,
            self.release.open_loop_volts.is_some(),
        );
        s.set(StatusFlags::OUTPUT_MOVING, self.output_moving());
        s
    }

    /// Queues the streams due at this step (`speed`: the cam speed in the drive direction).
    pub(super) fn send_streams(&mut self, now: u64, speed: f32) {
        if self.streams.telemetry_period == 0 {
            return;
        }
        if self.streams.health_due_us.is_some_and(|due| now >= due) {
            self.streams.health_due_us = Some(now + HEALTH_PERIOD_US);
            let health = self.health(now);
            if self.streams.pending_health.replace(health).is_some() {
                self.tx.note_dropped();
            }
        }
        self.streams.countdown = self.streams.countdown.saturating_sub(1);
        if self.streams.countdown > 0 {
            return;
        }
        self.streams.countdown = self.streams.telemetry_period;
        let estimate = self.estimator.last();
        let sample = TelemetrySample {
            seq: self.streams.telemetry_seq,
            device_time_us: now,
            cam_speed_rad_s: speed,
            current_a: self.current.filtered_a(),
            pwm_duty: self.duty,
            tau_cam_nm: estimate.map_or(0.0, |e| e.tau_cam_nm),
            tau_rot_nm: estimate.map_or(0.0, |e| e.tau_rot_nm),
            state: self.supervisor.state(),
            faults: self.faults.latched(),
            status: self.status_flags(),
            // NaN without an output encoder (Capabilities::OUTPUT_ENCODER clear).
            output_angle_rad: self.output_motion().map_or(f32::NAN, |m| m.0),
            output_speed_rad_s: self.output_motion().map_or(f32::NAN, |m| m.1),
        };
        // Sequence numbers advance even for a dropped sample: the host sees the gap.
        self.streams.telemetry_seq = self.streams.telemetry_seq.wrapping_add(1);
        if self.streams.pending_telemetry.replace(sample).is_some() {
            self.tx.note_dropped();
        }
    }

    /// Frames the samples the steps took (health first), for `transmit`; whether there
    /// were any.
    pub(super) fn frame_streams(&mut self) -> bool {
        let mut any = false;
        if let Some(health) = self.streams.pending_health.take() {
            self.tx.push(&DeviceMessage::Health(health), REPLY_RESERVE);
            any = true;
        }
        if let Some(sample) = self.streams.pending_telemetry.take() {
            self.tx
                .push(&DeviceMessage::Telemetry(sample), REPLY_RESERVE);
            any = true;
        }
        any
    }

    fn health(&self, now: u64) -> HealthSample {
        let (step_cycles_mean, step_cycles_max) = self.step_timing.last;
        HealthSample {
            device_time_us: now,
            // What the binary measures (BoardInputs); NaN where not fitted. The bus
            // voltage only where `Info` declares the divider (`BUS_VOLTAGE`), so a host
            // never reads a value the device says it cannot measure; the thermistor is
            // detected at run time (an open input reads NaN).
            bus_voltage_v: if self.config.capabilities.contains(Capabilities::BUS_VOLTAGE) {
                self.board.bus_voltage_v
            } else {
                f32::NAN
            },
            motor_temp_c: self.board.motor_temp_c,
            step_cycles_mean,
            step_cycles_max,
            rx_frame_errors: self.deframer.stats().errors(),
            tx_frames_dropped: self.tx.dropped(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_timing_reports_the_last_full_second() {
        let mut t = StepTiming::default();
        for k in 0..1000u64 {
            t.record(k * 1000, 20_000 + (k % 3) as u32 * 1000);
        }
        assert_eq!(t.last, (0, 0), "nothing before a second has passed");
        t.record(1_000_000, 50_000);
        // 1000 steps of 20 000, 21 000 and 22 000 cycles in turn.
        assert_eq!(t.last.1, 22_000);
        assert!((20_990..=21_000).contains(&t.last.0), "{:?}", t.last);
        for k in 1..1000u64 {
            t.record(1_000_000 + k * 1000, 10_000);
        }
        t.record(2_000_000, 0);
        assert_eq!(t.last, (10_040, 50_000));
    }
}
