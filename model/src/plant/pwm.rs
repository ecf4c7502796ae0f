//! The bridge's 20 kHz switching as the current sensor sees it: the winding current's
//! ripple within a PWM period and the instant in the period at which the ADC samples it.
//!
//! The plant integrates the period-mean current (the average model: the bridge applies
//! d V_bus on average). Within a period of centre-aligned PWM (TIM1 counting up and down,
//! output high while the counter is below the compare value) the bridge applies V_bus for
//! the on-time d T, centred on the counter's zero, and shorts the winding (braking,
//! slow decay) for the off-time (1 - d) T, centred on the counter's top. With the winding's
//! time constant L / R (0.45 ms) ten times the period (50 us) the current is a triangle of
//! straight segments around its mean, rising by (V_bus - V_avg) d T / L in the on-time and
//! falling as much in the off-time, V_avg = d V_bus:
//!
//! peak to peak: delta_i = V_bus d (1 - d) T / L,
//!
//! largest at d = 1/2: 12 V x 50 us / (4 x 0.2 mH) = 0.75 A, +-0.375 A about the mean. The
//! exact segments are exponentials; their curvature changes the peak by a fraction of
//! order (T R / L)^2 / 12, 0.1 % here, so the triangle is what the plant uses: a few
//! multiplications per sample, no sub-stepping at 20 kHz.
//!
//! A straight segment's value at its centre is its mean, so a sample at the centre of the
//! on-time or of the off-time reads the period's mean: TIM1's own trigger at the
//! counter's top ([`AdcSampling::Synchronous`], as the firmware samples) has no bias. A
//! trigger from a timer unrelated to the PWM (the old TIM6 at 10 kHz, running from the
//! same clock) samples at a phase fixed at boot ([`AdcSampling::Unsynchronised`]) and reads
//! the mean plus the triangle's value there: a bias of up to half the ripple.

use crate::hardware::board;

/// When in the PWM period the ADC samples the motor current.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum AdcSampling {
    /// Triggered by TIM1 itself at the counter's top, the centre of the off-time
    /// (phase 1/2), as the firmware does.
    #[default]
    Synchronous,
    /// Triggered by an unrelated timer at a fixed phase to the PWM, as a fraction of the
    /// period from the counter's zero (the centre of the on-time): 0..1.
    Unsynchronised {
        /// Phase of the sampling instant in the PWM period, 0..1.
        phase: f64,
    },
}

impl AdcSampling {
    /// Phase of the sampling instant in the PWM period, 0..1 from the counter's zero.
    pub fn phase(&self) -> f64 {
        match *self {
            AdcSampling::Synchronous => 0.5,
            AdcSampling::Unsynchronised { phase } => phase - libm::floor(phase),
        }
    }
}

/// PWM period of the bridge, s ([`board::PWM_FREQUENCY_HZ`]).
pub const PERIOD_S: f64 = 1.0 / board::PWM_FREQUENCY_HZ;

/// Peak-to-peak ripple of the winding current at duty magnitude `duty` (0..1) on a bus of
/// `bus_v` volts through `inductance` henries, A: V_bus d (1 - d) T / L.
pub fn ripple_peak_to_peak(duty: f64, bus_v: f64, inductance: f64) -> f64 {
    let d = duty.abs().min(1.0);
    if inductance <= 0.0 {
        return 0.0;
    }
    (bus_v * d * (1.0 - d) * PERIOD_S / inductance).max(0.0)
}

/// The triangle's value at `phase` (fraction of the period from the counter's zero, the
/// on-time's centre) for duty magnitude `duty` and peak-to-peak ripple `pp`, relative to
/// the period's mean, A (for forward drive; the reverse is its negative).
pub fn ripple_at(phase: f64, duty: f64, pp: f64) -> f64 {
    let d = duty.abs().min(1.0);
    if pp == 0.0 || d <= 0.0 || d >= 1.0 {
        return 0.0;
    }
    // x in [-1/2, 1/2): the on-time is |x| <= d / 2.
    let x = phase - libm::floor(phase + 0.5);
    let half = 0.5 * d;
    if x.abs() <= half {
        // Rising from -pp/2 at the on-time's start to +pp/2 at its end.
        pp * x / d
    } else {
        // Falling through the off-time, from +pp/2 at x = d/2 to -pp/2 a period later.
        let since = if x > half { x - half } else { x + 1.0 - half };
        0.5 * pp - pp * since / (1.0 - d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hardware::rs735;

    #[test]
    fn the_triangle_closes_and_averages_to_zero() {
        for d in [0.1, 0.3, 0.5, 0.73] {
            let pp = ripple_peak_to_peak(d, 12.0, rs735::INDUCTANCE_H);
            let n = 10_000;
            let mean = (0..n)
                .map(|k| ripple_at(k as f64 / n as f64, d, pp))
                .sum::<f64>()
                / n as f64;
            assert!(mean.abs() < 1e-3 * pp, "{d}: {mean}");
            // Extremes at the on-time's edges, zero at both centres.
            assert!((ripple_at(0.5 * d, d, pp) - 0.5 * pp).abs() < 1e-12);
            assert!((ripple_at(1.0 - 0.5 * d, d, pp) + 0.5 * pp).abs() < 1e-12);
            assert!(ripple_at(0.0, d, pp).abs() < 1e-12);
            assert!(ripple_at(0.5, d, pp).abs() < 1e-12);
        }
    }

    #[test]
    fn worst_ripple_is_the_papers_0_37_amperes() {
        // V T / (4 L) at d = 1/2 on the 12 V bus: half of it either side of the mean.
        let pp = ripple_peak_to_peak(0.5, 12.0, rs735::INDUCTANCE_H);
        let expected = 12.0 * PERIOD_S / (4.0 * rs735::INDUCTANCE_H);
        assert!((pp - expected).abs() < 1e-12);
        assert!((0.5 * pp - 0.375).abs() < 1e-9, "{pp}");
        // The exact exponential segments' periodic solution differs by well under 1 %.
        let tau = rs735::INDUCTANCE_H / rs735::RESISTANCE_OHM;
        let a = libm::exp(-0.5 * PERIOD_S / tau);
        let exact = 12.0 / rs735::RESISTANCE_OHM * (1.0 - a) * (1.0 - a) / (1.0 - a * a);
        assert!((exact / pp - 1.0).abs() < 2e-3, "{exact} vs {pp}");
    }

    #[test]
    fn sampling_phases() {
        assert_eq!(AdcSampling::Synchronous.phase(), 0.5);
        assert!((AdcSampling::Unsynchronised { phase: 1.25 }.phase() - 0.25).abs() < 1e-15);
    }
}
