//! The hardware overcurrent trip: COMP3 compares the current-sense pin with a threshold
//! from DAC3 and its output is TIM1's break input, so the bridge's PWM stops within
//! microseconds with no software involved.
//!
//! ```text
//!  ACS714 -> 10k/20k divider -> PA0 --+--> ADC1_IN1 (sampling)
//!                                     '--> COMP3_INP (INPSEL = 0)
//!  DAC3_CH1 (internal, no pin) ---------> COMP3_INM (INMSEL = 100: DAC3_CH1, RM0440 Table 197)
//!  COMP3_OUT -> TIM1 BRK (AF1.BKCMP3E, not inverted; BDTR.BKP active high, BKF 8 x 16/170 MHz)
//!            -> MOE cleared in hardware -> PA8 to its idle level (low)
//!            -> TIM1_BRK_TIM15 interrupt drops the bridge enable (PA9)
//! ```
//!
//! Timing: the ACS714 itself (5 us rise time, 80 kHz bandwidth) dominates; COMP3 in
//! high-speed mode adds tens of ns, the break filter 0.75 us (8 samples at 170/16 MHz, which
//! rejects the shorter spikes the bridge's switching edges couple into the sense line). The
//! threshold is [`crate::board::HW_TRIP_MARGIN`] above the core's software limit, so the
//! software check acts on slow overloads and the comparator only on fast faults.
//!
//! The comparator sees one polarity. The threshold follows the drive direction: above zero
//! (output not inverted) while driving forward, below zero (output inverted) while driving
//! in reverse; the software check (|I|) covers both.

use embassy_stm32::Peri;
use embassy_stm32::dac::{Ch1, DacChannel, Value};
use embassy_stm32::mode::Blocking;
use embassy_stm32::pac;
use embassy_stm32::pac::comp::vals::{Hysteresis, Inm, Polarity};
use embassy_stm32::peripherals::{COMP3, DAC3};

use crate::analog;

/// DAC3 settling (unbuffered, internal load) and COMP3 start-up: 10 us at 170 MHz.
const SETTLE_CYCLES: u32 = 1_700;

/// COMP3 with its DAC3 threshold, following the drive direction and the measured zero.
pub struct OvercurrentTrip {
    dac: DacChannel<'static, Blocking>,
    _comp: Peri<'static, COMP3>,
    limit_a: f32,
    zero_counts: f32,
    direction: Direction,
}

impl OvercurrentTrip {
    /// Enables DAC3_CH1 (internal, unbuffered) and COMP3 on PA0 (already analog: ADC1 owns
    /// the pin) against it, for `limit_a` amperes forward from `zero_counts`. TIM1's break
    /// input must already listen to COMP3 (`CamMotor::new`); clear the break flag after this.
    pub fn new(
        comp: Peri<'static, COMP3>,
        dac: Peri<'static, DAC3>,
        limit_a: f32,
        zero_counts: f32,
    ) -> Self {
        let dac = DacChannel::new_internal_blocking::<DAC3, Ch1>(dac);
        // COMP is clocked with SYSCFG (RCC_APB2ENR.SYSCFGEN).
        pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
        let mut trip = Self {
            dac,
            _comp: comp,
            limit_a,
            zero_counts,
            direction: Direction::Forward,
        };
        trip.apply();
        pac::COMP3.csr().write(|w| {
            w.set_inpsel(false); // PA0
            w.set_inmsel(Inm::DACA); // DAC3_CH1 for COMP3
            w.set_hyst(Hysteresis::HYST20M); // ~25 counts, 0.16 A: no chatter at the limit
            w.set_polarity(Polarity::NOT_INVERTED);
            w.set_en(true);
        });
        cortex_m::asm::delay(SETTLE_CYCLES);
        trip
    }

    /// The limit, A.
    pub fn limit_a(&self) -> f32 {
        self.limit_a
    }

    /// The threshold now, DAC counts.
    pub fn threshold_counts(&self) -> u16 {
        self.dac.read()
    }

    /// Re-centres the threshold on the core's measured zero (counts); cheap when unchanged.
    pub fn set_zero(&mut self, zero_counts: f32) {
        if (zero_counts - self.zero_counts).abs() >= 0.5 {
            self.zero_counts = zero_counts;
            self.apply();
        }
    }

    /// Points the trip at the current of the drive direction and waits for the comparator
    /// to settle. Moving the threshold across the signal trips the break on the way, so
    /// call it with the bridge off (`CamMotor::set_direction` does, and clears that trip).
    pub fn set_direction(&mut self, direction: Direction) {
        if direction != self.direction {
            self.direction = direction;
            self.apply();
            cortex_m::asm::delay(SETTLE_CYCLES);
        }
    }

    fn apply(&mut self) {
        let (sign, polarity) = match self.direction {
            Direction::Forward => (1.0, Polarity::NOT_INVERTED),
            Direction::Reverse => (-1.0, Polarity::INVERTED),
        };
        let code = analog::trip_threshold_counts(self.zero_counts, self.limit_a, sign);
        self.dac.set(Value::Bit12Right(code));
        pac::COMP3.csr().modify(|w| w.set_polarity(polarity));
    }
}

/// Whether COMP3 sees an overcurrent now (its output, after the polarity the drive
/// direction set).
pub fn over_threshold() -> bool {
    pac::COMP3.csr().read().value()
}

/// Sense of rotation of the cam motor, as driven on the direction pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum Direction {
    /// Direction pin low.
    Forward,
    /// Direction pin high.
    Reverse,
}
