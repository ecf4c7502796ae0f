//! The Nucleo-G474RE board: clocks, pin map and peripheral drivers.
//!
//! This is the one file that knows which pin does what. It hands the rest of the firmware
//! ready drivers in their safe state; tasks only move data between them and the control core.
//!
//! # Pin map
//!
//! Header names are the Nucleo-64 ones (UM2505): Arduino `Dn`/`An`, morpho `CN7-n`.
//!
//! | Signal                  | Pin  | Header       | Peripheral (AF)        | Notes                                            |
//! |-------------------------|------|--------------|------------------------|--------------------------------------------------|
//! | Cam motor PWM           | PA8  | D7           | TIM1_CH1 (AF6), 20 kHz centre-aligned | H-bridge PWM input; 10 kΩ pull-down on the driver; idle (break, MOE off) = low |
//! | Cam motor direction     | PB5  | D4           | GPIO out               | low = [`Direction::Forward`]                     |
//! | Cam motor enable        | PA9  | D8           | GPIO out               | low = off; 10 kΩ pull-down on the driver (¹); the safe state's BSRR write |
//! | Encoder A (AMT102-V)    | PB6  | D10          | TIM4_CH1 (AF2)         | quadrature, x4 decoding, digital filter; no internal pull (push-pull 5 V outputs) (²) |
//! | Encoder B (AMT102-V)    | PB7  | CN7-21       | TIM4_CH2 (AF2)         | (²)                                              |
//! | Output encoder A        | PC6  | CN10-4       | TIM3_CH1 (AF2)         | second AMT102-V on the output shaft, x4, same filter; no internal pull, external 10 kΩ pull-up to 5 V (⁸) |
//! | Output encoder B        | PC7  | D9 (CN10-19) | TIM3_CH2 (AF2)         | as A (⁸)                                          |
//! | Motor current (ACS714)  | PA0  | A0           | ADC1_IN1 and COMP3_INP | through a divider to ≤ 3.3 V (³); the comparator trips TIM1's break (⁴) |
//! | Bridge supply voltage   | PA1  | A1           | ADC1_IN2               | 100 kΩ over 10 kΩ, 100 nF at the pin: 12–24 V reads 1.09–2.18 V, 36 V full scale (⁵) |
//! | Motor NTC (optional)    | PB0  | A3           | ADC1_IN15              | 10 kΩ NTC to GND, 10 kΩ pull-up to 3V3 (VDDA), 100 nF; open = not fitted (⁶) |
//! | Host link TX            | PA2  | ST-LINK VCP  | USART2_TX (AF7)        | 921 600 baud 8N1                                 |
//! | Host link RX            | PA3  | ST-LINK VCP  | USART2_RX (AF7)        |                                                  |
//! | Release button B1       | PC13 | B1           | EXTI13                 | active high (held = release requested)           |
//! | Heartbeat LED LD2       | PA5  | LD2 / D13    | GPIO out               | active high                                      |
//! | SWD                     | PA13, PA14 | ST-LINK | SWDIO, SWCLK          | keep free: flashing and defmt-rtt                |
//!
//! # Internal resources
//!
//! | Resource            | Use                                                                 |
//! |---------------------|---------------------------------------------------------------------|
//! | TIM1                | PWM, centre-aligned 20 kHz; master: TRGO = update, repetition counter 3, so ADC1 is triggered every second PWM period (10 kHz) at the same counter extreme (⁷); break input = COMP3 (and the core's LOCKUP, SYSCFG_CFGR2.CLL), filter 0.75 µs; LOCK level 2 (BDTR's break and off-state bits, OIS1, CC1P; not MOE, CCR1, CCMR1) |
//! | COMP3, DAC3_CH1     | hardware overcurrent trip ([`crate::trip`]): PA0 against an internal DAC threshold, no pin |
//! | ADC1 + DMA1_CH1     | scan of PA0, PA1, PB0, VREFINT per TIM1 trigger ([`crate::analog`]); VDDA from VREFINT and its factory calibration (`VREFINTCAL`, 0x1FFF_75AA) |
//! | TIM4                | encoder, input filter fDTS/16 × 8 (0.75 µs)                          |
//! | TIM3                | output encoder, the same mode and filter                             |
//! | TIM2                | embassy's time driver (`time-driver-tim2`): TIM15, `time-driver-any`'s pick, shares its vector with TIM1_BRK |
//! | TIM1_BRK_TIM15 IRQ  | break: drops the bridge enable ~1 µs after the hardware trip (P0)    |
//! | WWDG + its IRQ      | control-loop deadline, 2 ms ([`crate::safety::StallWatchdog`], P0)  |
//! | IWDG                | ≈ 250 ms, fed only when every task checked in: the last layer        |
//! | DMA1_CH2 / CH3      | USART2 TX / RX (through DMAMUX)                                      |
//! | UART4 IRQ           | the control task's high-priority executor (the UART itself is unused) |
//! | NMI                 | flash double-ECC in the STORAGE region counts as a corrupt slot; anything else resets in the safe state |
//! | DWT CYCCNT          | cycles per control step (mean, max per second)                      |
//! | MPU region 0        | stack guard: 1 KiB, no access, between the statics and the stack ([`crate::stack_guard`]) |
//! | Flash 0x0807_C000..0x0808_0000 | bank 2: the calibration store (`memory.x`)               |
//!
//! (¹) From reset until [`Board::new`] runs every GPIO is a high-impedance analog input, so only
//! the external pull-downs keep the bridge off while the MCU resets or is being flashed.
//! PB4 (D5) was avoided for the enable: as JTAG NJTRST it has an internal pull-up at reset.
//! (²) The AMT102-V runs from 5 V, so its A/B outputs need 5 V-tolerant (FT) inputs or a level
//! shifter. TIM4 on PB6/PB7 was preferred to TIM3 on PA6/PA7 because PA6 doubles as DAC2_OUT1,
//! which is not 5 V tolerant; confirm FT for PB6/PB7 in the DS12288 pin table before wiring.
//! The filter: at the cam's top speed (20 Hz, one turn per vibration cycle) the 2048-PPR
//! encoder puts out 41 kHz per channel, so each level lasts ≥ 12.2 µs and the x4 edges come
//! 6.1 µs apart. [`ENCODER_FILTER`] passes a level only after 8 equal samples at
//! 170 MHz / 16, 0.75 µs: glitches from the bridge's switching edges on the encoder cable
//! (tens to hundreds of ns) are dropped, real levels have 16 times that, and both channels
//! are delayed alike (±94 ns), far inside the 6.1 µs quadrature spacing.
//! (³) The ACS714 output swings 0.5–4.5 V on a 5 V supply; analog inputs are never 5 V tolerant,
//! e.g. 10 kΩ over 20 kΩ scales it to 0.33–3.0 V. The core owns the counts-to-amperes calibration.
//! The sensor is in series with the motor: forward drive (direction low) must read above zero.
//! (⁴) See [`crate::trip`]: threshold [`HW_TRIP_MARGIN`] × the core's current limit, re-centred
//! on the core's measured zero, on the drive direction's side of zero.
//! (⁵) `model::hardware::bus_divider`. 9.1 kΩ source with 100 nF: the sampling capacitor is
//! charged from the 100 nF, the 0.9 ms time constant averages the bridge's ripple.
//! (⁶) `model::hardware::ntc`; ratiometric to VDDA, so VDDA drops out. Readings within 2 % of
//! either rail mean not fitted (open) or shorted, and no temperature is reported. PB0 (an
//! ADC1 input) rather than PA4 (ADC2 only): one scan of one ADC carries every analog input,
//! in step with the PWM. Header names of PA1 (A1) and PB0 (A3) per UM2505's Arduino table:
//! confirm against the board's solder-bridge settings before wiring.
//! (⁷) The sampling instant, argued: in centre-aligned PWM the on-time is centred on the
//! counter's zero and the off-time on its top. The motor current (L/R = 0.45 ms, ten PWM
//! periods) is a triangle of straight segments, and the value of a straight segment at its
//! centre is its mean, so the current at the middle of the on-time and at the middle of the
//! off-time both equal the period's mean, whatever the duty, ripple or supply (continuous
//! conduction: always with [`Decay::Brake`]). A timer unrelated to the PWM (the old TIM6)
//! samples the ripple at a phase fixed at boot: a bias of up to half the ripple. The
//! repetition counter is written before the counter starts, which puts every update on the
//! overflow (RM0440: odd RCR in centre-aligned mode), i.e. the centre of the off-time: for
//! the rig's duties (3.6–8.8 V from 12–24 V, d < 0.75) that is the instant furthest from a
//! switching edge at low duty, where the edges' spikes would land in the short on-time. The
//! board checks the phase at boot and logs it; the other extreme is as unbiased. The
//! ACS714's own lag (~2 µs) is roughly undone by the 2.2 µs sampling window that follows the
//! trigger; what is left (< 0.1 µs of slope) is for a scope on the real board to confirm.
//! (⁸) The optional output-shaft encoder ([`OUTPUT_ENCODER`]; `firmware_core`'s
//! `output-encoder` feature): TIM3 on PC6/PC7 (RM0440 / DS12288 alternate functions: AF2 is
//! TIM3_CH1/CH2 on both; the metapac's STM32G474RE pin map agrees). TIM3 is otherwise unused
//! (the time driver is TIM2), PC6/PC7 are not analog or DAC pins and clash with nothing
//! above (TIM3's other channels, PB0 and PB5, stay GPIO/analog: only CH1/CH2 are taken).
//! TIM3 on PA6/PA7 was avoided as for the cam encoder (²). The output turns far slower
//! than the cam (Fig. 5's load falls at about 1 rad/s, 1.3 kHz of x4 edges): the filter
//! costs nothing. Confirm FT for PC6/PC7 and the CN10 positions (UM2505) before wiring.
//! No internal pull on any encoder input (PB6/PB7, PC6/PC7): the AMT102-V drives them from
//! 5 V, and an FT pin driven above VDD must not have its internal pull-up (or pull-down)
//! enabled (AN4899, "5 V tolerant I/Os"). The AMT102-V's outputs are push-pull, so a fitted
//! encoder needs no pull at all; for the output encoder, which may be left unplugged, fit
//! 10 kΩ external pull-ups from PC6 and PC7 to the encoder's 5 V (an unplugged encoder then
//! reads still instead of counting noise; 0.5 mA into a driven-low output is harmless).

use core::sync::atomic::Ordering;
use embassy_stm32::adc::{Adc, AdcChannel as _, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{Blocking, FLASH_BASE, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::mode::Async;
use embassy_stm32::pac::timer::vals::{
    Bkinp, Bkp, Cms, Dir, FilterValue, Lock, Mms, Ocm, Ossi, Urs,
};
use embassy_stm32::peripherals::{
    ADC1, DMA1_CH1, DMA1_CH2, DMA1_CH3, EXTI13, IWDG, PA0, PA1, PA2, PA3, PA8, PA9, PB0, PB5, PB6,
    PB7, PC6, PC7, PC13, TIM1, TIM3, TIM4, USART2,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::Ch1;
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::qei::{self, Qei};
use embassy_stm32::timer::simple_pwm::{PwmPin, PwmPinConfig};
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Config, Peri, Peripherals, bind_interrupts, dma, interrupt, pac, triggers};

use firmware_core::CoreConfig;
use firmware_core::bridge::{BridgeGate, BridgeHw, EnableResult};
use model::hardware::board as hw;

use crate::analog;
use crate::safety::StallWatchdog;
use crate::trip::OvercurrentTrip;

bind_interrupts!(struct Irqs {
    USART2 => usart::InterruptHandler<USART2>;
    DMA1_CHANNEL1 => dma::InterruptHandler<DMA1_CH1>;
    DMA1_CHANNEL2 => dma::InterruptHandler<DMA1_CH2>;
    DMA1_CHANNEL3 => dma::InterruptHandler<DMA1_CH3>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// PWM carrier frequency of the cam motor's H-bridge: above hearing, within the driver's limit.
pub const MOTOR_PWM_FREQUENCY: Hertz = Hertz(hw::PWM_FREQUENCY_HZ as u32);
/// Rate at which TIM1 triggers the motor-current conversions, Hz.
pub const CURRENT_SAMPLE_RATE_HZ: u32 = hw::CURRENT_SAMPLE_RATE_HZ as u32;
/// TIM1 repetition counter: centre-aligned, the counter over- or underflows twice per PWM
/// period, and an update (ADC trigger) comes every `RCR + 1` of them: 4, every second period.
const PWM_REPETITION: u16 = (2 * MOTOR_PWM_FREQUENCY.0 / CURRENT_SAMPLE_RATE_HZ - 1) as u16;
/// TIM1's counter clock, Hz: the APB2 timer clock, SYSCLK undivided ([`config`]).
const TIM1_CLOCK_HZ: u32 = hw::SYSCLK_HZ as u32;
/// TIM1's auto-reload, prescaler 1: centre-aligned, the counter runs 0 → ARR → 0, one
/// period is `2 ARR` clocks (RM0440 28.3.3), so ARR = clock / (2 × [`MOTOR_PWM_FREQUENCY`])
/// = 4250: 20,000.0 Hz, and the ADC's blocks (the control steps) come every 1,000.0 us of
/// the device's clock. (4249, embassy's `SimplePwm` choice for the same frequency, runs at
/// 20,004.7 Hz: every step 0.24 us early, telemetry at 250 Hz 3,999 us apart; the image on
/// the emulated board showed it.) Written directly, so the image has no run-time 64-bit
/// division for it. The compare value for 100 % duty is `ARR + 1`.
const PWM_ARR: u16 = {
    let clocks = TIM1_CLOCK_HZ / (2 * MOTOR_PWM_FREQUENCY.0);
    // An exact period, and ARR + 1 (full duty) must fit the 16-bit compare register too.
    assert!(clocks * 2 * MOTOR_PWM_FREQUENCY.0 == TIM1_CLOCK_HZ);
    assert!(clocks >= 2 && clocks < u16::MAX as u32);
    clocks as u16
};
/// TIM1 CH1's compare value for 100 % duty.
const PWM_FULL_DUTY: u16 = PWM_ARR + 1;
/// ADC DMA ring: two control steps, so one is read while the DMA fills the other.
const ADC_DMA_LEN: usize = 2 * analog::BLOCK_LEN;
/// Baud rate of the host link over the ST-LINK virtual COM port.
pub const HOST_BAUD_RATE: u32 = crate::HOST_BAUD;
/// UART receive DMA ring: 44 ms of back-to-back bytes at [`HOST_BAUD_RATE`] (10 bits a
/// byte), more than thread mode stalls in a calibration save ([`SAVE_STALL_MAX_US`]), so a
/// request sent during a save waits in the ring and is answered after it.
const HOST_RX_DMA_LEN: usize = 4096;
/// Longest stall of thread mode (`host_rx` included) by one calibration save, us: the
/// store erases one 2 KiB page (DS12288: 22 ms typical, 24.5 ms at most) and programs a
/// 112-byte record, 14 double words at 91 us at most, then reads it back.
pub const SAVE_STALL_MAX_US: u32 = 24_500 + 14 * 91 + 300;
/// The ring outlasts a save by half again: bytes the ring holds, in microseconds at
/// [`HOST_BAUD_RATE`] (10 bits a byte).
const _: () = assert!(
    (HOST_RX_DMA_LEN as u64) * 10 * 1_000_000 / (HOST_BAUD_RATE as u64)
        >= (SAVE_STALL_MAX_US as u64) * 3 / 2
);
/// Independent-watchdog timeout. LSI is 32 kHz ± ~7 %, so the real timeout is ~235–270 ms.
pub const WATCHDOG_TIMEOUT_US: u32 = 250_000;
/// The hardware trip sits this far above the core's software current limit: the software
/// check (1 ms means, a 10 ms hold) handles slow overloads, the comparator fast faults.
/// 1.25 × 4.8 A = 6 A, inside the ACS714's 0.5–4.5 V output swing (±10.8 A).
pub const HW_TRIP_MARGIN: f32 = 1.25;
/// TIM4's input filter on the encoder channels: 8 samples at fDTS/16 (0.75 µs), see (²).
pub const ENCODER_FILTER: FilterValue = FilterValue::FDTS_DIV16_N8;
/// TIM1's break filter on COMP3's output: 8 samples at fDTS/16 (0.75 µs).
const BREAK_FILTER: FilterValue = FilterValue::FDTS_DIV16_N8;

/// What the bridge does with the motor during the PWM's off-time: the one setting
/// `model::hardware::board::DECAY`, which the plant and the core's estimator read too.
pub use model::hardware::board::Decay;

/// The H-bridge board wired to PA8 / PB5 / PA9.
#[derive(Clone, Copy, Debug)]
pub struct BridgeBoard {
    /// Product name, for the log.
    pub name: &'static str,
    /// Off-time behaviour with sign-magnitude PWM (PWM on PA8, direction on PB5, enable on PA9).
    pub decay: Decay,
}

/// The bridge the image is built for (`model::hardware::board::DECAY`).
///
/// The recommended bridge is the Pololu G2 High-Power Motor Driver 24v13 (#2992): 6.5–40 V,
/// 13 A continuous, PWM to 100 kHz, 1.8–5 V logic. Sign-magnitude: PWM high drives in DIR's
/// direction, PWM low brakes low (both outputs to ground), SLP low puts the outputs in high
/// impedance. So [`Decay::Brake`] while enabled, coast when the enable (SLP) is low, which is
/// the safe state: the default image is built for it. Check the board's SLP default before
/// wiring: where it is pulled up on the board, the 10 kΩ pull-down must be sized to win (¹).
/// With the feature `bridge-coast-decay` the image is built for a bridge that coasts in the
/// off-time ([`Decay::Coast`], e.g. PWM on its enable), the drive the paper's bench supply
/// had.
///
/// Braking decay takes power back: when the cam overruns the drive (the carrier pushing
/// back once a turn, a deceleration) the current reverses and flows into the supply in the
/// on-time. A bench supply cannot sink it, so the bus rises; the core stops the drive above
/// `model::hardware::board::BUS_OVERVOLTAGE_V` (`BUS_OVERVOLTAGE`). The hardware trip
/// (COMP3) watches the drive direction's side of zero only, so it does not see that reverse
/// current; the software check (|I|, 1 ms means) does.
pub const BRIDGE: BridgeBoard = BridgeBoard {
    name: match hw::DECAY {
        Decay::Brake => "Pololu G2 24v13 (braking decay)",
        Decay::Coast => "a bridge that coasts in the off-time",
    },
    decay: hw::DECAY,
};

/// The core's configuration on this board: the defaults (read from `model::hardware`, the
/// bridge's decay mode among them) with the output encoder.
pub fn core_config() -> CoreConfig {
    let mut config = CoreConfig {
        output_encoder: OUTPUT_ENCODER,
        // 1.0 on a board; an emulated board's pace (`crate::RIG_TIME_SCALE`).
        time_scale: crate::time_scale(),
        ..CoreConfig::default()
    };
    // The bus divider is fitted (main.rs reads it every step): `Info` says so, and health
    // reports the voltage only then.
    config
        .capabilities
        .insert(protocol::Capabilities::BUS_VOLTAGE);
    config
}

/// The output-shaft encoder on TIM3 (PC6/PC7, see (⁸)): an AMT102-V at 2048 pulses per
/// revolution, as on the cam. `None` for a board without one: then telemetry reports NaN
/// for the output angle and `Info` leaves `OUTPUT_ENCODER` clear (a floating input would
/// read as an output at rest, which the procedures would believe).
pub const OUTPUT_ENCODER: Option<firmware_core::OutputEncoderConfig> =
    Some(firmware_core::OutputEncoderConfig {
        counts_per_rev: model::hardware::amt102::COUNTS_PER_REV,
        moving_rad_s: 0.01,
        overspeed_rad_s: 20.0,
        speed_window_us: 50_000,
    });

/// The Nucleo-G474RE's HSE crystal (X3, MB1367), Hz.
pub const HSE_HZ: u32 = 24_000_000;

/// Clock tree: 170 MHz SYSCLK from the Nucleo's 24 MHz HSE crystal (24 MHz / 6 × 85 / 2),
/// range-1 boost, ADC12 on SYSCLK. USART2 runs on PCLK1 (170 MHz, undivided), so the host
/// link's clock is the crystal's (tens of ppm) instead of HSI16's ±1 %: what is left is
/// the divider's quantisation, [`crate::HOST_BAUD_ERROR_PPM`] (+0.25 %: BRR 184 gives
/// 923,913 Bd for 921,600), logged at boot. APB1 and APB2 run undivided (170 MHz): the
/// WWDG's timing assumes it.
pub fn config() -> Config {
    use embassy_stm32::rcc::{
        Hse, HseMode, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk, mux,
    };
    use embassy_stm32::time::Hertz;

    let mut config = Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV6,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    // Above 150 MHz the regulator must run in range-1 boost mode.
    config.rcc.boost = true;
    // The ADC kernel clock is off after reset; the driver divides SYSCLK to ≤ 60 MHz.
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    config
}

/// Why the MCU last came out of reset, read from RCC_CSR.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct ResetCause {
    /// The independent watchdog expired: a task stopped checking in.
    pub watchdog: bool,
    /// The window watchdog expired: the control loop stalled with interrupts masked, or the
    /// core locked up (the early-wakeup handler resets by software first otherwise).
    pub window_watchdog: bool,
    /// Software reset (e.g. a probe's `reset`, `SYSRESETREQ`, or a fault handler).
    pub software: bool,
    /// NRST pin went low (B2, the probe; internal resets also pull NRST, so this is set too).
    pub pin: bool,
    /// Brown-out or power-on reset.
    pub brown_out: bool,
}

impl ResetCause {
    /// Reads the reset flags and clears them, so the next boot reports only its own cause.
    pub fn take() -> Self {
        let csr = pac::RCC.csr().read();
        pac::RCC.csr().modify(|w| w.set_rmvf(true));
        Self {
            watchdog: csr.iwdgrstf(),
            window_watchdog: csr.wwdgrstf(),
            software: csr.sftrstf(),
            pin: csr.pinrstf(),
            brown_out: csr.borrstf(),
        }
    }
}

pub use crate::trip::Direction;

/// Where in the PWM period TIM1's update (the ADC trigger) falls.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum SamplingPoint {
    /// Counter at its top: the centre of the off-time (the intended point).
    OffTimeCentre,
    /// Counter at zero: the centre of the on-time (as unbiased; nearer the edges at low duty).
    OnTimeCentre,
    /// No update seen (TIM1 not counting): no samples will come either.
    Unknown,
}

/// TIM1, COMP3 and the bridge enable pin as the bridge gate's registers
/// ([`firmware_core::bridge`] has the switch-on order and its tests).
struct BridgeRegs {
    enable: Output<'static>,
}

impl BridgeHw for BridgeRegs {
    fn break_seen(&mut self) -> bool {
        pac::TIM1.sr().read().bif(0) || crate::safety::BREAK_LATCHED.load(Ordering::Acquire)
    }

    fn overcurrent_now(&mut self) -> bool {
        crate::trip::over_threshold()
    }

    fn clear_break(&mut self) {
        crate::safety::BREAK_LATCHED.store(false, Ordering::Release);
        clear_tim1_flags(|w| w.set_bif(0, false));
        pac::TIM1.dier().modify(|w| w.set_bie(true));
    }

    fn load_duty_now(&mut self, compare: u16) {
        // With OC1PE clear, a CCR1 write reaches the active register at once (RM0440
        // 28.6.27); the preload goes back on before MOE, so later writes wait for the
        // update event as usual. (Why TIM1 is locked at level 2, not 3: level 3 would
        // freeze OC1PE.)
        let t = pac::TIM1;
        t.ccmr_output(0).modify(|w| w.set_ocpe(0, false));
        t.ccr(0).write(|w| w.set_ccr(compare));
        t.ccmr_output(0).modify(|w| w.set_ocpe(0, true));
    }

    fn set_duty(&mut self, compare: u16) {
        pac::TIM1.ccr(0).write(|w| w.set_ccr(compare));
    }

    fn set_main_output(&mut self, on: bool) {
        pac::TIM1.bdtr().modify(|w| w.set_moe(on));
    }

    fn set_enable(&mut self, on: bool) {
        if on {
            self.enable.set_high();
        } else {
            self.enable.set_low();
        }
    }
}

/// Clears TIM1 status flags by one write: `clear` sets to 0 the flags to clear in an
/// all-ones word. The flags are rc_w0 (writing 1 leaves a flag as it is), so a
/// read-modify-write would clear a flag the timer set between the read and the write.
fn clear_tim1_flags(clear: impl FnOnce(&mut pac::timer::regs::SrAdv)) {
    pac::TIM1.sr().write(|w| {
        w.0 = u32::MAX;
        clear(w);
    });
}

/// The cam motor's H-bridge: PWM magnitude, direction and enable, behind TIM1's break.
///
/// Built in the safe state (enable low, MOE off, 0 % duty) and returns to it on
/// [`CamMotor::stop`]. After a hardware trip it refuses to drive until [`CamMotor::rearm`];
/// the order of every switch-on around the break is [`BridgeGate`]'s.
pub struct CamMotor {
    /// TIM1, clocked (dropping it would stop its clock).
    _timer: Timer<'static, TIM1>,
    /// PA8 in its TIM1_CH1 function (dropping it would disconnect the pin).
    _pwm_pin: PwmPin<'static, TIM1, Ch1>,
    direction_pin: Output<'static>,
    regs: BridgeRegs,
    gate: BridgeGate,
    direction: Direction,
    sampling: SamplingPoint,
}

impl CamMotor {
    /// Sets up TIM1 CH1 at [`MOTOR_PWM_FREQUENCY`], centre-aligned, as the ADC's trigger
    /// master, with COMP3 as its break input, everything off.
    pub fn new(
        tim: Peri<'static, TIM1>,
        pwm_pin: Peri<'static, PA8>,
        direction_pin: Peri<'static, PB5>,
        enable_pin: Peri<'static, PA9>,
    ) -> Self {
        // Enable first, so the bridge is held off before the PWM pin becomes an output.
        let enable = Output::new(enable_pin, Level::Low, Speed::Low);
        let direction_pin = Output::new(direction_pin, Level::Low, Speed::Low);
        // Low speed (OSPEEDR 00): a 20 kHz line needs edges of tens of ns at most, and the
        // slowest slew rings least into the bridge's input (embassy's `PwmPin::new` picks
        // very high). The boot trace checks GPIOA_OSPEEDR8 = 00.
        let pwm_pin = PwmPin::new_with_config(
            pwm_pin,
            PwmPinConfig {
                output_type: OutputType::PushPull,
                speed: Speed::Low,
                pull: Pull::None,
            },
        );
        // TIM1 clocked and reset: main output (MOE) off, CH1 disabled.
        let timer = Timer::new(tim);
        let t = pac::TIM1;
        // Centre-aligned mode 2 at MOTOR_PWM_FREQUENCY, CH1 in PWM mode 1 with preloaded
        // compare and auto-reload, loaded by an update event that sets no flag: the setup
        // embassy's `SimplePwm` made (`CountingMode::CenterAlignedUpInterrupts`).
        t.cr1().modify(|w| {
            w.set_dir(Dir::UP);
            w.set_cms(Cms::CENTER_ALIGNED2);
            w.set_arpe(true);
        });
        t.psc().write_value(0);
        t.arr().write(|w| w.set_arr(PWM_ARR));
        t.ccmr_output(0).modify(|w| {
            w.set_ocm(0, Ocm::PWM_MODE1);
            w.set_ocpe(0, true);
        });
        t.ccr(0).write(|w| w.set_ccr(0));
        t.cr1().modify(|w| w.set_urs(Urs::COUNTER_ONLY));
        t.egr().write(|w| w.set_ug(true));
        t.cr1().modify(|w| {
            w.set_urs(Urs::ANY_EVENT);
            w.set_cen(true);
        });
        // Debug halt (`model::hardware::board::TIM1_STOPS_IN_DEBUG`, false): TIM1 keeps
        // switching the last duty while a probe halts the core, with the COMP3 break still
        // armed, until the IWDG (not frozen) resets the chip ~250 ms in; the pins then float
        // and the bridge's pull-downs switch it off (the G2 sleeps and coasts). Stopped
        // instead (DBG_TIM1_STOP set, as before), TIM1 would put PA8 at its idle level, low,
        // while the enable (a GPIO) stays high: the G2 brakes a spinning cam at about 17 A,
        // beyond the current sensor's range and in the direction COMP3 does not watch.
        // The WWDG is frozen (`StallWatchdog::new`), or every breakpoint would reset. The
        // boot trace checks the bit.
        pac::DBGMCU
            .apb2fzr()
            .modify(|w| w.set_tim1(model::hardware::board::TIM1_STOPS_IN_DEBUG));
        // Break from COMP3 only (not the BKIN pins).
        t.af1().modify(|w| {
            w.set_bkine(false);
            w.set_bkcmpe(2, true);
            w.set_bkcmpp(2, Bkinp::NOT_INVERTED);
        });
        // Outputs off (MOE clear, by software or break) hold PWM at its idle level, low; no
        // automatic re-enable. LOCK level 2 then freezes until reset: BDTR's break and
        // off-state bits (BKE, BKP, BKF, AOE, OSSI, OSSR, DTG), CR2's idle levels (OIS1)
        // and CCER's polarity (CC1P). Not locked: MOE (software must clear and set it),
        // CCR1, and CCMR1 (level 3 would freeze OC1PE, which a switch-on clears to load
        // the duty at once: `BridgeRegs::load_duty_now`). COMP3's own CSR lock is not set
        // either: the trip flips its polarity with the drive direction (`crate::trip`).
        t.bdtr().modify(|w| {
            w.set_ossi(Ossi::IDLE_LEVEL);
            w.set_bkf(0, BREAK_FILTER);
            w.set_bkp(0, Bkp::ACTIVE_HIGH);
            w.set_bke(0, true);
            w.set_aoe(false);
            w.set_moe(false);
            w.set_lock(Lock::LEVEL2);
        });
        let sampling = start_synchronous_trigger();
        let mut motor = Self {
            _timer: timer,
            _pwm_pin: pwm_pin,
            direction_pin,
            regs: BridgeRegs { enable },
            gate: BridgeGate::new(),
            direction: Direction::Forward,
            sampling,
        };
        motor.stop();
        t.ccer().modify(|w| w.set_cce(0, true));
        motor
    }

    /// Where the ADC samples within the PWM period (checked at boot).
    pub fn sampling_point(&self) -> SamplingPoint {
        self.sampling
    }

    /// Clears a break flag left by the comparator's start-up and unmasks the break interrupt.
    /// Call once the trip is configured.
    pub fn arm_break(&mut self) {
        self.gate.rearm(&mut self.regs);
        crate::safety::enable_break_interrupt();
    }

    /// Compare value for 100 % duty (4251: ARR + 1, ARR = 170 MHz / 2 / 20 kHz).
    pub fn max_duty(&self) -> u32 {
        u32::from(PWM_FULL_DUTY)
    }

    /// Sets the direction pin and points the trip at that direction's current. A change
    /// switches the bridge off first (the caller enables it again): moving the comparator's
    /// threshold across the signal trips the break on the way, which is then cleared.
    pub fn set_direction(&mut self, direction: Direction, trip: &mut OvercurrentTrip) {
        if direction == self.direction {
            return;
        }
        self.stop();
        pac::TIM1.dier().modify(|w| w.set_bie(false));
        match direction {
            Direction::Forward => self.direction_pin.set_low(),
            Direction::Reverse => self.direction_pin.set_high(),
        }
        trip.set_direction(direction);
        self.direction = direction;
        if !self.gate.tripped() {
            self.gate.rearm(&mut self.regs);
        }
    }

    /// Drives the bridge at compare value `duty` (clamped to [`CamMotor::max_duty`]): from
    /// off, the duty is loaded before the main output goes on, and a break is checked for
    /// right before and after. Refused (false) after a hardware trip until
    /// [`CamMotor::rearm`], and for a step while the comparator is over its threshold.
    pub fn enable(&mut self, duty: u32) -> bool {
        let duty = u16::try_from(duty).map_or(PWM_FULL_DUTY, |d| d.min(PWM_FULL_DUTY));
        self.gate.enable(&mut self.regs, duty) == EnableResult::Driving
    }

    /// The safe state: bridge disabled, main output off, 0 % duty (vibration off).
    pub fn stop(&mut self) {
        self.gate.stop(&mut self.regs);
    }

    /// Reads TIM1's break flag and the break interrupt's latch (call once per control step):
    /// true while a trip is latched. The bridge is then held off.
    pub fn poll_break(&mut self) -> bool {
        self.gate.poll(&mut self.regs)
    }

    /// Clears the trip once the current is back under the threshold: call when the core no
    /// longer drives and has latched a fault for the trip. Returns whether the bridge may be
    /// enabled again.
    pub fn rearm(&mut self) -> bool {
        self.gate.rearm(&mut self.regs)
    }
}

/// Makes TIM1's update event the ADC trigger, every [`PWM_REPETITION`]` + 1` over/underflows,
/// with the repetition counter loaded before the counter starts (so the updates fall on the
/// overflow), then reports where they fall.
fn start_synchronous_trigger() -> SamplingPoint {
    let t = pac::TIM1;
    t.cr1().modify(|w| w.set_cen(false));
    t.cr2().modify(|w| w.set_mms(Mms::UPDATE));
    t.rcr().write(|w| w.set_rep(PWM_REPETITION));
    t.cnt().write(|w| w.set_cnt(0));
    // Loads the repetition counter (ADC1 is not converting yet, so this trigger is lost).
    t.egr().write(|w| w.set_ug(true));
    clear_tim1_flags(|w| w.set_uif(false));
    t.cr1().modify(|w| w.set_cen(true));
    // Right after an update the counter turns: counting down means it was at the top.
    for _ in 0..100_000 {
        if t.sr().read().uif() {
            let point = match t.cr1().read().dir() {
                Dir::DOWN => SamplingPoint::OffTimeCentre,
                Dir::UP => SamplingPoint::OnTimeCentre,
            };
            clear_tim1_flags(|w| w.set_uif(false));
            return point;
        }
    }
    SamplingPoint::Unknown
}

/// The cam shaft's AMT102-V incremental encoder on TIM4 in encoder mode 3 (x4).
pub struct CamEncoder {
    qei: Qei<'static, TIM4>,
}

impl CamEncoder {
    /// Starts TIM4 counting both edges of A and B over the full 16-bit range, through the
    /// input filter [`ENCODER_FILTER`].
    pub fn new(tim: Peri<'static, TIM4>, a: Peri<'static, PB6>, b: Peri<'static, PB7>) -> Self {
        let config = qei::Config {
            // The AMT102-V has push-pull outputs.
            ch1_pull: Pull::None,
            ch2_pull: Pull::None,
            mode: qei::QeiMode::Mode3,
            auto_reload: u16::MAX,
        };
        let qei = Qei::new(tim, a, b, config);
        pac::TIM4.ccmr_input(0).modify(|w| {
            w.set_icf(0, ENCODER_FILTER);
            w.set_icf(1, ENCODER_FILTER);
        });
        Self { qei }
    }

    /// Raw count; it wraps at 2^16, so take differences with `wrapping_sub` as `i16`.
    pub fn count(&self) -> u16 {
        self.qei.count()
    }
}

/// The optional output-shaft encoder (see (⁸)) on TIM3 in encoder mode 3 (x4).
pub struct OutputEncoder {
    qei: Qei<'static, TIM3>,
}

impl OutputEncoder {
    /// Starts TIM3 counting both edges of A and B over the full 16-bit range, through the
    /// input filter [`ENCODER_FILTER`]. No internal pulls: the encoder drives 5 V into the
    /// pins, and a pull-up to 3.3 V on a pin driven above VDD is outside the FT pin's rules
    /// (AN4899); an unplugged encoder is kept still by the board's external pull-ups (⁸).
    pub fn new(tim: Peri<'static, TIM3>, a: Peri<'static, PC6>, b: Peri<'static, PC7>) -> Self {
        let config = qei::Config {
            ch1_pull: Pull::None,
            ch2_pull: Pull::None,
            mode: qei::QeiMode::Mode3,
            auto_reload: u16::MAX,
        };
        let qei = Qei::new(tim, a, b, config);
        pac::TIM3.ccmr_input(0).modify(|w| {
            w.set_icf(0, ENCODER_FILTER);
            w.set_icf(1, ENCODER_FILTER);
        });
        Self { qei }
    }

    /// Raw count, wrapping at 2^16 (the core takes the differences).
    pub fn count(&self) -> u16 {
        self.qei.count()
    }
}

/// The ADC DMA lapped the reader: at least one block of samples was lost.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct SampleOverrun;

/// ADC1 scanning the current, bus voltage, NTC and VREFINT on every TIM1 trigger
/// ([`crate::analog`] has the order), streamed by DMA into a ring buffer.
pub struct AnalogSense {
    adc: RingBufferedAdc<'static, ADC1>,
    vrefint_cal: u16,
}

impl AnalogSense {
    /// Calibrates ADC1 and sets up the scan with TIM1_TRGO as its trigger. Conversions begin
    /// with the first [`AnalogSense::read_block`].
    pub fn new(
        adc: Peri<'static, ADC1>,
        current: Peri<'static, PA0>,
        bus: Peri<'static, PA1>,
        ntc: Peri<'static, PB0>,
        dma: Peri<'static, DMA1_CH1>,
        dma_buf: &'static mut [u16],
    ) -> Self {
        let adc = Adc::new(adc, AdcConfig::default());
        let vrefint = adc.enable_vrefint();
        let vrefint_cal = vrefint.calibrated_value();
        // 92.5 cycles = 2.2 µs at 42.5 MHz: settles the current divider's few-kΩ source to
        // 12 bits; the bus and NTC pins have 100 nF behind them. VREFINT needs ≥ 4 µs.
        let sequence = [
            (current.degrade_adc(), SampleTime::CYCLES92_5),
            (bus.degrade_adc(), SampleTime::CYCLES92_5),
            (ntc.degrade_adc(), SampleTime::CYCLES92_5),
            (vrefint.degrade_adc(), SampleTime::CYCLES247_5),
        ];
        let adc = adc.into_ring_buffered(
            dma,
            dma_buf,
            Irqs,
            sequence.into_iter(),
            triggers::TIM1_TRGO,
            Exten::RISING_EDGE,
        );
        Self { adc, vrefint_cal }
    }

    /// The chip's VREFINT factory calibration (VREFINT at VDDA = 3.0 V).
    pub fn vrefint_cal(&self) -> u16 {
        self.vrefint_cal
    }

    /// Waits for the next control step's scans ([`analog::BLOCK_LEN`] values, interleaved,
    /// oldest first). After an overrun the ring restarts; the caller decides whether that is
    /// a fault.
    pub async fn read_block(
        &mut self,
        block: &mut [u16; analog::BLOCK_LEN],
    ) -> Result<(), SampleOverrun> {
        self.adc
            .read(block)
            .await
            .map(|_| ())
            .map_err(|_| SampleOverrun)
    }
}

/// The host link: USART2 on the ST-LINK virtual COM port, DMA both ways.
pub struct HostLink {
    /// Frames to the host.
    pub tx: UartTx<'static, Async>,
    /// Bytes from the host, received continuously into a DMA ring.
    pub rx: RingBufferedUartRx<'static>,
}

impl HostLink {
    /// Opens USART2 at [`HOST_BAUD_RATE`], 8N1.
    pub fn new(
        uart: Peri<'static, USART2>,
        tx_pin: Peri<'static, PA2>,
        rx_pin: Peri<'static, PA3>,
        tx_dma: Peri<'static, DMA1_CH2>,
        rx_dma: Peri<'static, DMA1_CH3>,
        rx_buf: &'static mut [u8],
    ) -> Self {
        let mut config = usart::Config::default();
        config.baudrate = HOST_BAUD_RATE;
        let uart = defmt::unwrap!(Uart::new(
            uart, rx_pin, tx_pin, tx_dma, rx_dma, Irqs, config
        ));
        let (tx, rx) = uart.split();
        Self {
            tx,
            rx: rx.into_ring_buffered(rx_buf),
        }
    }
}

/// The physical release input: user button B1, held = release requested.
pub struct ReleaseButton {
    input: ExtiInput<'static, Async>,
}

impl ReleaseButton {
    /// B1 pulls PC13 high when pressed; the pull-down keeps a missing button reading released.
    pub fn new(pin: Peri<'static, PC13>, exti: Peri<'static, EXTI13>) -> Self {
        Self {
            input: ExtiInput::new(pin, exti, Pull::Down, Irqs),
        }
    }

    /// Whether the button is held right now.
    pub fn is_held(&self) -> bool {
        self.input.is_high()
    }
}

/// The STORAGE region of `memory.x` (last 16 KiB of bank 2) as a flash of its own; the
/// store's ECC hook ([`crate::safety::take_flash_ecc_error`]) reports double-ECC reads.
pub type CalibrationFlash = firmware_core::storage::Partition<Flash<'static, Blocking>>;

/// Wraps the whole-chip flash driver into the STORAGE window. Erasing its 2 KiB pages in
/// bank 2 does not stall code running from bank 1 (dual-bank read-while-write).
fn calibration_flash(flash: Flash<'static, Blocking>) -> CalibrationFlash {
    let (start, end) = crate::safety::storage_region();
    firmware_core::storage::Partition::new(flash, start - FLASH_BASE as u32, end - start)
}

/// Every driver of the rig, in its safe state.
pub struct Board {
    /// Cam motor H-bridge (disabled).
    pub motor: CamMotor,
    /// Hardware overcurrent trip (armed).
    pub trip: OvercurrentTrip,
    /// Cam shaft encoder.
    pub encoder: CamEncoder,
    /// Output shaft encoder (read only when [`OUTPUT_ENCODER`] is set).
    pub output_encoder: OutputEncoder,
    /// Motor current, bus voltage, motor NTC and VDDA samples.
    pub sense: AnalogSense,
    /// Host link over the ST-LINK virtual COM port.
    pub host_link: HostLink,
    /// Physical release input.
    pub release_button: ReleaseButton,
    /// Heartbeat LED LD2 (off).
    pub led: Output<'static>,
    /// Independent watchdog, configured but not yet started.
    pub watchdog: IndependentWatchdog<'static, IWDG>,
    /// Control-loop deadline (window watchdog), not yet started.
    pub stall: StallWatchdog,
    /// The calibration store's window of the internal flash.
    pub storage: CalibrationFlash,
}

impl Board {
    /// Builds every driver from the pin map above, the trip at `trip_limit_a`. Call once,
    /// right after `embassy_stm32::init`.
    pub fn new(p: Peripherals, trip_limit_a: f32) -> Self {
        // Motor first: it takes the bridge pins from floating to driven-off as early as possible.
        let mut motor = CamMotor::new(p.TIM1, p.PA8, p.PB5, p.PA9);

        let adc_buf = defmt::unwrap!(cortex_m::singleton!(: [u16; ADC_DMA_LEN] = [0; ADC_DMA_LEN]));
        let host_rx_buf =
            defmt::unwrap!(cortex_m::singleton!(: [u8; HOST_RX_DMA_LEN] = [0; HOST_RX_DMA_LEN]));

        // ADC1 makes PA0 analog, which COMP3 shares.
        let sense = AnalogSense::new(p.ADC1, p.PA0, p.PA1, p.PB0, p.DMA1_CH1, adc_buf);
        let trip = OvercurrentTrip::new(
            p.COMP3,
            p.DAC3,
            trip_limit_a,
            analog::nominal_zero_counts(model::hardware::adc::VREF_V as f32),
        );
        motor.arm_break();

        Self {
            motor,
            trip,
            encoder: CamEncoder::new(p.TIM4, p.PB6, p.PB7),
            output_encoder: OutputEncoder::new(p.TIM3, p.PC6, p.PC7),
            sense,
            host_link: HostLink::new(p.USART2, p.PA2, p.PA3, p.DMA1_CH2, p.DMA1_CH3, host_rx_buf),
            release_button: ReleaseButton::new(p.PC13, p.EXTI13),
            led: Output::new(p.PA5, Level::Low, Speed::Low),
            watchdog: IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US),
            stall: StallWatchdog::new(p.WWDG),
            storage: calibration_flash(Flash::new_blocking(p.FLASH)),
        }
    }
}
