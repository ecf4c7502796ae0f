//! Motor current from the ACS714: ADC counts to amperes, the zero offset, and filtering.
//!
//! At 10 kHz each control step brings ~10 samples. The step mean feeds the overcurrent
//! check and the speed loop; a first-order low-pass of it is what telemetry shows; the
//! estimator sums raw counts over a whole revolution (see `estimator`).

use crate::config::CurrentSensorConfig;

/// Outcome of a finished zero measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ZeroResult {
    /// The zero is within its plausible range and now in use.
    InRange,
    /// The zero is implausible: the sensor, its supply or the divider is wrong.
    OutOfRange,
}

/// Current measurement state.
#[derive(Debug, Clone)]
pub struct CurrentSense {
    config: CurrentSensorConfig,
    amps_per_count: f32,
    zero_samples: u32,
    alpha_per_step: f32,
    zero_counts: f32,
    zero_valid: bool,
    zero_in_range: bool,
    zeroing: Option<(u64, u32)>,
    step_mean_a: f32,
    filtered_a: f32,
}

impl CurrentSense {
    /// Sensor with the nominal zero, not yet measured; `step_s` is the control period.
    pub fn new(config: &CurrentSensorConfig, step_s: f32) -> Self {
        let amps_per_count = config.amps_per_count();
        let tau = config.display_time_constant_s.max(step_s);
        Self {
            config: *config,
            amps_per_count,
            zero_samples: config.zero_samples.max(1),
            alpha_per_step: step_s / tau,
            zero_counts: config.nominal_zero_counts(),
            zero_valid: false,
            zero_in_range: true,
            zeroing: None,
            step_mean_a: 0.0,
            filtered_a: 0.0,
        }
    }

    /// Starts a zero measurement; the caller guarantees the bridge is off meanwhile.
    pub fn begin_zero(&mut self) {
        self.zeroing = Some((0, 0));
    }

    /// Whether a zero measurement is running.
    pub fn zeroing(&self) -> bool {
        self.zeroing.is_some()
    }

    /// Whether a zero has been measured and found plausible.
    pub fn zero_valid(&self) -> bool {
        self.zero_valid
    }

    /// False while the last measured zero is out of its plausible range.
    pub fn zero_in_range(&self) -> bool {
        self.zero_in_range
    }

    /// Zero offset in use, ADC counts.
    pub fn zero_counts(&self) -> f32 {
        self.zero_counts
    }

    /// Amperes per ADC count.
    #[cfg(test)]
    pub fn amps_per_count(&self) -> f32 {
        self.amps_per_count
    }

    /// Amperes for a mean ADC reading.
    pub fn amps(&self, mean_counts: f32) -> f32 {
        (mean_counts - self.zero_counts) * self.amps_per_count
    }

    /// Takes one step's samples: updates the mean and the display filter, and advances a
    /// running zero measurement. Returns the zero's verdict when the measurement completes.
    #[cfg(test)]
    pub fn update(&mut self, samples: &[u16]) -> Option<ZeroResult> {
        self.update_with_vdda(samples, f32::NAN)
    }

    /// As [`CurrentSense::update`], with the measured ADC reference `vdda_v` (NaN: the
    /// nominal one) for the zero's plausibility window.
    pub fn update_with_vdda(&mut self, samples: &[u16], vdda_v: f32) -> Option<ZeroResult> {
        let mut sum = 0u32;
        for &s in samples {
            sum += u32::from(s);
        }
        if !samples.is_empty() {
            let mean = sum as f32 / samples.len() as f32;
            self.step_mean_a = self.amps(mean);
            self.filtered_a += self.alpha_per_step * (self.step_mean_a - self.filtered_a);
        }
        let (acc, n) = self.zeroing.as_mut()?;
        *acc += u64::from(sum);
        *n += samples.len() as u32;
        if *n < self.zero_samples {
            return None;
        }
        let zero = *acc as f32 / *n as f32;
        self.zeroing = None;
        self.zero_counts = zero;
        // The window from the real tolerances: a ratiometric sensor on a 4.5-5.5 V supply
        // through a 1 % divider, read against the measured VDDA.
        let vref = if vdda_v.is_finite() && vdda_v > 1.0 {
            vdda_v
        } else {
            self.config.adc_reference_v
        };
        let full_scale = ((1u32 << self.config.adc_bits) - 1) as f32;
        let zero_v = zero * vref / full_scale;
        let (low, high) = self.config.zero_window_v();
        self.zero_in_range = zero_v >= low && zero_v <= high;
        self.zero_valid = self.zero_in_range;
        if self.zero_in_range {
            self.amps_per_count = self.config.ratiometric_amps_per_count(zero);
        }
        self.filtered_a = 0.0;
        self.step_mean_a = 0.0;
        Some(if self.zero_in_range {
            ZeroResult::InRange
        } else {
            ZeroResult::OutOfRange
        })
    }

    /// Mean current of the last step, A.
    pub fn step_mean_a(&self) -> f32 {
        self.step_mean_a
    }

    /// Low-pass filtered current for display, A.
    pub fn filtered_a(&self) -> f32 {
        self.filtered_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sense() -> CurrentSense {
        CurrentSense::new(&CurrentSensorConfig::default(), 1e-3)
    }

    #[test]
    fn zero_is_measured_and_used() {
        let mut s = sense();
        s.begin_zero();
        let block = [2080u16; 10];
        let mut verdict = None;
        for _ in 0..100 {
            verdict = verdict.or(s.update(&block));
        }
        assert_eq!(verdict, Some(ZeroResult::InRange));
        assert!(s.zero_valid());
        assert!((s.zero_counts() - 2080.0).abs() < 1e-3);
        // One ampere is 0.185 V * 2/3 / 3.3 V * 4095 = 153 counts.
        s.update(&[2080 + 153; 10]);
        assert!((s.step_mean_a() - 1.0).abs() < 0.01, "{}", s.step_mean_a());
    }

    #[test]
    fn zero_window_covers_the_supply_range() {
        // 4.75 V and 5.25 V sensor supplies read zeros of 1965 and 2172 counts: in range,
        // and the sensitivity follows the supply (ratiometric).
        for (supply, zero) in [(4.75f32, 1965u16), (5.25, 2172)] {
            let mut s = sense();
            s.begin_zero();
            let mut verdict = None;
            for _ in 0..100 {
                verdict = verdict.or(s.update(&[zero; 10]));
            }
            assert_eq!(verdict, Some(ZeroResult::InRange), "{supply}");
            let counts_per_amp = 0.185 * supply / 5.0 * (2.0 / 3.0) / 3.3 * 4095.0;
            assert!((1.0 / s.amps_per_count() / counts_per_amp - 1.0).abs() < 0.002);
        }
    }

    #[test]
    fn implausible_zero_is_reported() {
        let mut s = sense();
        s.begin_zero();
        // 2 A-equivalent above Vcc/2: an offset no sensor on a 4.5-5.5 V supply has.
        let block = [(2068.0 + 2.0 * 153.0) as u16; 10];
        let mut verdict = None;
        for _ in 0..100 {
            verdict = verdict.or(s.update(&block));
        }
        assert_eq!(verdict, Some(ZeroResult::OutOfRange));
        assert!(!s.zero_valid() && !s.zero_in_range());
    }

    #[test]
    fn display_filter_settles_with_its_time_constant() {
        let mut s = sense();
        let one_amp = (s.zero_counts() + 1.0 / s.amps_per_count()) as u16;
        for _ in 0..20 {
            s.update(&[one_amp; 10]);
        }
        // After one time constant (20 ms) a first-order filter reaches 1 - 1/e.
        let f = s.filtered_a() / s.step_mean_a();
        assert!((f - 0.64).abs() < 0.03, "{f}");
    }
}
