//! The rig's sensors as the firmware sees them: an ACS714 hall current sensor through a
//! divider into a 12-bit ADC, and a quadrature encoder (CUI AMT102-V) on the cam shaft.

use super::rng::NoiseSource;
use crate::hardware::{acs714, adc, amt102, divider};

/// Sensor parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SensorParams {
    /// ACS714 sensitivity at the nominal 5.0 V supply, V/A (185 mV/A for the +-5 A part);
    /// the sensor is ratiometric: at `acs_supply` it is this times `acs_supply / 5.0`.
    pub acs_sensitivity: f64,
    /// ACS714 supply, V: the zero-current output is half of it.
    pub acs_supply: f64,
    /// Error of the zero-current output from Vcc/2, V.
    pub acs_zero_error: f64,
    /// RMS output noise of the ACS714 at the ADC's bandwidth, V.
    pub acs_noise: f64,
    /// Divider from the sensor output to the ADC pin (ADC volts per sensor volt).
    pub divider: f64,
    /// ADC reference, V.
    pub adc_reference: f64,
    /// ADC resolution, bits.
    pub adc_bits: u32,
    /// Encoder pulses per revolution per channel (the AMT102-V is set to 2048).
    pub encoder_ppr: u32,
}

impl Default for SensorParams {
    fn default() -> Self {
        Self {
            acs_sensitivity: acs714::SENSITIVITY_V_PER_A,
            acs_supply: acs714::SUPPLY_NOMINAL_V,
            acs_zero_error: 0.0,
            acs_noise: acs714::NOISE_RMS_V,
            divider: divider::RATIO,
            adc_reference: adc::VREF_V,
            adc_bits: adc::BITS,
            encoder_ppr: amt102::PPR,
        }
    }
}

impl SensorParams {
    /// Sensitivity at the sensor's actual supply (ratiometric), V/A.
    pub fn sensitivity_at_supply(&self) -> f64 {
        self.acs_sensitivity * self.acs_supply / acs714::SUPPLY_NOMINAL_V
    }

    /// Largest ADC code.
    pub fn adc_full_scale(&self) -> u16 {
        u16::try_from((1u32 << self.adc_bits.min(16)) - 1).unwrap_or(u16::MAX)
    }

    /// ADC code for motor current `current` (A), with noise from `rng` and quantisation.
    pub fn current_to_adc(&self, current: f64, rng: &mut NoiseSource) -> u16 {
        let v_sensor = self.acs_supply / 2.0
            + self.acs_zero_error
            + self.sensitivity_at_supply() * current
            + self.acs_noise * rng.normal_fast();
        let v_pin = (v_sensor * self.divider).clamp(0.0, self.adc_reference);
        let full = self.adc_full_scale() as f64;
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "clamped to 0..=full, a u16"
        )]
        let code = libm::round(v_pin / self.adc_reference * full).clamp(0.0, full) as u16;
        code
    }

    /// Noise-free voltage at the ADC pin (and the comparator's input) for `current`, V.
    pub fn pin_voltage(&self, current: f64) -> f64 {
        (self.acs_supply / 2.0 + self.acs_zero_error + self.sensitivity_at_supply() * current)
            * self.divider
    }

    /// Current (A) an ideal zeroed reading of `code` stands for (the firmware's inverse).
    pub fn adc_to_current(&self, code: u16) -> f64 {
        let v_pin = code as f64 / self.adc_full_scale() as f64 * self.adc_reference;
        (v_pin / self.divider - self.acs_supply / 2.0) / self.sensitivity_at_supply()
    }

    /// Quadrature counts per cam revolution (4 edges per pulse).
    pub fn counts_per_rev(&self) -> u32 {
        4 * self.encoder_ppr
    }

    /// 16-bit hardware counter value for cam angle `angle` (rad), wrapping like a timer in
    /// encoder mode.
    pub fn encoder_count(&self, angle: f64) -> u16 {
        let counts =
            libm::floor(angle / (2.0 * core::f64::consts::PI) * self.counts_per_rev() as f64);
        // The timer is a 16-bit up/down counter: it wraps, and so does this.
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "a 16-bit hardware counter wraps modulo 2^16"
        )]
        let count = (counts as i64) as u16;
        count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_current_reads_mid_supply_through_the_divider() {
        let s = SensorParams {
            acs_noise: 0.0,
            ..Default::default()
        };
        let mut rng = NoiseSource::new(1);
        let code = s.current_to_adc(0.0, &mut rng);
        // 2.5 V * 2/3 = 1.667 V of 3.3 V: 2068 of 4095.
        assert_eq!(code, 2068);
        let back = s.adc_to_current(s.current_to_adc(3.0, &mut rng));
        // One LSB is 3.3 / 4095 / (2/3) / 0.185 = 6.5 mA.
        assert!((back - 3.0).abs() < 0.0066, "{back}");
    }

    #[test]
    fn encoder_wraps_like_a_16_bit_timer() {
        let s = SensorParams::default();
        let rev = 2.0 * core::f64::consts::PI;
        assert_eq!(s.encoder_count(0.0), 0);
        assert_eq!(s.encoder_count(rev * 0.25 + 1e-9), 2048);
        assert_eq!(s.encoder_count(rev * 8.0 + 1e-9), 0); // 65536 counts wrap
        assert_eq!(s.encoder_count(-rev / 8192.0 * 0.5), u16::MAX);
    }
}
