//! Cam-speed PI loop: target vibration frequency to PWM duty.
//!
//! The reference ramps to the target at a bounded acceleration (which bounds the
//! accelerating current), a feed-forward from the motor model supplies the steady duty
//! `(R i_noload(w) + ke w) / V`, and the PI trims the rest. Anti-windup is conditional
//! integration: the integrator holds whenever the limited duty differs from the unlimited
//! one in the direction the error pushes. The PI's authority around the feed-forward is
//! bounded (a lost speed signal cannot run the duty away), and the output is clamped to
//! `[0, max_duty]` (the
//! cam is only driven forward; braking through the bridge would exceed the current
//! sensor's range) and slew limited.

use crate::config::{MotorConfig, SpeedLoopConfig};

/// `x` limited to `[lo, hi]` (`hi` wins if they cross). Unlike `f32::clamp` it cannot
/// panic, which keeps float formatting out of the firmware image; NaN gives `lo`.
fn bound(x: f32, lo: f32, hi: f32) -> f32 {
    x.max(lo).min(hi)
}

/// Feed-forward model of the vibrator: no-load current `C5 w + C6` (SI) through `R`, plus
/// the back-EMF `ke w`, over the supply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedForward {
    /// Winding resistance, ohm.
    pub resistance_ohm: f32,
    /// Back-EMF constant at the cam, V s/rad.
    pub ke: f32,
    /// No-load current slope C5, A s/rad.
    pub c5: f32,
    /// No-load current offset C6, A.
    pub c6: f32,
    /// Bridge supply, V.
    pub supply_v: f32,
}

impl FeedForward {
    /// Duty that holds cam speed `w` (rad/s) at no load.
    pub fn duty(&self, w: f32) -> f32 {
        if w <= 0.0 {
            return 0.0;
        }
        let i = self.c5 * w + self.c6;
        (self.resistance_ohm * i + self.ke * w) / self.supply_v
    }
}

/// The speed controller's state.
#[derive(Debug, Clone)]
pub struct SpeedLoop {
    gains: SpeedLoopConfig,
    max_duty: f32,
    slew_per_s: f32,
    feed_forward: FeedForward,
    reference: f32,
    integral: f32,
    duty: f32,
}

impl SpeedLoop {
    /// A loop at rest.
    pub fn new(gains: SpeedLoopConfig, motor: &MotorConfig, feed_forward: FeedForward) -> Self {
        Self {
            gains,
            max_duty: bound(motor.max_duty, 0.0, 1.0),
            slew_per_s: motor.duty_slew_per_s,
            feed_forward,
            reference: 0.0,
            integral: 0.0,
            duty: 0.0,
        }
    }

    /// Replaces the feed-forward model (the calibration changed).
    pub fn set_feed_forward(&mut self, feed_forward: FeedForward) {
        self.feed_forward = feed_forward;
    }

    /// The bridge supply the feed-forward divides by, V (the measured bus voltage).
    pub fn set_supply_v(&mut self, supply_v: f32) {
        self.feed_forward.supply_v = supply_v;
    }

    /// Restarts from the measured speed (a new spin-up). The duty starts at the
    /// feed-forward of that speed: enabling the bridge at zero duty on a coasting motor
    /// would short it (ke w / R = 10 A at 55 rad/s).
    pub fn reset(&mut self, measured_rad_s: f32) {
        self.reference = measured_rad_s.max(0.0);
        self.integral = 0.0;
        self.duty = self.feed_forward.duty(self.reference);
        self.duty = bound(self.duty, 0.0, self.max_duty);
    }

    /// One control step of `dt` s toward `target_rad_s`; returns the duty magnitude.
    pub fn update(&mut self, target_rad_s: f32, measured_rad_s: f32, dt: f32) -> f32 {
        let max_step = self.gains.max_accel_rad_s2 * dt;
        self.reference += bound(target_rad_s - self.reference, -max_step, max_step);
        let error = self.reference - measured_rad_s;
        let feed_forward = self.feed_forward.duty(self.reference);
        let proportional = self.gains.kp * error;
        let integral = self.integral + self.gains.ki * error * dt;
        let unlimited = feed_forward + proportional + integral;
        let authority = self.gains.max_correction;
        let max_slew = self.slew_per_s * dt;
        let limited = bound(
            unlimited,
            feed_forward - authority,
            feed_forward + authority,
        );
        let limited = bound(limited, 0.0, self.max_duty);
        let limited = bound(limited, self.duty - max_slew, self.duty + max_slew);
        // Integrate only while the limits do not already push the same way as the error.
        let pushed_by_limit = limited != unlimited && (unlimited - limited) * error > 0.0;
        if !pushed_by_limit {
            self.integral = integral;
        }
        self.duty = limited;
        limited
    }

    /// Duty of the last step.
    #[cfg(test)]
    pub fn duty(&self) -> f32 {
        self.duty
    }

    /// Ramped speed reference, rad/s.
    pub fn reference(&self) -> f32 {
        self.reference
    }

    /// Integrator state, duty.
    #[cfg(test)]
    pub fn integral(&self) -> f32 {
        self.integral
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::hardware::{board, rs735};
    use model::paper;
    use model::plant::{Drive, Load, Plant, PlantParams};

    fn feed_forward() -> FeedForward {
        let c = paper::CALIBRATION;
        FeedForward {
            resistance_ohm: rs735::RESISTANCE_OHM as f32,
            ke: rs735::KE_CAM_V_S_PER_RAD as f32,
            c5: c.c5 as f32,
            c6: c.c6 as f32,
            supply_v: board::BRIDGE_SUPPLY_V as f32,
        }
    }

    fn controller() -> SpeedLoop {
        SpeedLoop::new(
            SpeedLoopConfig::default(),
            &MotorConfig::default(),
            feed_forward(),
        )
    }

    /// Runs the loop at 1 kHz on the plant (10 kHz) for `seconds`; returns the speed trace.
    fn run(plant: &mut Plant, pi: &mut SpeedLoop, target: f32, seconds: f64) -> Vec<f64> {
        let mut trace = Vec::new();
        let mut drive = Drive::default();
        for _ in 0..(seconds * 1000.0) as usize {
            for _ in 0..10 {
                plant.step(1e-4, drive);
            }
            let w = plant.state().cam_speed as f32;
            drive = Drive {
                duty: f64::from(pi.update(target, w, 1e-3)),
                enabled: true,
            };
            trace.push(plant.state().cam_speed);
        }
        trace
    }

    fn plant(load_nm: f64) -> Plant {
        Plant::new(
            PlantParams::paper(paper::RIG_GEARS, Load::Torque(load_nm)),
            7,
        )
    }

    #[test]
    fn step_response_on_the_plant() {
        for (load, hz) in [(0.0, 10.0f32), (3.68, 10.0), (1.0, 5.0), (0.5, 20.0)] {
            let target = core::f32::consts::TAU * hz;
            let mut p = plant(load);
            let mut pi = controller();
            let trace = run(&mut p, &mut pi, target, 3.0);
            let target = f64::from(target);
            // The ramp takes target / 60 rad/s^2; settle within 0.4 s after it.
            let ramp_s = target / 60.0;
            let settled = &trace[((ramp_s + 0.4) * 1000.0) as usize..];
            let worst = settled
                .iter()
                .map(|w| ((w - target) / target).abs())
                .fold(0.0, f64::max);
            assert!(worst < 0.03, "{load} N m, {hz} Hz: error {worst}");
            let peak = trace.iter().cloned().fold(0.0, f64::max);
            assert!(
                peak < target * 1.08,
                "{load} N m, {hz} Hz: overshoot {peak}"
            );
        }
    }

    #[test]
    fn anti_windup_recovers_without_a_large_overshoot() {
        let mut pi = controller();
        // Held back (a stuck cam): the duty saturates while the integrator must not run away.
        for _ in 0..2000 {
            pi.update(100.0, 0.0, 1e-3);
        }
        assert!(pi.duty() > 0.9, "{}", pi.duty());
        assert!(
            pi.integral() < 0.95,
            "integral wound up to {}",
            pi.integral()
        );
        // Released: the overshoot is what the slew-limited way down from full duty costs
        // (0.5/s), not a wound-up integrator, and the speed settles.
        let mut p = plant(0.0);
        let trace = run(&mut p, &mut pi, 100.0, 2.5);
        let peak = trace.iter().cloned().fold(0.0, f64::max);
        assert!(peak < 100.0 * 1.25, "overshoot to {peak}");
        let settled = trace[1500..].iter().all(|w| (w - 100.0).abs() < 3.0);
        assert!(settled, "{:?}", &trace[1500..1510]);
    }

    #[test]
    fn duty_is_slew_limited_and_clamped() {
        let mut pi = controller();
        let mut last = 0.0f32;
        for _ in 0..1000 {
            let d = pi.update(1000.0, 0.0, 1e-3);
            assert!(d - last <= 0.5e-3 + 1e-6);
            assert!((0.0..=0.95).contains(&d));
            last = d;
        }
        pi.reset(0.0);
        assert_eq!(pi.update(-50.0, 10.0, 1e-3), 0.0);
    }
}
