//! The board's analog front end in numbers: what one control step's ADC block says about
//! the motor current, the ADC's own reference (VDDA), the bridge supply and the motor
//! temperature, and where the hardware overcurrent trip sits in ADC counts.
//!
//! Pure functions of counts (no registers), so they are unit-tested on the host. The
//! constants of the parts are in [`model::hardware`].
//!
//! Every trigger of ADC1 converts one scan of [`SCAN_LEN`] channels, in this order:
//!
//! | rank | channel              | pin  | sample time            |
//! |------|----------------------|------|------------------------|
//! | 0    | motor current ACS714 | PA0  | 92.5 cycles (2.2 us)   |
//! | 1    | bus voltage          | PA1  | 92.5 cycles            |
//! | 2    | motor NTC            | PB0  | 92.5 cycles            |
//! | 3    | VREFINT              | -    | 247.5 cycles (5.8 us, the data sheet asks >= 4 us) |
//!
//! The current is converted first, at the trigger (the PWM instant the board documentation
//! argues for); the slow channels follow within ~14 us.

use model::hardware::{acs714, adc, bus_divider, ntc};

/// ADC1 channels converted per trigger.
pub const SCAN_LEN: usize = 4;
/// Triggers (current samples) per control step: 10 kHz sampling, 1 kHz control.
pub const SAMPLES_PER_STEP: usize = 10;
/// ADC values per control step, interleaved scan by scan.
pub const BLOCK_LEN: usize = SCAN_LEN * SAMPLES_PER_STEP;

/// VDDA at which the factory measured VREFINT_CAL (stored at 0x1FFF_75AA, the metapac's
/// `VREFINTCAL`; RM0440: 3.0 V, 30 deg C).
pub const VREFINT_CAL_VDDA_V: f32 = 3.0;

/// Largest ADC code.
const FULL_SCALE: f32 = adc::FULL_SCALE as f32;
/// VDDA the data sheet allows with the ADC running (DS12288: 1.62-3.6 V).
const VDDA_RANGE_V: (f32, f32) = (1.62, 3.6);
/// Readings of the NTC pin outside this fraction of full scale mean open (pull-up only) or
/// shorted: no thermistor fitted, or a broken wire.
const NTC_VALID_FRACTION: (f32, f32) = (0.02, 0.98);

/// One control step's ADC block, taken apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Block {
    /// Motor current samples, oldest first (raw counts, as the core expects).
    pub current: [u16; SAMPLES_PER_STEP],
    /// Mean bus-voltage reading, counts.
    pub bus_counts: f32,
    /// Mean NTC reading, counts.
    pub ntc_counts: f32,
    /// Mean VREFINT reading, counts.
    pub vrefint_counts: f32,
}

/// Splits an interleaved block (`[I, Vbus, NTC, VREFINT, I, ...]`) into the current
/// samples and the means of the slow channels.
pub fn split(raw: &[u16; BLOCK_LEN]) -> Block {
    let mut current = [0u16; SAMPLES_PER_STEP];
    let mut sums = [0u32; SCAN_LEN];
    for (n, scan) in raw.chunks_exact(SCAN_LEN).enumerate() {
        current[n] = scan[0];
        for (sum, &v) in sums.iter_mut().zip(scan) {
            *sum += u32::from(v);
        }
    }
    let mean = |rank: usize| sums[rank] as f32 / SAMPLES_PER_STEP as f32;
    Block {
        current,
        bus_counts: mean(1),
        ntc_counts: mean(2),
        vrefint_counts: mean(3),
    }
}

/// VDDA (the ADC's and the DAC's reference) from a VREFINT reading and the chip's factory
/// calibration: VDDA = 3.0 V x VREFINT_CAL / VREFINT_DATA. `None` when the reading is
/// implausible (no conversion, or a VDDA the chip cannot run the ADC at).
pub fn vdda_v(vrefint_cal: u16, vrefint_counts: f32) -> Option<f32> {
    if vrefint_counts < 1.0 {
        return None;
    }
    let v = VREFINT_CAL_VDDA_V * f32::from(vrefint_cal) / vrefint_counts;
    (VDDA_RANGE_V.0..=VDDA_RANGE_V.1).contains(&v).then_some(v)
}

/// Bridge supply voltage from the bus-divider reading, V.
pub fn bus_v(counts: f32, vdda_v: f32) -> f32 {
    counts / FULL_SCALE * vdda_v / bus_divider::RATIO as f32
}

/// Motor temperature from the NTC reading, deg C; `None` when no thermistor is fitted
/// (the pull-up reads full scale) or the input is shorted. The divider is ratiometric to
/// VDDA, so VDDA drops out.
pub fn motor_temperature_c(counts: f32) -> Option<f32> {
    let x = counts / FULL_SCALE;
    if !(NTC_VALID_FRACTION.0..=NTC_VALID_FRACTION.1).contains(&x) {
        return None;
    }
    // NTC to ground, pull-up to VDDA: x = R / (R + R_pull).
    let r = ntc::PULL_UP_OHM as f32 * x / (1.0 - x);
    let inv_t = 1.0 / ntc::T25_K as f32 + ln(r / ntc::R25_OHM as f32) / ntc::BETA_K as f32;
    Some(1.0 / inv_t - 273.15)
}

/// Natural logarithm of a positive, normal `x`, within 2e-6 of ln x (the NTC's resistance
/// ratio, 0.02-49 over the valid readings: 1e-4 K of temperature). `x` = m 2^e with m in
/// [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s), s = (m - 1) / (m + 1), |s| < 0.172, three terms of
/// the series. In place of libm's `logf` (~300 B of flash in the image, whose budget is
/// tight) for a reading reported once a second.
fn ln(x: f32) -> f32 {
    let bits = x.to_bits();
    let mut exponent = ((bits >> 23) & 0xFF) as i32 - 127;
    // The mantissa with a zero exponent: m in [1, 2).
    let mut m = f32::from_bits((bits & 0x007F_FFFF) | 0x3F80_0000);
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        exponent += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let atanh2 = s * (2.0 + s2 * (2.0 / 3.0 + s2 * (2.0 / 5.0)));
    exponent as f32 * core::f32::consts::LN_2 + atanh2
}

/// The ACS714's ratiometric sensitivity: output change per ampere as a fraction of its zero
/// output (Vcc/2), 1/A. 185 mV/A at 5 V is 0.074 of 2.5 V per ampere, at any supply.
pub const RATIOMETRIC_SENSITIVITY_PER_A: f32 =
    (acs714::SENSITIVITY_V_PER_A / (acs714::ZERO_FRACTION * acs714::SUPPLY_NOMINAL_V)) as f32;

/// Comparator threshold, in ADC (= DAC, both referenced to VDDA) counts, for `limit_a`
/// amperes through the sensor in the direction `sign` (+1 forward, -1 reverse), from the
/// measured zero-current reading `zero_counts`.
///
/// The ACS714 is ratiometric: its zero is Vcc/2 and its sensitivity is proportional to Vcc,
/// so in counts the current is `zero x (1 + 0.074/A x I)`, whatever the sensor supply
/// (4.5-5.5 V), the divider and VDDA are. Sizing the threshold from the measured zero keeps
/// the trip at `limit_a` where a fixed voltage would move it by +-10 % with the supply.
pub fn trip_threshold_counts(zero_counts: f32, limit_a: f32, sign: f32) -> u16 {
    let counts = zero_counts * (1.0 + sign * RATIOMETRIC_SENSITIVITY_PER_A * limit_a);
    counts.clamp(0.0, FULL_SCALE) as u16
}

/// The nominal zero-current reading before the core has measured it: Vcc/2 of a 5 V sensor
/// through the divider, at the measured VDDA.
pub fn nominal_zero_counts(vdda_v: f32) -> f32 {
    let zero_v =
        (acs714::zero_output_v(acs714::SUPPLY_NOMINAL_V) * model::hardware::divider::RATIO) as f32;
    zero_v / vdda_v * FULL_SCALE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ADC code of `volts` at the pin with reference `vdda`.
    fn code(volts: f64, vdda: f64) -> f32 {
        (volts / vdda * f64::from(adc::FULL_SCALE)) as f32
    }

    #[test]
    fn split_takes_every_fourth_value_as_current_and_averages_the_rest() {
        let mut raw = [0u16; BLOCK_LEN];
        for n in 0..SAMPLES_PER_STEP {
            raw[n * SCAN_LEN] = 2000 + n as u16;
            raw[n * SCAN_LEN + 1] = 900 + (n as u16 % 2) * 2;
            raw[n * SCAN_LEN + 2] = 2047;
            raw[n * SCAN_LEN + 3] = 1500;
        }
        let b = split(&raw);
        assert_eq!(b.current, core::array::from_fn(|n| 2000 + n as u16));
        assert_eq!(b.bus_counts, 901.0);
        assert_eq!(b.ntc_counts, 2047.0);
        assert_eq!(b.vrefint_counts, 1500.0);
    }

    #[test]
    fn vdda_from_vrefint_matches_the_supply() {
        // A part whose VREFINT is 1.212 V: VREFINT_CAL = 1.212 / 3.0 x 4095 = 1654.
        let cal = (1.212 / 3.0 * 4095.0_f64).round() as u16;
        for vdda in [3.0, 3.3, 3.6] {
            let reading = code(1.212, vdda);
            let v = vdda_v(cal, reading).expect("plausible");
            assert!((f64::from(v) - vdda).abs() < 2e-3, "{vdda}: {v}");
        }
        assert_eq!(vdda_v(cal, 0.0), None);
        // A reading that would mean VDDA = 6 V is refused, not believed.
        assert_eq!(vdda_v(cal, code(1.212, 6.0)), None);
    }

    #[test]
    fn bus_voltage_through_the_divider() {
        for (bus, vdda) in [(12.0, 3.3), (24.0, 3.3), (24.0, 3.1)] {
            let reading = code(bus * bus_divider::RATIO, vdda);
            let v = bus_v(reading, vdda as f32);
            assert!(
                (f64::from(v) - bus).abs() < 0.01,
                "{bus} V at VDDA {vdda}: {v}"
            );
        }
        // Full scale is 36.3 V: room above a 24 V supply.
        assert!((bus_v(4095.0, 3.3) - 36.3).abs() < 0.01);
    }

    #[test]
    fn ntc_beta_equation() {
        // At 25 deg C the NTC equals the pull-up: half scale.
        let t = motor_temperature_c(4095.0 / 2.0).expect("fitted");
        assert!((t - 25.0).abs() < 0.05, "{t}");
        // At 85 deg C: R = R25 exp(B (1/T - 1/T25)) = 1.07 k (B25/85 = 3977 K by definition).
        let r85 = ntc::R25_OHM * (ntc::BETA_K * (1.0 / 358.15 - 1.0 / ntc::T25_K)).exp();
        let x = r85 / (r85 + ntc::PULL_UP_OHM);
        let t = motor_temperature_c((x * 4095.0) as f32).expect("fitted");
        assert!((t - 85.0).abs() < 0.3, "{t}");
        // Colder is a higher resistance: a higher reading.
        assert!(motor_temperature_c(3000.0).unwrap() < 25.0);
        // Not fitted (pull-up only) or shorted.
        assert_eq!(motor_temperature_c(4095.0), None);
        assert_eq!(motor_temperature_c(10.0), None);
    }

    #[test]
    fn ln_is_the_logarithm_over_the_ntc_range_and_beyond() {
        // Every ratio the NTC can report (0.02-49) and the binades around, log-spaced, with
        // the powers of two and the mantissa's sqrt(2) switch exactly.
        let mut worst = 0.0f64;
        let mut x = 1e-3f64;
        while x < 1e3 {
            for v in [x, x * std::f64::consts::SQRT_2] {
                let got = f64::from(ln(v as f32));
                let want = f64::from(v as f32).ln();
                worst = worst.max((got - want).abs());
            }
            x *= 1.0007;
        }
        assert!(worst < 2e-6, "{worst}");
        assert_eq!(ln(1.0), 0.0);
        assert!((ln(2.0) - core::f32::consts::LN_2).abs() < 1e-7);
        assert!((ln(0.5) + core::f32::consts::LN_2).abs() < 1e-7);
    }

    /// The reading of `amps` for a sensor on `supply` V, through the 2/3 divider, at `vdda`.
    fn sensor_counts(amps: f64, supply: f64, vdda: f64) -> f32 {
        let v = acs714::zero_output_v(supply) + amps * acs714::sensitivity_v_per_a(supply);
        code(v * model::hardware::divider::RATIO, vdda)
    }

    #[test]
    fn trip_threshold_is_the_limit_at_any_sensor_supply() {
        for supply in [4.5, 4.75, 5.0, 5.25, 5.5] {
            for vdda in [3.2, 3.3] {
                let zero = sensor_counts(0.0, supply, vdda);
                let up = trip_threshold_counts(zero, 6.0, 1.0);
                let down = trip_threshold_counts(zero, 6.0, -1.0);
                let want_up = sensor_counts(6.0, supply, vdda);
                let want_down = sensor_counts(-6.0, supply, vdda);
                assert!(
                    (f32::from(up) - want_up).abs() <= 1.0,
                    "{supply} V: {up} vs {want_up}"
                );
                assert!(
                    (f32::from(down) - want_down).abs() <= 1.0,
                    "{supply} V: {down} vs {want_down}"
                );
            }
        }
        // A fixed threshold sized at 5 V would sit at 4.2 A on a 5.5 V supply: under the 4.8 A
        // software limit, so the comparator would cut a legal current.
        let fixed = sensor_counts(6.0, 5.0, 3.3);
        let at_5v5 = (f64::from(fixed) - f64::from(sensor_counts(0.0, 5.5, 3.3)))
            / (f64::from(sensor_counts(1.0, 5.5, 3.3)) - f64::from(sensor_counts(0.0, 5.5, 3.3)));
        assert!(at_5v5 < 4.8, "{at_5v5}");
    }

    #[test]
    fn nominal_zero_is_the_core_s_nominal_zero() {
        // 2.5 V x 2/3 at 3.3 V: 2068 counts, what the core assumes before measuring.
        assert!((nominal_zero_counts(3.3) - 2068.2).abs() < 0.1);
        assert!((RATIOMETRIC_SENSITIVITY_PER_A - 0.074).abs() < 1e-6);
    }
}
