//! Everything the core needs to know about the board and the rig that is not in the
//! calibration: sensor scaling, motor model, loop gains, supervisor and fault limits.
//!
//! [`CoreConfig::default`] is the real rig (Nucleo-G474RE, ACS714 +-5 A through a 2/3
//! divider, AMT102-V at 2048 PPR, RS-735 with an 8.5:1 gearhead on a 12 V H-bridge): its
//! hardware numbers are read from [`model::hardware`], the one place they are written.

use model::hardware::{acs714, adc, amt102, board, divider, rs735};

/// The ACS714 hall current sensor and the ADC that samples it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentSensorConfig {
    /// Sensor sensitivity, V/A (185 mV/A for the +-5 A part).
    pub sensitivity_v_per_a: f32,
    /// Sensor supply, V; zero current reads half of it.
    pub supply_v: f32,
    /// Divider from the sensor output to the ADC pin (pin volts per sensor volt).
    pub divider: f32,
    /// ADC reference, V.
    pub adc_reference_v: f32,
    /// ADC resolution, bits.
    pub adc_bits: u32,
    /// Largest plausible offset of the sensor's own zero from Vcc/2, in amperes (on top
    /// of the supply and divider tolerances below).
    pub zero_tolerance_a: f32,
    /// Lowest and highest sensor supply the board may give the ACS714, V (4.5-5.5 V: the
    /// zero window is sized from them, the sensor being ratiometric).
    pub supply_range_v: (f32, f32),
    /// Lowest and highest divider ratio with its resistors' tolerance.
    pub divider_range: (f32, f32),
    /// Samples averaged for a zero measurement (motor off).
    pub zero_samples: u32,
    /// Time constant of the displayed (telemetry) current's low-pass, s.
    pub display_time_constant_s: f32,
}

impl CurrentSensorConfig {
    /// Amperes per ADC count.
    pub fn amps_per_count(&self) -> f32 {
        let full_scale = ((1u32 << self.adc_bits) - 1) as f32;
        self.adc_reference_v / full_scale / self.divider / self.sensitivity_v_per_a
    }

    /// The plausible window of the zero-current pin voltage, V: Vcc/2 over the supply
    /// range through the divider's range, widened by the sensor's own offset.
    pub fn zero_window_v(&self) -> (f32, f32) {
        let offset = self.zero_tolerance_a * self.sensitivity_v_per_a * self.divider;
        (
            self.supply_range_v.0 / 2.0 * self.divider_range.0 - offset,
            self.supply_range_v.1 / 2.0 * self.divider_range.1 + offset,
        )
    }

    /// Amperes per ADC count of a ratiometric sensor whose zero reads `zero_counts`: the
    /// zero is Vcc/2 and the sensitivity scales with Vcc, so the sensor supply follows
    /// from the zero and the divider and the ADC reference cancel out.
    pub fn ratiometric_amps_per_count(&self, zero_counts: f32) -> f32 {
        // sensitivity(Vcc) * divider / (vref / full) = S_nom / V_nom * 2 * zero_counts.
        self.supply_v / (2.0 * self.sensitivity_v_per_a * zero_counts)
    }

    /// ADC reading of zero current for an ideal sensor (Vcc/2 through the divider), counts.
    pub fn nominal_zero_counts(&self) -> f32 {
        let full_scale = ((1u32 << self.adc_bits) - 1) as f32;
        self.supply_v / 2.0 * self.divider / self.adc_reference_v * full_scale
    }
}

impl Default for CurrentSensorConfig {
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "the model's f64 hardware constants, well inside f32's range and precision needs"
    )]
    fn default() -> Self {
        Self {
            sensitivity_v_per_a: acs714::SENSITIVITY_V_PER_A as f32,
            supply_v: acs714::SUPPLY_NOMINAL_V as f32,
            divider: divider::RATIO as f32,
            adc_reference_v: adc::VREF_V as f32,
            adc_bits: adc::BITS,
            zero_tolerance_a: 0.3,
            supply_range_v: (acs714::SUPPLY_MIN_V as f32, acs714::SUPPLY_MAX_V as f32),
            divider_range: (
                divider::ratio_bounds().0 as f32,
                divider::ratio_bounds().1 as f32,
            ),
            zero_samples: 1000,
            display_time_constant_s: 0.02,
        }
    }
}

/// The vibrator motor as the speed loop's feed-forward sees it (cam-shaft side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorConfig {
    /// Winding resistance, ohm (`model::hardware::rs735`: 0.44).
    pub resistance_ohm: f32,
    /// Back-EMF constant at the cam shaft, V s/rad (0.078 for the RS-735 with 8.5:1,
    /// `model::hardware::rs735`).
    pub ke_cam_v_s_per_rad: f32,
    /// Largest duty the loop commands (keeps the bridge's bootstrap alive).
    pub max_duty: f32,
    /// Largest duty change, per second.
    pub duty_slew_per_s: f32,
    /// Drive the cam with a negative duty (direction pin high) instead.
    pub reverse: bool,
    /// The motor's own constants, against which a new calibration's C1-C6 are judged
    /// ([`model::Calibration::check`]); set them with [`MotorConfig::set_constants`].
    constants: model::MotorConstants,
    /// `constants` in `f32`, as the core checks them ([`MotorRules::new`]).
    rules: MotorRules,
}

impl MotorConfig {
    /// The motor's own constants (what the host's [`model::Calibration::check`] takes).
    pub const fn constants(&self) -> &model::MotorConstants {
        &self.constants
    }

    /// The same constants in `f32`, as the core checks a new calibration against them.
    pub const fn rules(&self) -> MotorRules {
        self.rules
    }

    /// Another motor: its constants and their `f32` form together.
    pub const fn set_constants(&mut self, constants: model::MotorConstants) {
        self.constants = constants;
        self.rules = MotorRules::new(&constants);
    }
}

impl Default for MotorConfig {
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "the model's f64 hardware constants, well inside f32's range and precision needs"
    )]
    fn default() -> Self {
        Self {
            resistance_ohm: rs735::RESISTANCE_OHM as f32,
            ke_cam_v_s_per_rad: rs735::KE_CAM_V_S_PER_RAD as f32,
            max_duty: 0.95,
            // 0.5/s accelerates the cam at ~77 rad/s^2 at most: ~1 A above the running
            // current, which itself is 2.3-2.7 A (C6 = 2.25 A) under a 4.5 A limit.
            duty_slew_per_s: 0.5,
            reverse: false,
            constants: model::MotorConstants::RS735,
            // At compile time: converted at run time, the constants would cost the image
            // the software `f64` to `f32` conversion.
            rules: const { MotorRules::new(&model::MotorConstants::RS735) },
        }
    }
}

/// The motor's constants as [`model::check_constants`] takes them in `f32`: eta N Kt
/// (`MotorConstants::cam_torque_constant`, multiplied in f32), the no-load current and
/// speed. [`MotorRules::new`] is a `const fn`: [`MotorConfig::default`] converts the
/// model's constants at compile time, so the firmware has no software double maths for them
/// (converted at run time, they cost the image `__aeabi_d2f`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorRules {
    pub(crate) kt: f32,
    pub(crate) i0: f32,
    pub(crate) w0: f32,
}

impl MotorRules {
    /// `motor`'s constants in `f32`.
    #[allow(
        clippy::cast_possible_truncation,
        reason = "the motor's constants, well inside f32's range; rounded to nearest like `CheckFloat::of`"
    )]
    pub const fn new(motor: &model::hardware::MotorConstants) -> Self {
        Self {
            kt: motor.gearhead_efficiency as f32 * motor.gear_ratio as f32 * motor.kt_motor as f32,
            i0: motor.no_load_current as f32,
            w0: motor.no_load_speed as f32,
        }
    }
}

/// Gains and limits of the cam-speed PI loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLoopConfig {
    /// Proportional gain, duty per rad/s.
    pub kp: f32,
    /// Integral gain, duty per rad (per rad/s of error and second).
    pub ki: f32,
    /// Ramp rate of the speed reference, rad/s^2: limits the accelerating current.
    pub max_accel_rad_s2: f32,
    /// Largest duty the PI may add to (or take from) the feed-forward: bounds a runaway
    /// when the speed feedback is lost.
    pub max_correction: f32,
}

impl Default for SpeedLoopConfig {
    fn default() -> Self {
        // Plant: w/duty ~ (V/ke) / (tau_m s + 1), V/ke = 154 rad/s, tau_m ~ 75 ms. PI zero on
        // the motor pole and a 30 ms closed-loop time constant: kp = tau_m / (154 * 0.03).
        Self {
            kp: 0.016,
            ki: 0.22,
            // 60 rad/s^2 takes 0.8 A of accelerating current (J = 8.2e-4 kg m^2, C1 =
            // 62.1 N mm/A); 10 Hz is reached in ~1.05 s, 20 Hz in ~2.1 s.
            max_accel_rad_s2: 60.0,
            max_correction: 0.2,
        }
    }
}

/// When the supervisor starts, holds, retunes and stops the vibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupervisorConfig {
    /// Vibration frequency of a button release, Hz.
    pub default_freq_hz: f32,
    /// Lowest frequency a release may ask for, Hz.
    pub min_freq_hz: f32,
    /// Highest frequency a release may ask for, Hz (the calibration may lower it).
    pub max_freq_hz: f32,
    /// Largest load on the output while released, N m: the gear's tooth-strength limit
    /// (3.68 N m for the paper's gear, [`model::BoardLimits::PAPER`]). The calibration's
    /// `max_release_load_nm` may lower it, never raise it; a load estimate above it while
    /// released latches `LOAD_LIMIT`.
    pub max_release_load_nm: f32,
    /// Relative allowance for the load estimate's error above `max_release_load_nm`
    /// before `LOAD_LIMIT` latches, and above the calibration's release limit before
    /// `OVERLOAD` (the estimate is good to about 2 % at the cap, see the closed-loop
    /// tests; 0.05 keeps a load at the limit itself from tripping on noise).
    pub load_cap_tolerance: f32,
    /// Relative speed error within which the cam counts as at speed.
    pub at_speed_tolerance: f32,
    /// How long the cam must stay at speed before `Vibrating`, us.
    pub at_speed_time_us: u64,
    /// Longest spin-up before `CANNOT_RELEASE`, us.
    pub spin_up_timeout_us: u64,
    /// Below this cam speed the cam counts as at rest, rad/s.
    pub stop_speed_rad_s: f32,
    /// Longest coast-down before `Locked` regardless of speed, us.
    pub stop_timeout_us: u64,
    /// Frequency added when the cam torque stays below Eq. (10)'s requirement, Hz.
    pub freq_step_hz: f32,
    /// How far below Eq. (10)'s zero-load requirement tau_cam may fall, N m.
    pub weak_margin_nm: f32,
    /// Consecutive weak revolutions before raising the frequency (or failing).
    pub weak_revolutions: u8,
    /// Revolutions ignored after reaching speed (settling) before the load checks run.
    pub settle_revolutions: u8,
    /// Consecutive revolutions above the release limit (plus `load_cap_tolerance`) before
    /// `OVERLOAD`.
    pub overload_revolutions: u8,
    /// Consecutive revolutions above the board's load cap (`max_release_load_nm` and its
    /// tolerance) before `LOAD_LIMIT`.
    pub load_limit_revolutions: u8,
    /// `JAM` when tau_cam exceeds this multiple of Eq. (10) at the largest release load.
    pub jam_ratio: f32,
    /// Requests other than status and clear are refused this long after a fault, us.
    pub fault_hold_us: u64,
}

impl Default for SupervisorConfig {
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "the model's f64 hardware constants, well inside f32's range and precision needs"
    )]
    fn default() -> Self {
        Self {
            default_freq_hz: 10.0,
            min_freq_hz: 1.0,
            max_freq_hz: board::MAX_FREQ_HZ as f32,
            max_release_load_nm: model::BoardLimits::PAPER.max_release_load_nm as f32,
            load_cap_tolerance: 0.05,
            at_speed_tolerance: 0.1,
            at_speed_time_us: 100_000,
            spin_up_timeout_us: 3_000_000,
            stop_speed_rad_s: 2.0,
            stop_timeout_us: 2_000_000,
            freq_step_hz: 2.0,
            weak_margin_nm: 0.002,
            weak_revolutions: 3,
            settle_revolutions: 1,
            overload_revolutions: 1,
            load_limit_revolutions: 3,
            jam_ratio: 2.0,
            fault_hold_us: protocol::FAULT_HOLD_MS as u64 * 1000,
        }
    }
}

/// Thresholds of the hardware faults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultConfig {
    /// Board current limit, A; the effective limit is the lower of this and the
    /// calibration's `max_current_a`.
    pub overcurrent_a: f32,
    /// How long the (1 ms mean) current must exceed the limit, us.
    pub overcurrent_time_us: u64,
    /// Duty magnitude above which the cam must turn.
    pub stall_duty: f32,
    /// Window in which the cam must move `stall_min_counts`, us.
    pub stall_window_us: u64,
    /// Encoder counts the cam must move per window while driven above `stall_duty`.
    pub stall_min_counts: u32,
    /// A step later than this many control periods is `CONTROL_OVERRUN`.
    pub overrun_periods: u32,
    /// How long the encoder's speed may run against the drive's sign (above the stop
    /// speed) before `REVERSED_ENCODER`, us.
    pub reversed_time_us: u64,
    /// Measured bridge bus above which the drive stops (`BUS_OVERVOLTAGE`), V
    /// (`model::hardware::board::BUS_OVERVOLTAGE_V`, from the bridge's rating).
    pub bus_overvoltage_v: f32,
}

impl Default for FaultConfig {
    fn default() -> Self {
        Self {
            overcurrent_a: 4.8,
            overcurrent_time_us: 10_000,
            stall_duty: 0.25,
            stall_window_us: 200_000,
            stall_min_counts: 64,
            overrun_periods: 2,
            reversed_time_us: 100_000,
            #[allow(clippy::cast_possible_truncation, reason = "34 V: exact in f32")]
            bus_overvoltage_v: board::BUS_OVERVOLTAGE_V as f32,
        }
    }
}

/// How the per-revolution cam torque becomes a load estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorConfig {
    /// The bridge takes the carrier's inertial power back (synchronous rectification), so
    /// True: the drive takes power back, Eq. (9)'s inertia term averages to zero over a
    /// revolution. False (default, as the paper's bench supply and ref. \[18\]): the drive
    /// cannot take the carrier's power back, so the revolution mean carries the rectified
    /// inertia term M w^2 e^2 / (2 pi). Either way the rest of Eq. (10)'s inertia term is
    /// added back before Eq. (10) is inverted for the load.
    pub carrier_power_returned: bool,
    /// A revolution slower than this is dropped (the cam is not really vibrating), us.
    pub max_revolution_us: u64,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            // The board's decay mode, the one setting the plant reads too.
            carrier_power_returned: board::REGENERATIVE_DECAY,
            max_revolution_us: 2_000_000,
        }
    }
}

/// The core's configuration. [`Default`] is the real rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreConfig {
    /// Control step rate, Hz.
    pub control_hz: u32,
    /// Current samples per control step (10 at 10 kHz ADC and a 1 kHz loop).
    pub samples_per_step: usize,
    /// Encoder pulses per revolution per channel (AMT102-V: 2048); x4 decoding.
    pub encoder_ppr: u32,
    /// H-bridge supply, V (feed-forward).
    pub supply_v: f32,
    /// A host release lapses without a request for this long, us.
    pub comms_timeout_us: u64,
    /// Board name reported in `Info` (at most 16 bytes are sent).
    pub board_name: &'static str,
    /// Optional hardware fitted, reported in `Info`; telemetry and health report NaN for
    /// what is missing (health's bus voltage unless `BUS_VOLTAGE` is set). The default
    /// has none; the Nucleo's `board::core_config` sets `BUS_VOLTAGE` and the output
    /// encoder, the virtual rig adds `BUS_VOLTAGE` and `SIMULATION`.
    pub capabilities: protocol::Capabilities,
    /// Device seconds per wall-clock second, reported in `Info` (`DeviceInfo::time_scale`):
    /// 1 on a board; the virtual rig served at `--speed N` reports N.
    pub time_scale: f32,
    /// The fastest host link rate `SetBaud` switches to, Bd (`DeviceInfo::max_baud`):
    /// [`protocol::FAST_BAUD_RATE`] (the Nucleo's USART2 and the virtual rig);
    /// [`protocol::DEFAULT_BAUD_RATE`] for a device that cannot switch.
    pub max_baud: u32,
    /// Current sensor.
    pub current: CurrentSensorConfig,
    /// Motor model and drive limits.
    pub motor: MotorConfig,
    /// Speed loop.
    pub speed_loop: SpeedLoopConfig,
    /// Release supervisor.
    pub supervisor: SupervisorConfig,
    /// Fault thresholds.
    pub faults: FaultConfig,
    /// Torque estimator.
    pub estimator: EstimatorConfig,
    /// The optional output-shaft encoder (`None`: not fitted; `Some` also sets
    /// `Capabilities::OUTPUT_ENCODER` in `Info`). Read only with the `output-encoder`
    /// feature.
    pub output_encoder: Option<crate::OutputEncoderConfig>,
}

impl CoreConfig {
    /// Control period, us.
    pub fn period_us(&self) -> u64 {
        1_000_000 / u64::from(self.control_hz.max(1))
    }

    /// Current (and capture) sample rate, Hz.
    pub fn sample_rate_hz(&self) -> u32 {
        self.control_hz
            .saturating_mul(u32::try_from(self.samples_per_step).unwrap_or(u32::MAX))
    }

    /// Quadrature counts per cam revolution.
    pub fn counts_per_rev(&self) -> u32 {
        4 * self.encoder_ppr
    }

    /// The caps this board puts on a calibration's limits: the release load at
    /// `supervisor.max_release_load_nm`, the current at the overcurrent trip
    /// `faults.overcurrent_a`, the frequency at `supervisor.max_freq_hz`. A record asking
    /// for more is refused ([`model::BoardLimits::check`]); the host checks the same caps.
    pub fn board_limits(&self) -> model::BoardLimits {
        model::BoardLimits {
            max_release_load_nm: f64::from(self.supervisor.max_release_load_nm),
            max_current_a: f64::from(self.faults.overcurrent_a),
            max_freq_hz: f64::from(self.supervisor.max_freq_hz),
        }
    }
}

/// Control step rate of the real rig, Hz.
const CONTROL_HZ: u32 = 1000;

impl Default for CoreConfig {
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "the model's f64 hardware constants, well inside f32's range and precision needs"
    )]
    fn default() -> Self {
        Self {
            control_hz: CONTROL_HZ,
            samples_per_step: (board::CURRENT_SAMPLE_RATE_HZ as u32 / CONTROL_HZ) as usize,
            encoder_ppr: amt102::PPR,
            supply_v: board::BRIDGE_SUPPLY_V as f32,
            comms_timeout_us: protocol::COMMS_TIMEOUT_MS as u64 * 1000,
            board_name: "nucleo-g474re",
            // The board's decay mode (`model::hardware::board::DECAY`), stated in `Info`.
            capabilities: if board::DECAY.returns_power() {
                protocol::Capabilities::BRAKING_DECAY
            } else {
                protocol::Capabilities::empty()
            },
            time_scale: 1.0,
            max_baud: protocol::FAST_BAUD_RATE,
            current: CurrentSensorConfig::default(),
            motor: MotorConfig::default(),
            speed_loop: SpeedLoopConfig::default(),
            supervisor: SupervisorConfig::default(),
            faults: FaultConfig::default(),
            estimator: EstimatorConfig::default(),
            output_encoder: None,
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
    use model::plant::SensorParams;

    #[test]
    fn defaults_are_the_rigs_hardware() {
        let c = CoreConfig::default();
        // 10 kHz current samples, ten per 1 kHz step; 8192 counts per cam turn.
        assert_eq!(
            (c.control_hz, c.samples_per_step, c.sample_rate_hz()),
            (1000, 10, 10_000)
        );
        assert_eq!(c.counts_per_rev(), 8192);
        assert_eq!(c.current.adc_bits, 12);
        // One ampere is 0.185 V * 2/3 / 3.3 V * 4095 = 153 counts.
        assert!((1.0 / c.current.amps_per_count() - 153.0).abs() < 0.1);
        assert_eq!(c.supervisor.max_freq_hz, 20.0);
        assert_eq!(
            (c.motor.resistance_ohm, c.motor.ke_cam_v_s_per_rad),
            (0.44, 0.078)
        );
    }

    #[test]
    fn estimator_and_plant_agree_on_the_decay_mode() {
        let gear = model::GearSet::paper(model::paper::RIG_Z).unwrap();
        let plant = model::plant::PlantParams::paper(gear, model::plant::Load::Torque(0.0));
        assert_eq!(
            CoreConfig::default().estimator.carrier_power_returned,
            plant.regeneration
        );
        assert_eq!(plant.regeneration, board::REGENERATIVE_DECAY);
    }

    #[test]
    fn current_scaling_matches_the_plant_sensor() {
        let c = CurrentSensorConfig::default();
        let s = SensorParams::default();
        for code in [0u16, 1000, 2068, 3000, 4095] {
            let core = (f32::from(code) - c.nominal_zero_counts()) * c.amps_per_count();
            let plant = s.adc_to_current(code) as f32;
            assert!((core - plant).abs() < 1e-3, "{code}: {core} vs {plant}");
        }
    }
}
