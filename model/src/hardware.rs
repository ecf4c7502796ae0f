//! The rig's hardware, written once: the vibrator motor, the current sensor and its divider,
//! the ADC, the encoder and the H-bridge board.
//!
//! This module is the one home of the data-sheet and board constants. The plant's defaults
//! ([`crate::plant::MotorParams`], [`crate::plant::SensorParams`],
//! [`crate::plant::PlantParams::paper`]) and the firmware's configuration defaults read them
//! from here. The paper's own numbers (gears, Table 2, test conditions) live in
//! [`crate::paper`].
//!
//! Units are SI (ohm, H, V, A, s, rad, Hz) unless a name says otherwise.

use crate::paper;

/// The vibrator: a Mabuchi RS-735 DC motor with an 8.5:1 gearhead driving the cam.
///
/// Chosen so the paper's calibration (Table 2) is what a calibration of this motor returns
/// and the paper's voltage-speed points hold: N Ke = 0.078 V s/rad and R = 0.44 ohm give
/// about 5 / 10 / 15 Hz at 3.6 / 6.2 / 8.8 V under the paper's loads.
pub mod rs735 {
    use super::paper;

    /// Winding resistance at [`AMBIENT_C`], ohm.
    pub const RESISTANCE_OHM: f64 = 0.44;
    /// Winding inductance, H. Not on Mabuchi's RS-735 data sheet (it gives R, Kt and the
    /// no-load and stall points only): 0.2 mH is the typical terminal inductance of a
    /// 12 V 735-frame ferrite motor (0.15-0.3 mH measured at 1 kHz with the rotor
    /// blocked, e.g. with an LCR meter; measure the rig's motor so). It sets the PWM
    /// ripple, V T / (4 L) = 0.75 A peak to peak at d = 1/2 on 12 V and 20 kHz
    /// ([`crate::plant::pwm`]), and the electrical time constant L / R = 0.45 ms.
    pub const INDUCTANCE_H: f64 = 0.2e-3;
    /// Gearhead reduction N (motor turns per cam turn).
    pub const GEAR_RATIO: f64 = 8.5;
    /// Back-EMF constant seen at the cam shaft, N Ke, V s/rad.
    pub const KE_CAM_V_S_PER_RAD: f64 = 0.078;
    /// Back-EMF constant at the motor shaft, Ke (= torque constant Kt), V s/rad.
    pub const KE_MOTOR_V_S_PER_RAD: f64 = KE_CAM_V_S_PER_RAD / GEAR_RATIO;
    /// Efficiency eta of the gearhead (a two-stage spur gearhead: about 0.8), so that the
    /// torque per ampere at the cam is C1 = eta N Kt = 62.4 N mm/A (Table 2: 62.1).
    pub const GEARHEAD_EFFICIENCY: f64 = 0.8;
    /// Reverse (back-drive) efficiency of the gearhead: the share of power driven into its
    /// output shaft that reaches the motor. Not from a data sheet (makers state only the
    /// forward figure); a two-stage spur gearhead's reverse efficiency is about its forward
    /// one at these ratios (both set by the same mesh losses), so taken equal. A braking
    /// drive's return of the carrier's power passes through it
    /// ([`crate::effects::KAPPA_BRAKING_DRIVE`]).
    pub const GEARHEAD_REVERSE_EFFICIENCY: f64 = 0.8;
    /// Rotor inertia at the motor shaft, kg m^2.
    pub const ROTOR_INERTIA_KG_M2: f64 = 1.0e-5;
    /// Inertia of the cam and its shaft at the cam shaft, kg m^2.
    pub const CAM_INERTIA_KG_M2: f64 = 1.0e-4;
    /// Heat capacity of the winding, J/K.
    pub const THERMAL_CAPACITY_J_PER_K: f64 = 40.0;
    /// Thermal resistance winding to ambient, K/W.
    pub const THERMAL_RESISTANCE_K_PER_W: f64 = 6.0;
    /// Ambient (and reference) temperature of the winding, deg C.
    pub const AMBIENT_C: f64 = 25.0;
    /// Temperature coefficient of the copper winding's resistance, 1/K.
    pub const COPPER_TEMPCO_PER_K: f64 = 0.0039;
    /// Cam speed of [`NO_LOAD_CURRENT_A`], rad/s (10 Hz).
    pub const NO_LOAD_SPEED_RAD_S: f64 = 2.0 * core::f64::consts::PI * 10.0;
    /// No-load current of the vibrator (motor, gearhead and cam shaft, uncoupled) at
    /// [`NO_LOAD_SPEED_RAD_S`], A: what the paper's no-load test measured, Table 2's
    /// C5 w + C6 (2.49 A at 10 Hz).
    pub const NO_LOAD_CURRENT_A: f64 =
        paper::CALIBRATION.c5 * NO_LOAD_SPEED_RAD_S + paper::CALIBRATION.c6;
    /// Lowest voltage that starts the vibrator from rest, V: R (-C2) / C1 with Table 2's C1
    /// and C2 (0.98 V; the paper: "below 1.0 V it does not turn").
    pub const BREAKAWAY_V: f64 = RESISTANCE_OHM * -paper::CALIBRATION.c2 / paper::CALIBRATION.c1;
}

/// The current sensor: a Pololu ACS714 hall sensor, +-5 A version.
pub mod acs714 {
    /// Sensitivity at the nominal supply, V/A (185 mV/A).
    pub const SENSITIVITY_V_PER_A: f64 = 0.185;
    /// Measuring range, +-A.
    pub const RANGE_A: f64 = 5.0;
    /// Nominal supply, V.
    pub const SUPPLY_NOMINAL_V: f64 = 5.0;
    /// Lowest supply the sensor is specified for, V.
    pub const SUPPLY_MIN_V: f64 = 4.5;
    /// Highest supply the sensor is specified for, V.
    pub const SUPPLY_MAX_V: f64 = 5.5;
    /// Zero-current output as a fraction of the supply (Vcc / 2).
    pub const ZERO_FRACTION: f64 = 0.5;
    /// RMS output noise at the ADC's bandwidth, V (data sheet: 21 mV peak to peak at full
    /// bandwidth, about 5 mV RMS).
    pub const NOISE_RMS_V: f64 = 0.005;

    /// Zero-current output at sensor supply `supply_v`, V (ratiometric: Vcc / 2).
    pub const fn zero_output_v(supply_v: f64) -> f64 {
        ZERO_FRACTION * supply_v
    }

    /// Sensitivity at sensor supply `supply_v`, V/A (ratiometric: proportional to Vcc).
    pub const fn sensitivity_v_per_a(supply_v: f64) -> f64 {
        SENSITIVITY_V_PER_A * supply_v / SUPPLY_NOMINAL_V
    }
}

/// The divider from the ACS714's output to the ADC pin (10 k over 20 k): the 0.5-4.5 V
/// output range fits the 3.3 V ADC.
pub mod divider {
    /// Upper resistor, ohm.
    pub const R_TOP_OHM: f64 = 10.0e3;
    /// Lower resistor, ohm.
    pub const R_BOTTOM_OHM: f64 = 20.0e3;
    /// Nominal ratio, ADC volts per sensor volt (2/3).
    pub const RATIO: f64 = 2.0 / 3.0;
    /// Tolerance of each resistor (1 % parts), relative.
    pub const RESISTOR_TOLERANCE: f64 = 0.01;

    /// Lowest and highest ratio with both resistors at the ends of their tolerance.
    pub const fn ratio_bounds() -> (f64, f64) {
        let t = RESISTOR_TOLERANCE;
        let lo = R_BOTTOM_OHM * (1.0 - t) / (R_BOTTOM_OHM * (1.0 - t) + R_TOP_OHM * (1.0 + t));
        let hi = R_BOTTOM_OHM * (1.0 + t) / (R_BOTTOM_OHM * (1.0 + t) + R_TOP_OHM * (1.0 - t));
        (lo, hi)
    }
}

/// The divider from the H-bridge supply to the bus-voltage pin (PA1): 100 k over 10 k with
/// 100 nF at the pin. 12-24 V supplies read 1.09-2.18 V; the ADC's 3.3 V full scale is 36 V,
/// headroom for a regenerating bridge pumping a supply that cannot sink.
pub mod bus_divider {
    /// Upper resistor, ohm.
    pub const R_TOP_OHM: f64 = 100.0e3;
    /// Lower resistor, ohm.
    pub const R_BOTTOM_OHM: f64 = 10.0e3;
    /// Ratio, pin volts per bus volt (1/11).
    pub const RATIO: f64 = R_BOTTOM_OHM / (R_TOP_OHM + R_BOTTOM_OHM);
    /// Filter capacitor at the pin, F: 0.9 ms with the divider's 9.1 k, averages the
    /// 20 kHz supply ripple and feeds the ADC's sampling capacitor.
    pub const FILTER_CAPACITANCE_F: f64 = 100.0e-9;
}

/// The optional motor thermistor (PB0): a 10 k NTC on the motor can (B25/85 = 3977 K, e.g.
/// Vishay NTCLE100E3103) to ground, a 10 k pull-up to VDDA, so the reading is a ratio of
/// VDDA whatever VDDA is. Beta equation: 1/T = 1/T25 + ln(R/R25)/B.
pub mod ntc {
    /// Resistance at 25 deg C, ohm.
    pub const R25_OHM: f64 = 10.0e3;
    /// 25 deg C in kelvin.
    pub const T25_K: f64 = 298.15;
    /// B constant (25/85 deg C), K.
    pub const BETA_K: f64 = 3977.0;
    /// Pull-up from the pin to VDDA, ohm.
    pub const PULL_UP_OHM: f64 = 10.0e3;
}

/// The STM32G474's 12-bit ADC and its references.
pub mod adc {
    /// Resolution, bits.
    pub const BITS: u32 = 12;
    /// Largest code.
    pub const FULL_SCALE: u16 = (1 << BITS) - 1;
    /// Nominal reference VREF+ = VDDA on the Nucleo-G474RE, V.
    pub const VREF_V: f64 = 3.3;
    /// Internal reference VREFINT, typical, V (STM32G474 data sheet).
    pub const VREFINT_TYP_V: f64 = 1.212;
    /// VREFINT, minimum, V.
    pub const VREFINT_MIN_V: f64 = 1.182;
    /// VREFINT, maximum, V.
    pub const VREFINT_MAX_V: f64 = 1.232;
}

/// The encoder: a CUI AMT102-V on the cam shaft, quadrature.
pub mod amt102 {
    /// Pulses per revolution per channel, as the rig sets the encoder's DIP switches (the
    /// largest setting).
    pub const PPR: u32 = 2048;
    /// Counts per revolution with x4 decoding.
    pub const COUNTS_PER_REV: u32 = 4 * PPR;
}

/// The controller board: a Nucleo-G474RE driving an H-bridge.
pub mod board {
    /// PWM frequency of the H-bridge (TIM1 CH1), Hz.
    pub const PWM_FREQUENCY_HZ: f64 = 20_000.0;
    /// The STM32G474's system clock as the firmware sets its clock tree (the Nucleo's 24 MHz
    /// HSE crystal / 6 x 85 / 2),
    /// Hz; APB1 and APB2, and the timers on them (TIM1, the WWDG), run undivided.
    pub const SYSCLK_HZ: f64 = 170_000_000.0;
    /// H-bridge supply, V.
    pub const BRIDGE_SUPPLY_V: f64 = 12.0;
    /// Internal resistance of the bridge's supply as the bridge sees it, ohm: a regulated
    /// bench supply's own output resistance is milliohms, its leads are not: 2 x 1 m of
    /// 0.75 mm^2 copper is 0.046 ohm, with connectors 0.05 ohm. The bus sags by this times
    /// the supply current d i (0.1 V at 8.8 V and 3 A); the firmware measures the bus, so
    /// its feed-forward sees the sag.
    pub const SUPPLY_RESISTANCE_OHM: f64 = 0.05;
    /// Current-sensor sample rate, Hz (the paper logged at the same rate).
    pub const CURRENT_SAMPLE_RATE_HZ: f64 = 10_000.0;
    /// Highest vibration frequency the board's controller accepts, Hz.
    pub const MAX_FREQ_HZ: f64 = 20.0;
    /// Whether the H-bridge's decay mode takes the carrier's inertial power back into the
    /// supply: [`DECAY`]`.returns_power()`. The plant
    /// ([`crate::plant::PlantParams::regeneration`]), the firmware's estimator
    /// (`carrier_power_returned`) and the firmware's bridge driver read this one setting,
    /// so they agree.
    pub const REGENERATIVE_DECAY: bool = DECAY.returns_power();

    /// What the H-bridge does with the motor in the PWM's off-time.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Decay {
        /// Both low-side switches on (slow decay, synchronous rectification): the current
        /// keeps flowing and may reverse, so the bridge takes the carrier's power back when
        /// the cam overruns the drive, into a supply that may not be able to sink it (the
        /// bus then rises: [`BUS_OVERVOLTAGE_V`]).
        Brake,
        /// All switches off (fast decay through the diodes): the current cannot reverse, the
        /// bridge takes no power back, like the paper's bench supply.
        Coast,
    }

    impl Decay {
        /// Whether the drive takes the carrier's power back.
        pub const fn returns_power(self) -> bool {
            matches!(self, Decay::Brake)
        }

        /// The name used in logs and provenance lines.
        pub const fn name(self) -> &'static str {
            match self {
                Decay::Brake => "brake",
                Decay::Coast => "coast",
            }
        }
    }

    /// The decay mode the rig is built for, the one setting: [`Decay::Brake`] by default,
    /// the README's board, a Pololu G2 24v13 driven sign-magnitude (PWM low brakes both
    /// outputs to ground, so the drive takes the carrier's power back through the
    /// gearhead: [`crate::effects::KAPPA_BRAKING_DRIVE`]); [`Decay::Coast`] with this
    /// crate's `bridge-coast-decay` feature (the firmware's feature of the same name turns
    /// it on), a bridge that takes no power back, like the paper's bench supply. The
    /// firmware image, its estimator and the virtual rig's plant read it; a rig file's
    /// `[drive] decay` and a data file's `# drive:` line name the mode they were made with.
    pub const DECAY: Decay = if cfg!(feature = "bridge-coast-decay") {
        Decay::Coast
    } else {
        Decay::Brake
    };

    /// Whether a debug halt stops TIM1 (DBGMCU_APB2FZR.DBG_TIM1_STOP), read by the firmware
    /// (`board.rs`) and the virtual rig's halt (`sim::SimRig::debug_halt`). `false`: TIM1
    /// keeps switching the last duty through a halt, up to the IWDG's reset (~250 ms, not
    /// frozen), whose floating pins let the bridge's pull-downs switch it off. Stopped
    /// (`true`, the earlier setting), TIM1 holds PA8 at its idle level, low, while the
    /// enable (a GPIO) stays high: the G2 then brakes a spinning cam with its back-EMF over
    /// the winding alone, about 17 A at 15 Hz, beyond the ACS714-05's +-5 A, in the
    /// direction COMP3 does not watch (`rig sim faults debug-halt` shows both).
    pub const TIM1_STOPS_IN_DEBUG: bool = false;

    /// Highest supply the H-bridge is rated for, V: the Pololu G2 24v13's operating range
    /// ends at 40 V.
    pub const BRIDGE_MAX_V: f64 = 40.0;

    /// Bus voltage above which the firmware stops the drive and latches
    /// `BUS_OVERVOLTAGE`, V: 85 % of [`BRIDGE_MAX_V`] (34 V), below the bus divider's
    /// 36.3 V full scale at VDDA 3.3 V, so the ADC still reads it.
    pub const BUS_OVERVOLTAGE_V: f64 = 0.85 * BRIDGE_MAX_V;

    /// Capacitance on the bridge's supply bus, F: the bridge's bulk capacitor and the bench
    /// supply's output capacitance together. Not from a data sheet: 470 uF is a typical
    /// bulk electrolytic added at a motor bridge's supply terminals; measure the rig's (it
    /// sets how far a regenerating bridge pumps the bus per joule returned).
    pub const BUS_CAPACITANCE_F: f64 = 470.0e-6;
}

/// The hardware overcurrent trip: COMP3 on the current-sense pin (PA0) against an internal
/// DAC threshold, routed to TIM1's break input, so the bridge switches off within
/// microseconds with no software involved (the firmware's 1 ms mean check stays as the
/// second layer).
pub mod comparator {
    use super::{acs714, divider};

    /// Instantaneous motor current at which the comparator trips, A: 25 % above the
    /// board's 4.8 A software limit, so start-up peaks and the PWM ripple (about
    /// +-0.4 A) never reach it while a jam (a stall current of 10-27 A) does within a
    /// fraction of the winding's 0.45 ms time constant.
    pub const TRIP_A: f64 = 6.0;

    /// Pin voltage of `trip_a` through the nominal sensor transfer (ACS714 at 5.0 V,
    /// the 2/3 divider): the DAC's threshold, V (2.41 V for 6 A).
    pub const fn threshold_v(trip_a: f64) -> f64 {
        let supply = acs714::SUPPLY_NOMINAL_V;
        (acs714::zero_output_v(supply) + acs714::sensitivity_v_per_a(supply) * trip_a)
            * divider::RATIO
    }
}

/// A vibrator motor's own constants, against which a calibration is judged
/// ([`crate::Calibration::check`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotorConstants {
    /// Torque (= back-EMF) constant at the motor shaft Kt, N m/A.
    pub kt_motor: f64,
    /// Gearhead reduction N.
    pub gear_ratio: f64,
    /// Gearhead efficiency eta.
    pub gearhead_efficiency: f64,
    /// No-load current at [`MotorConstants::no_load_speed`], A.
    pub no_load_current: f64,
    /// Cam speed of [`MotorConstants::no_load_current`], rad/s.
    pub no_load_speed: f64,
}

impl MotorConstants {
    /// The rig's RS-735 with its 8.5:1 gearhead ([`rs735`]).
    pub const RS735: MotorConstants = MotorConstants {
        kt_motor: rs735::KE_MOTOR_V_S_PER_RAD,
        gear_ratio: rs735::GEAR_RATIO,
        gearhead_efficiency: rs735::GEARHEAD_EFFICIENCY,
        no_load_current: rs735::NO_LOAD_CURRENT_A,
        no_load_speed: rs735::NO_LOAD_SPEED_RAD_S,
    };

    /// Torque per ampere the motor delivers at the cam shaft, eta N Kt, N m/A (what C1
    /// should be).
    pub fn cam_torque_constant(&self) -> f64 {
        self.gearhead_efficiency * self.gear_ratio * self.kt_motor
    }
}

impl Default for MotorConstants {
    fn default() -> Self {
        Self::RS735
    }
}

/// The bench around the rig: what a load can do before something stops it.
pub mod bench {
    use crate::paper;

    /// Height a load hung on the output pulley falls before it rests on the floor, m (a
    /// rig on a frame above the floor; long enough that a sweep's point, re-hung before
    /// each run, ends or trips OUTPUT_OVERSPEED at 20 rad/s before its load lands).
    /// The default of a rig file's `[load] drop_m`.
    pub const LOAD_DROP_M: f64 = 2.0;
    /// The output's travel from where the load was hung to where it rests, rad: the drop
    /// unwound from the pulley of radius [`paper::R_OUT`] (26.7 rad).
    pub const OUTPUT_TRAVEL_RAD: f64 = output_travel_rad(LOAD_DROP_M);

    /// The output's travel, rad, before a load hung `drop_m` metres above the floor rests
    /// on it: the drop unwound from the pulley of radius [`paper::R_OUT`].
    pub const fn output_travel_rad(drop_m: f64) -> f64 {
        drop_m / paper::R_OUT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motor_constants_match_table2() {
        let m = MotorConstants::RS735;
        // eta N Kt = 0.8 x 0.078 = 62.4 N mm/A against Table 2's 62.1.
        assert!((m.cam_torque_constant() * 1e3 - 62.4).abs() < 1e-9);
        // C5 w + C6 at 10 Hz: 0.00378 x 62.83 + 2.25 = 2.4875 A.
        assert!(
            (m.no_load_current - 2.4875).abs() < 1e-3,
            "{}",
            m.no_load_current
        );
        // The paper: the vibrator does not turn below 1.0 V.
        const { assert!(rs735::BREAKAWAY_V > 0.9 && rs735::BREAKAWAY_V < 1.0) };
    }

    #[test]
    fn bus_overvoltage_threshold_is_under_the_rating_and_readable() {
        // 34 V: under the G2's 40 V, and under what the bus divider lets the ADC read.
        assert!((board::BUS_OVERVOLTAGE_V - 34.0).abs() < 1e-12);
        let full_scale_v = adc::VREF_V / bus_divider::RATIO;
        assert!((full_scale_v - 36.3).abs() < 1e-9, "{full_scale_v}");
        assert!(board::BUS_OVERVOLTAGE_V < full_scale_v);
        const { assert!(board::BUS_OVERVOLTAGE_V > board::BRIDGE_SUPPLY_V) };
        assert_eq!(board::REGENERATIVE_DECAY, board::DECAY.returns_power());
    }

    #[test]
    fn comparator_threshold_is_the_trip_current_at_the_pin() {
        // (2.5 V + 0.185 V/A x 6 A) x 2/3 = 2.407 V, inside the 3.3 V DAC range.
        let v = comparator::threshold_v(comparator::TRIP_A);
        assert!((v - 2.4067).abs() < 1e-3, "{v}");
    }

    #[test]
    fn sensor_chain_numbers() {
        assert_eq!(adc::FULL_SCALE, 4095);
        assert_eq!(amt102::COUNTS_PER_REV, 8192);
        assert!((acs714::zero_output_v(4.75) - 2.375).abs() < 1e-12);
        assert!((acs714::sensitivity_v_per_a(5.0) - 0.185).abs() < 1e-15);
        let (lo, hi) = divider::ratio_bounds();
        // 1 % resistors move a 2/3 divider by about +-0.67 %.
        assert!(lo < divider::RATIO && hi > divider::RATIO);
        assert!(((hi / divider::RATIO - 1.0) - 0.0067).abs() < 2e-4, "{hi}");
        assert!(
            (divider::R_BOTTOM_OHM / (divider::R_BOTTOM_OHM + divider::R_TOP_OHM) - divider::RATIO)
                .abs()
                < 1e-15
        );
    }
}
