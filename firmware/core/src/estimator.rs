//! Cam torque and output load, averaged over each cam revolution.
//!
//! tau_cam = C1 i + C2 - (C3 w + C4) (Eqs. 15-17) is linear in i and w, so its revolution
//! mean is that of the revolution's mean current and mean speed. Per sample the estimator
//! only adds raw ADC counts; at each revolution boundary (interpolated inside the step) it
//! converts once and inverts Eq. (10) for the load tau_rot, in single precision with
//! [`Coefficients`] derived once from the rig parameters (the Cortex-M4F's FPU is f32 only;
//! [`EstimatorModel`] is the same model in f64 on the model's own functions, and the tests
//! hold the two together).
//!
//! Eq. (9)'s inertia term exchanges power with the carrier and averages to zero over a
//! turn when the drive takes power back; the paper's Eq. (10) is the mean over the
//! acceleration phase and carries `M w^2 e^2 / pi`. How much of it a revolution mean holds
//! is the model's inertia-rectification law ([`model::effects::rectified_inertia_torque`])
//! with the drive's kappa ([`model::effects::drive_kappa`] of
//! [`crate::config::EstimatorConfig::carrier_power_returned`]: -1 returned, -1/2 not): the
//! plant and `rig explain` use the same law. The rest of Eq. (10)'s term is added to the
//! measured mean before Eq. (10) is inverted, and left out of the requirement the
//! supervisor compares against.

use core::f32::consts::TAU;

use model::CamDrive;
use model::effects::{drive_kappa, rectified_inertia_torque};

/// Calibration and geometry the estimator works with, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorModel {
    /// The cam drive: gear set, eccentricity and carrier mass.
    pub drive: CamDrive,
    /// Vibrator constants C1..C6.
    pub vibrator: model::Calibration,
    /// Friction coefficient used in Eq. (10) (the calibration's mu_s).
    pub mu: f64,
    /// Whether the revolution mean lacks Eq. (9)'s inertia term (see the module doc).
    pub carrier_power_returned: bool,
}

impl EstimatorModel {
    /// Cam torque from mean current `i` (A) and mean speed `w` (rad/s), N m.
    pub fn cam_torque(&self, i: f64, w: f64) -> f64 {
        self.vibrator.cam_torque(i, w)
    }

    /// Inertia share present in a revolution mean at speed `w`, N m: none when the drive
    /// takes the carrier's power back; otherwise the rectified half of Eq. (9)'s inertia
    /// term, M w^2 e^2 / (2 pi), half of Eq. (10)'s acceleration-phase mean (the model's
    /// inertia-rectification law with the drive's kappa).
    fn inertia_in_mean(&self, w: f64) -> f64 {
        rectified_inertia_torque(&self.drive, w, drive_kappa(self.carrier_power_returned))
    }

    /// Load torque explaining a revolution-mean cam torque at speed `w`, by inverting Eq. (10).
    pub fn load(&self, tau_cam: f64, w: f64) -> f64 {
        let added_back = self.drive.required_inertia_torque(w) - self.inertia_in_mean(w);
        self.drive
            .load_from_cam_torque(self.mu, tau_cam + added_back, w)
    }

    /// Revolution-mean cam torque Eq. (10) predicts for load `tau_rot` at speed `w`, N m.
    pub fn required(&self, tau_rot: f64, w: f64) -> f64 {
        self.drive.required_cam_torque(self.mu, tau_rot, w) - self.drive.required_inertia_torque(w)
            + self.inertia_in_mean(w)
    }
}

impl EstimatorModel {
    /// The single-precision coefficients of this model (host side: the model's f64
    /// functions; the firmware derives them in f32, see `controller::derived`).
    pub fn coefficients(&self) -> Coefficients {
        let slope = self.drive.required_cam_torque(self.mu, 1.0, 0.0);
        Coefficients::new(
            [
                self.vibrator.c1,
                self.vibrator.c2,
                self.vibrator.c3,
                self.vibrator.c4,
            ]
            .map(to_f32),
            to_f32(slope),
            to_f32(self.drive.required_inertia_torque(1.0)),
            self.carrier_power_returned,
        )
    }
}

/// Eq. (10) and the vibrator's torque, reduced to single-precision coefficients: what the
/// estimator evaluates at each revolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients {
    /// C1 (N m/A), C2 (N m), C3 (N m s/rad), C4 (N m).
    c: [f32; 4],
    /// Eq. (10)'s friction part per newton metre of load: 2/pi mu e (axial force per torque).
    per_load: f32,
    /// The inertia share present in a revolution mean per (rad/s)^2: (1 + kappa) M e^2 / pi
    /// with the drive's kappa (`model::effects::drive_kappa`).
    inertia_in_mean: f32,
}

impl Coefficients {
    /// From the vibrator constants (SI), Eq. (10)'s slope per unit load and its inertia
    /// term per (rad/s)^2, M e^2 / pi.
    pub fn new(c: [f32; 4], per_load: f32, inertia: f32, carrier_power_returned: bool) -> Self {
        Self {
            c,
            per_load,
            // (1 + kappa) of M e^2 / pi: 0.18 of it for a braking drive (its return through
            // the gearhead, `model::effects::KAPPA_BRAKING_DRIVE`), 1/2 for a coasting one.
            #[allow(clippy::cast_possible_truncation)] // a fraction in [0, 1/2]
            inertia_in_mean: (1.0 + drive_kappa(carrier_power_returned)) as f32 * inertia,
        }
    }

    /// Cam torque from mean current `i` (A) and mean speed `w` (rad/s), N m.
    pub fn cam_torque(&self, i: f32, w: f32) -> f32 {
        let [c1, c2, c3, c4] = self.c;
        c1 * i + c2 - (c3 * w.abs() + c4)
    }

    /// Load torque explaining a revolution-mean cam torque at speed `w` (Eq. 10 inverted).
    pub fn load(&self, tau_cam: f32, w: f32) -> f32 {
        (tau_cam - self.inertia_in_mean * w * w) / self.per_load
    }

    /// Revolution-mean cam torque Eq. (10) predicts for load `tau_rot` at speed `w`, N m.
    pub fn required(&self, tau_rot: f32, w: f32) -> f32 {
        self.per_load * tau_rot.abs() + self.inertia_in_mean * w * w
    }
}

/// One revolution's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RevolutionEstimate {
    /// Mean motor current over the revolution, A.
    pub current_a: f32,
    /// Mean cam speed over the revolution, rad/s.
    pub cam_speed_rad_s: f32,
    /// Mean torque delivered to the cam, tau_cam, N m.
    pub tau_cam_nm: f32,
    /// Output load from Eq. (10) inverted, tau_rot, N m.
    pub tau_rot_nm: f32,
    /// Eq. (10)'s zero-load requirement at this speed, N m.
    pub required_no_load_nm: f32,
}

/// Accumulates samples between revolution boundaries.
#[derive(Debug, Clone)]
pub struct TorqueEstimator {
    counts_per_rev: i64,
    max_revolution_us: u64,
    running: bool,
    next_boundary: i64,
    /// Time of the last boundary: whole microseconds and the fraction.
    last_cross_us: (u64, f32),
    sum_counts: u64,
    samples: u32,
    last: Option<RevolutionEstimate>,
    revolutions: u32,
}

/// One control step as the estimator needs it.
#[derive(Debug, Clone, Copy)]
pub struct StepSamples<'a> {
    /// Raw current samples of the step, oldest first.
    pub current_adc: &'a [u16],
    /// Time of the previous step, us.
    pub prev_us: u64,
    /// Time of this step, us.
    pub now_us: u64,
    /// Unwrapped position at the previous step, counts (in the drive direction).
    pub prev_position: i64,
    /// Unwrapped position now, counts (in the drive direction).
    pub position: i64,
}

impl TorqueEstimator {
    /// An idle estimator.
    pub fn new(counts_per_rev: u32, max_revolution_us: u64) -> Self {
        Self {
            counts_per_rev: i64::from(counts_per_rev.max(1)),
            max_revolution_us,
            running: false,
            next_boundary: 0,
            last_cross_us: (0, 0.0),
            sum_counts: 0,
            samples: 0,
            last: None,
            revolutions: 0,
        }
    }

    /// Starts a fresh revolution at `position` (counts, drive direction) at `now_us`.
    pub fn start(&mut self, now_us: u64, position: i64) {
        self.running = true;
        self.next_boundary = position + self.counts_per_rev;
        self.last_cross_us = (now_us, 0.0);
        self.sum_counts = 0;
        self.samples = 0;
        self.revolutions = 0;
    }

    /// Stops accumulating; the last estimate is kept for display.
    pub fn stop(&mut self) {
        self.running = false;
    }

    /// Completed revolutions since [`TorqueEstimator::start`].
    pub fn revolutions(&self) -> u32 {
        self.revolutions
    }

    /// The last completed revolution's estimate.
    pub fn last(&self) -> Option<RevolutionEstimate> {
        self.last
    }

    /// Takes one step; returns an estimate when a revolution completed within it.
    /// `to_amps` converts a mean ADC reading to amperes (zero offset applied).
    pub fn update(
        &mut self,
        step: &StepSamples,
        model: &Coefficients,
        to_amps: impl Fn(f32) -> f32,
    ) -> Option<RevolutionEstimate> {
        if !self.running {
            return None;
        }
        let n = step.current_adc.len();
        let mut result = None;
        if step.position >= self.next_boundary && step.position > step.prev_position {
            // Where in the step the boundary fell, by linear interpolation of the position.
            let frac = (self.next_boundary - step.prev_position) as f32
                / (step.position - step.prev_position) as f32;
            let frac = frac.clamp(0.0, 1.0);
            #[allow(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "frac is clamped to [0, 1]: a sample index 0..=n"
            )]
            let split = (frac * n as f32 + 0.5) as usize;
            let (before, after) = step.current_adc.split_at(split.min(n));
            self.add(before);
            let offset = frac * step.now_us.saturating_sub(step.prev_us) as f32;
            #[allow(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "0 <= offset <= the step's length in us"
            )]
            let whole = offset as u64;
            let cross_us = (step.prev_us + whole, offset - whole as f32);
            let period_us = cross_us.0.saturating_sub(self.last_cross_us.0) as f32
                + (cross_us.1 - self.last_cross_us.1);
            if self.samples > 0 && period_us > 0.0 && period_us <= self.max_revolution_us as f32 {
                let mean_counts = self.sum_counts as f32 / self.samples as f32;
                let i = to_amps(mean_counts);
                let w = TAU / (period_us * 1e-6);
                let tau_cam = model.cam_torque(i, w);
                let estimate = RevolutionEstimate {
                    current_a: i,
                    cam_speed_rad_s: w,
                    tau_cam_nm: tau_cam,
                    tau_rot_nm: model.load(tau_cam, w),
                    required_no_load_nm: model.required(0.0, w),
                };
                self.last = Some(estimate);
                self.revolutions = self.revolutions.saturating_add(1);
                result = Some(estimate);
            }
            self.last_cross_us = cross_us;
            self.sum_counts = 0;
            self.samples = 0;
            // A step spanning several turns (not at 1 kHz) restarts the count past it.
            while self.next_boundary <= step.position {
                self.next_boundary += self.counts_per_rev;
            }
            self.add(after);
        } else {
            self.add(step.current_adc);
        }
        result
    }

    fn add(&mut self, samples: &[u16]) {
        let mut sum = 0u32;
        for &s in samples {
            sum += u32::from(s);
        }
        self.sum_counts += u64::from(sum);
        self.samples = self
            .samples
            .saturating_add(u32::try_from(samples.len()).unwrap_or(u32::MAX));
    }
}

/// An f64 coefficient of the model in the target's f32 (derived once per parameter record).
#[allow(
    clippy::cast_possible_truncation,
    reason = "the estimator runs in f32 on the target; rounding to nearest is the intent"
)]
fn to_f32(x: f64) -> f32 {
    x as f32
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
    use crate::config::CurrentSensorConfig;
    use core::f64::consts::TAU;
    use model::effects::carrier_inertia_torque;
    use model::{hardware, paper};

    const CPR: u32 = hardware::amt102::COUNTS_PER_REV;

    fn model() -> EstimatorModel {
        EstimatorModel {
            drive: CamDrive::paper(paper::RIG_GEARS),
            vibrator: paper::CALIBRATION,
            mu: paper::MU_S,
            carrier_power_returned: true,
        }
    }

    /// Feeds `revs` revolutions at `w` rad/s of current `i(theta)` sampled at 10 kHz, 1 kHz
    /// steps; returns every estimate.
    fn feed(
        est: &mut TorqueEstimator,
        w: f64,
        revs: f64,
        current: impl Fn(f64) -> f64,
    ) -> Vec<RevolutionEstimate> {
        let sensor = CurrentSensorConfig::default();
        let zero = f64::from(sensor.nominal_zero_counts());
        let apc = f64::from(sensor.amps_per_count());
        let mut out = Vec::new();
        let steps = (revs * TAU / w * 1000.0) as u64;
        est.start(0, 0);
        let mut prev = 0i64;
        for k in 1..=steps {
            let mut block = [0u16; 10];
            for (j, b) in block.iter_mut().enumerate() {
                let t = (k - 1) as f64 * 1e-3 + (j + 1) as f64 * 1e-4;
                *b = libm::round(zero + current(w * t) / apc) as u16;
            }
            let t = k as f64 * 1e-3;
            let pos = libm::floor(w * t / TAU * f64::from(CPR)) as i64;
            let step = StepSamples {
                current_adc: &block,
                prev_us: (k - 1) * 1000,
                now_us: k * 1000,
                prev_position: prev,
                position: pos,
            };
            prev = pos;
            let to_amps = |c: f32| ((f64::from(c) - zero) * apc) as f32;
            out.extend(est.update(&step, &model().coefficients(), to_amps));
        }
        out
    }

    #[test]
    fn recovers_the_load_from_a_rippling_current() {
        let m = model();
        for (tau_rot, hz) in [
            (0.368, 5.0),
            (1.84, 10.0),
            (3.68, 10.0),
            (3.68, 15.0),
            (1.0, 20.0),
        ] {
            let w = TAU * hz;
            // Revolution-mean torque Eq. (10) predicts, and Eq. (9)'s ripple around it:
            // friction |sin| (twice per turn) and the inertia term sin cos.
            let tau_mean = m.required(tau_rot, w);
            let friction = tau_mean * core::f64::consts::PI / 2.0;
            let (mass, e) = (m.drive.carrier_mass, m.drive.eccentricity);
            let i = |theta: f64| {
                let (s, c) = (libm::sin(theta), libm::cos(theta));
                let tau = friction * libm::fabs(s) + carrier_inertia_torque(mass, e, s, c, w);
                m.vibrator.current_for(tau, w)
            };
            let est = feed(&mut TorqueEstimator::new(CPR, 2_000_000), w, 6.3, i);
            assert_eq!(est.len(), 6, "{hz} Hz");
            for e in &est[1..] {
                let tau_err = (f64::from(e.tau_cam_nm) - tau_mean) / tau_mean;
                let rot_err = (f64::from(e.tau_rot_nm) - tau_rot) / tau_rot;
                let w_err = (f64::from(e.cam_speed_rad_s) - w) / w;
                assert!(
                    tau_err.abs() < 0.01,
                    "{tau_rot} N m {hz} Hz: tau_cam {tau_err}"
                );
                assert!(
                    rot_err.abs() < 0.02,
                    "{tau_rot} N m {hz} Hz: tau_rot {rot_err}"
                );
                assert!(w_err.abs() < 0.005, "{hz} Hz: speed {w_err}");
            }
        }
    }

    #[test]
    fn a_drive_that_cannot_take_power_back_keeps_the_rectified_inertia_term() {
        let mut m = model();
        let w = TAU * 10.0;
        let inertia = m.drive.required_inertia_torque(w);
        // A braking drive returns eta_f eta_b = 64 % of it through the gearhead: 0.18 left.
        assert!((m.required(0.0, w) - 0.18 * inertia).abs() < 1e-9 * inertia.max(1.0));
        let c = m.coefficients();
        let f32_share = c.required(0.0, w as f32) / inertia as f32;
        assert!((f32_share - 0.18).abs() < 1e-4, "{f32_share}");
        m.carrier_power_returned = false;
        // Rectified over a turn: M w^2 e^2 / (2 pi), half of Eq. (10)'s term.
        assert!((m.required(0.0, w) - 0.5 * inertia).abs() < 1e-12);
        // Both conventions invert their own requirement exactly.
        for returned in [true, false] {
            m.carrier_power_returned = returned;
            let tau = m.required(2.0, w);
            assert!((m.load(tau, w) - 2.0).abs() < 1e-9);
        }
    }

    #[test]
    fn idle_or_slow_cam_gives_no_estimate() {
        let mut est = TorqueEstimator::new(CPR, 2_000_000);
        let step = StepSamples {
            current_adc: &[2068; 10],
            prev_us: 0,
            now_us: 1000,
            prev_position: 0,
            position: 100_000,
        };
        assert!(
            est.update(&step, &model().coefficients(), |_| 0.0)
                .is_none()
        );
        // At 2 rad/s one turn takes 3.1 s, longer than the 2 s limit.
        let got = feed(&mut est, 2.0, 1.2, |_| 2.5);
        assert!(got.is_empty());
    }
}
