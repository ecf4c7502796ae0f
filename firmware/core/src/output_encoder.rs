//! The optional output-shaft encoder: a second quadrature encoder on the output shaft
//! (suggested: TIM3 in encoder mode on PC6/PC7, five-volt-tolerant pins, x4 decoding).
//! Its 16-bit hardware count becomes the output angle and speed in telemetry, tells
//! whether the output is moving (backdrive: `StatusFlags::OUTPUT_MOVING`), and trips
//! `FaultFlags::OUTPUT_OVERSPEED` when the load runs away.
//!
//! The core's wiring is behind the `output-encoder` feature (on in the simulator; off in the
//! firmware image until the board reads the encoder, as it costs flash).
//!
//! Without it fitted ([`crate::CoreConfig::output_encoder`] is `None`) telemetry reports
//! NaN and `Info` leaves `Capabilities::OUTPUT_ENCODER` clear.

use core::f32::consts::TAU;

/// The output encoder's configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputEncoderConfig {
    /// Quadrature counts per output revolution (x4 decoding: 4 x pulses per revolution).
    pub counts_per_rev: u32,
    /// Output speed above which the output counts as moving (backdriven), rad/s.
    pub moving_rad_s: f32,
    /// Output speed above which `OUTPUT_OVERSPEED` latches and vibration stops, rad/s.
    pub overspeed_rad_s: f32,
    /// Window the speed is measured over, us.
    pub speed_window_us: u64,
}

impl Default for OutputEncoderConfig {
    /// An AMT102-V at 2048 pulses per revolution on the output; moving above 0.01 rad/s
    /// (3.8 counts in 0.05 s); overspeed at 20 rad/s (the paper's Fig. 5 load falls at
    /// about 1 rad/s: 20 rad/s is a runaway, 1.5 m/s of rope on a 75 mm pulley).
    fn default() -> Self {
        Self {
            counts_per_rev: 4 * 2048,
            moving_rad_s: 0.01,
            overspeed_rad_s: 20.0,
            speed_window_us: 50_000,
        }
    }
}

/// Output angle and speed from the output encoder's count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputEncoder {
    config: OutputEncoderConfig,
    last_count: Option<u16>,
    position: i64,
    window_start: (u64, i64),
    speed: f32,
}

impl OutputEncoder {
    /// An encoder at angle 0.
    pub fn new(config: OutputEncoderConfig) -> Self {
        Self {
            config,
            last_count: None,
            position: 0,
            window_start: (0, 0),
            speed: 0.0,
        }
    }

    /// Takes the hardware count at `now_us` (16-bit, wrapping).
    pub fn update(&mut self, now_us: u64, count: u16) {
        match self.last_count {
            None => self.window_start = (now_us, 0),
            Some(last) => self.position += i64::from(count.wrapping_sub(last).cast_signed()),
        }
        self.last_count = Some(count);
        let (t0, p0) = self.window_start;
        let dt = now_us.saturating_sub(t0);
        if dt >= self.config.speed_window_us.max(1) {
            let revs = (self.position - p0) as f32 / self.config.counts_per_rev.max(1) as f32;
            self.speed = revs * TAU / (dt as f32 * 1e-6);
            self.window_start = (now_us, self.position);
        }
    }

    /// Output angle since boot, rad.
    pub fn angle_rad(&self) -> f32 {
        self.position as f32 / self.config.counts_per_rev.max(1) as f32 * TAU
    }

    /// Output position since boot, quadrature counts (not wrapped); `None` before the
    /// first reading.
    pub fn position_counts(&self) -> Option<i64> {
        self.last_count.map(|_| self.position)
    }

    /// Output speed over the last window, rad/s.
    pub fn speed_rad_s(&self) -> f32 {
        self.speed
    }

    /// The output turns (backdrive).
    pub fn moving(&self) -> bool {
        self.speed.abs() > self.config.moving_rad_s
    }

    /// The output turns faster than the configured limit.
    pub fn overspeed(&self) -> bool {
        self.speed.abs() > self.config.overspeed_rad_s
    }
}

impl crate::Core {
    /// The output encoder's hardware count for the next [`crate::Core::step`] (`None`:
    /// no new reading; ignored when no output encoder is configured).
    pub fn set_output_encoder_count(&mut self, count: Option<u16>) {
        self.output_count = count;
    }

    /// The output turns by the output encoder (false without one).
    pub fn output_moving(&self) -> bool {
        cfg!(feature = "output-encoder") && self.output_encoder.is_some_and(|e| e.moving())
    }

    /// Output position by the output encoder, counts since boot (`None` without one, or
    /// before its first reading).
    pub(crate) fn output_position_counts(&self) -> Option<i64> {
        if !cfg!(feature = "output-encoder") {
            return None;
        }
        self.output_encoder.and_then(|e| e.position_counts())
    }

    /// Output angle and speed by the output encoder, rad and rad/s (`None` without one).
    pub fn output_motion(&self) -> Option<(f32, f32)> {
        if !cfg!(feature = "output-encoder") {
            return None;
        }
        self.output_encoder
            .map(|e| (e.angle_rad(), e.speed_rad_s()))
    }

    /// One control step's output-encoder work: the count in, the overspeed check.
    pub(crate) fn update_output_encoder(&mut self, now: u64) {
        if !cfg!(feature = "output-encoder") {
            return;
        }
        let (Some(encoder), Some(count)) = (self.output_encoder.as_mut(), self.output_count) else {
            return;
        };
        encoder.update(now, count);
        if encoder.overspeed() {
            self.raise(protocol::FaultFlags::OUTPUT_OVERSPEED);
        }
    }
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests {
    use super::*;

    #[test]
    fn counts_become_angle_and_speed_across_the_wrap() {
        let mut e = OutputEncoder::new(OutputEncoderConfig::default());
        let cpr = 8192.0f32;
        // 1 rad/s: 8192 / TAU counts per second, from just below the 16-bit wrap.
        let mut count = 65_000u16;
        let mut acc = 0.0f32;
        for ms in 0..=1000u64 {
            e.update(ms * 1000, count);
            acc += cpr / TAU / 1000.0;
            let whole = acc.floor();
            acc -= whole;
            count = count.wrapping_add(whole as u16);
        }
        assert!((e.angle_rad() - 1.0).abs() < 0.01, "{}", e.angle_rad());
        assert!((e.speed_rad_s() - 1.0).abs() < 0.02, "{}", e.speed_rad_s());
        assert!(e.moving() && !e.overspeed());
    }

    #[test]
    fn standing_still_is_not_moving_and_a_runaway_is_overspeed() {
        let mut e = OutputEncoder::new(OutputEncoderConfig::default());
        for ms in 0..200u64 {
            e.update(ms * 1000, 123);
        }
        assert_eq!(e.speed_rad_s(), 0.0);
        assert!(!e.moving());
        // 30 rad/s backwards: 39 counts per ms.
        let mut count = 123u16;
        for ms in 200..400u64 {
            count = count.wrapping_sub(39);
            e.update(ms * 1000, count);
        }
        assert!(e.speed_rad_s() < -25.0, "{}", e.speed_rad_s());
        assert!(e.overspeed());
    }
}
