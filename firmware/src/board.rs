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
//! | Cam motor PWM           | PA8  | D7           | TIM1_CH1 (AF6), 20 kHz | H-bridge PWM input; 10 kΩ pull-down on the driver |
//! | Cam motor direction     | PB5  | D4           | GPIO out               | low = [`Direction::Forward`]                     |
//! | Cam motor enable        | PA9  | D8           | GPIO out               | low = off; 10 kΩ pull-down on the driver (¹)     |
//! | Encoder A (AMT102-V)    | PB6  | D10          | TIM4_CH1 (AF2)         | quadrature, x4 decoding (²)                      |
//! | Encoder B (AMT102-V)    | PB7  | CN7-21       | TIM4_CH2 (AF2)         | (²)                                              |
//! | Motor current (ACS714)  | PA0  | A0           | ADC1_IN1               | through a divider to ≤ 3.3 V (³)                 |
//! | Host link TX            | PA2  | ST-LINK VCP  | USART2_TX (AF7)        | 921 600 baud 8N1                                 |
//! | Host link RX            | PA3  | ST-LINK VCP  | USART2_RX (AF7)        |                                                  |
//! | Release button B1       | PC13 | B1           | EXTI13                 | active high (held = release requested)           |
//! | Heartbeat LED LD2       | PA5  | LD2 / D13    | GPIO out               | active high                                      |
//! | SWD                     | PA13, PA14 | ST-LINK | SWDIO, SWCLK          | keep free: flashing and defmt-rtt                |
//!
//! Internal resources: TIM6 paces the ADC at 10 kHz (TRGO = update, ADC1 EXTSEL 13);
//! TIM15 is embassy's time driver (`time-driver-any` picks it on the G474);
//! DMA1_CH1 = ADC1, DMA1_CH2 = USART2 TX, DMA1_CH3 = USART2 RX (through DMAMUX);
//! IWDG ≈ 250 ms. Flash 0x0807_C000..0x0808_0000 (bank 2) holds the calibration store (`memory.x`).
//! UART4's interrupt vector (the UART itself is unused) runs the control task's
//! high-priority executor.
//!
//! (¹) From reset until [`Board::new`] runs every GPIO is a high-impedance analog input, so only
//! the external pull-downs keep the bridge off while the MCU resets or is being flashed.
//! PB4 (D5) was avoided for the enable: as JTAG NJTRST it has an internal pull-up at reset.
//! (²) The AMT102-V runs from 5 V, so its A/B outputs need 5 V-tolerant (FT) inputs or a level
//! shifter. TIM4 on PB6/PB7 was preferred to TIM3 on PA6/PA7 because PA6 doubles as DAC2_OUT1,
//! which is not 5 V tolerant; confirm FT for PB6/PB7 in the DS12288 pin table before wiring.
//! (³) The ACS714 output swings 0.5–4.5 V on a 5 V supply; analog inputs are never 5 V tolerant,
//! e.g. 10 kΩ over 20 kΩ scales it to 0.33–3.0 V. The core owns the counts-to-amperes calibration.

use embassy_stm32::adc::{Adc, AdcChannel as _, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{Blocking, FLASH_BASE, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::mode::Async;
use embassy_stm32::pac::timer::vals::Ossi;
use embassy_stm32::peripherals::{
    ADC1, DMA1_CH1, DMA1_CH2, DMA1_CH3, EXTI13, IWDG, PA0, PA2, PA3, PA8, PA9, PB5, PB6, PB7, PC13,
    TIM1, TIM4, TIM6, USART2,
};
use embassy_stm32::time::{Hertz, khz};
use embassy_stm32::timer::low_level::{CountingMode, MasterMode, RoundTo, Timer as HwTimer};
use embassy_stm32::timer::qei::{self, Qei};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Config, Peri, Peripherals, bind_interrupts, dma, interrupt, pac, triggers};

bind_interrupts!(struct Irqs {
    USART2 => usart::InterruptHandler<USART2>;
    DMA1_CHANNEL1 => dma::InterruptHandler<DMA1_CH1>;
    DMA1_CHANNEL2 => dma::InterruptHandler<DMA1_CH2>;
    DMA1_CHANNEL3 => dma::InterruptHandler<DMA1_CH3>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// PWM carrier frequency of the cam motor's H-bridge: above hearing, within the driver's limit.
pub const MOTOR_PWM_FREQUENCY: Hertz = khz(20);
/// Rate at which TIM6 triggers the motor-current conversions.
pub const CURRENT_SAMPLE_RATE: Hertz = khz(10);
/// Samples per [`CurrentSense::read_block`]: 1 ms of current at [`CURRENT_SAMPLE_RATE`].
pub const CURRENT_BLOCK_LEN: usize = 10;
/// ADC DMA ring: two blocks, so one is read while the DMA fills the other.
const CURRENT_DMA_LEN: usize = 2 * CURRENT_BLOCK_LEN;
/// Baud rate of the host link over the ST-LINK virtual COM port.
pub const HOST_BAUD_RATE: u32 = 921_600;
/// UART receive DMA ring: ~5.5 ms of back-to-back bytes at [`HOST_BAUD_RATE`].
const HOST_RX_DMA_LEN: usize = 512;
/// Independent-watchdog timeout. LSI is 32 kHz ± ~7 %, so the real timeout is ~235–270 ms.
pub const WATCHDOG_TIMEOUT_US: u32 = 250_000;

/// Clock tree: 170 MHz SYSCLK from HSI16 (16 MHz / 4 × 85 / 2), range-1 boost, ADC12 on SYSCLK.
///
/// HSI16 (±1 %) is well inside the UART's clock tolerance and needs nothing on the board; the
/// Nucleo's 24 MHz HSE crystal would be `source: HSE, prediv: DIV6` with the same PLL.
pub fn config() -> Config {
    use embassy_stm32::rcc::{Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk, mux};

    let mut config = Config::default();
    config.rcc.hsi = true;
    config.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4,
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
    /// Software reset (e.g. a probe's `reset` or `SYSRESETREQ`).
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
            software: csr.sftrstf(),
            pin: csr.pinrstf(),
            brown_out: csr.borrstf(),
        }
    }
}

/// Sense of rotation of the cam motor, as driven on the direction pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum Direction {
    /// Direction pin low.
    Forward,
    /// Direction pin high.
    Reverse,
}

/// The cam motor's H-bridge: PWM magnitude, direction and enable.
///
/// Built in the safe state (enable low, 0 % duty) and returns to it on [`CamMotor::stop`].
pub struct CamMotor {
    pwm: SimplePwm<'static, TIM1>,
    direction: Output<'static>,
    enable: Output<'static>,
}

impl CamMotor {
    /// Sets up TIM1 CH1 at [`MOTOR_PWM_FREQUENCY`] with the bridge disabled.
    pub fn new(
        tim: Peri<'static, TIM1>,
        pwm_pin: Peri<'static, PA8>,
        direction_pin: Peri<'static, PB5>,
        enable_pin: Peri<'static, PA9>,
    ) -> Self {
        // Enable first, so the bridge is held off before the PWM pin becomes an output.
        let enable = Output::new(enable_pin, Level::Low, Speed::Low);
        let direction = Output::new(direction_pin, Level::Low, Speed::Low);
        let pwm = SimplePwm::new(
            tim,
            Some(PwmPin::new(pwm_pin, OutputType::PushPull)),
            None,
            None,
            None,
            MOTOR_PWM_FREQUENCY,
            CountingMode::EdgeAlignedUp,
        );
        // Whenever TIM1's outputs are switched off (MOE cleared, break), hold PWM at its idle
        // level (low) instead of releasing the pin.
        pac::TIM1.bdtr().modify(|w| w.set_ossi(Ossi::IDLE_LEVEL));
        // A debugger halt stops TIM1, which then switches its outputs off as above. The IWDG is
        // deliberately not frozen: a halt longer than ~250 ms resets the board.
        pac::DBGMCU.apb2fzr().modify(|w| w.set_tim1(true));
        let mut motor = Self {
            pwm,
            direction,
            enable,
        };
        motor.stop();
        motor.pwm.ch1().enable();
        motor
    }

    /// Compare value for 100 % duty (8500 at 170 MHz / 20 kHz).
    pub fn max_duty(&self) -> u32 {
        self.pwm.max_duty_cycle()
    }

    /// Sets the PWM compare value, clamped to [`CamMotor::max_duty`].
    pub fn set_duty(&mut self, duty: u32) {
        let duty = duty.min(self.max_duty());
        self.pwm.ch1().set_duty_cycle(duty);
    }

    /// Sets the direction pin.
    pub fn set_direction(&mut self, direction: Direction) {
        match direction {
            Direction::Forward => self.direction.set_low(),
            Direction::Reverse => self.direction.set_high(),
        }
    }

    /// Enables the bridge: the motor then follows the duty and direction.
    pub fn enable(&mut self) {
        self.enable.set_high();
    }

    /// The safe state: bridge disabled and 0 % duty (vibration off).
    pub fn stop(&mut self) {
        self.enable.set_low();
        self.pwm.ch1().set_duty_cycle_fully_off();
    }
}

/// The cam shaft's AMT102-V incremental encoder on TIM4 in encoder mode 3 (x4).
pub struct CamEncoder {
    qei: Qei<'static, TIM4>,
}

impl CamEncoder {
    /// Starts TIM4 counting both edges of A and B over the full 16-bit range.
    pub fn new(tim: Peri<'static, TIM4>, a: Peri<'static, PB6>, b: Peri<'static, PB7>) -> Self {
        let config = qei::Config {
            // The AMT102-V has push-pull outputs.
            ch1_pull: Pull::None,
            ch2_pull: Pull::None,
            mode: qei::QeiMode::Mode3,
            auto_reload: u16::MAX,
        };
        Self {
            qei: Qei::new(tim, a, b, config),
        }
    }

    /// Raw count; it wraps at 2^16, so take differences with `wrapping_sub` as `i16`.
    pub fn count(&self) -> u16 {
        self.qei.count()
    }
}

/// The ADC DMA lapped the reader: at least one block of current samples was lost.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct SampleOverrun;

/// Motor current from the ACS714: ADC1 triggered by TIM6 at [`CURRENT_SAMPLE_RATE`],
/// streamed by DMA into a ring buffer.
pub struct CurrentSense {
    adc: RingBufferedAdc<'static, ADC1>,
    // Kept alive: dropping the low-level timer would gate its clock and stop the triggers.
    _trigger: HwTimer<'static, TIM6>,
}

impl CurrentSense {
    /// Calibrates ADC1, points it at PA0 with TIM6_TRGO as the regular trigger and starts TIM6.
    /// Conversions begin with the first [`CurrentSense::read_block`].
    pub fn new(
        adc: Peri<'static, ADC1>,
        pin: Peri<'static, PA0>,
        dma: Peri<'static, DMA1_CH1>,
        trigger: Peri<'static, TIM6>,
        dma_buf: &'static mut [u16],
    ) -> Self {
        let adc = Adc::new(adc, AdcConfig::default());
        // 92.5 cycles = 2.2 µs at 42.5 MHz: settles the divider's few-kΩ source to 12 bits.
        let sequence = [(pin.degrade_adc(), SampleTime::CYCLES92_5)];
        let adc = adc.into_ring_buffered(
            dma,
            dma_buf,
            Irqs,
            sequence.into_iter(),
            triggers::TIM6_TRGO,
            Exten::RISING_EDGE,
        );

        let trigger = HwTimer::new(trigger);
        trigger.set_frequency(CURRENT_SAMPLE_RATE, RoundTo::Slower);
        // Load the prescaler now rather than at the first overflow.
        trigger.generate_update_event();
        trigger
            .regs_basic()
            .cr2()
            .modify(|w| w.set_mms(MasterMode::UPDATE));
        trigger.start();

        Self {
            adc,
            _trigger: trigger,
        }
    }

    /// Waits for the next [`CURRENT_BLOCK_LEN`] samples (12-bit counts, oldest first).
    /// After an overrun the ring restarts; the caller decides whether that is a fault.
    pub async fn read_block(
        &mut self,
        block: &mut [u16; CURRENT_BLOCK_LEN],
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

/// The STORAGE region of `memory.x` (last 16 KiB of bank 2) as a flash of its own.
pub type CalibrationFlash = firmware_core::storage::Partition<Flash<'static, Blocking>>;

// Declaring linker symbols takes an `unsafe extern` block; only their addresses are taken
// (safe), the symbols are never read.
#[allow(unsafe_code)]
unsafe extern "C" {
    // Defined by memory.x.
    static __storage_start: u8;
    static __storage_end: u8;
}

/// Wraps the whole-chip flash driver into the STORAGE window. Erasing its 2 KiB pages in
/// bank 2 does not stall code running from bank 1 (dual-bank read-while-write).
fn calibration_flash(flash: Flash<'static, Blocking>) -> CalibrationFlash {
    let start = (&raw const __storage_start) as u32;
    let end = (&raw const __storage_end) as u32;
    firmware_core::storage::Partition::new(flash, start - FLASH_BASE as u32, end - start)
}

/// Every driver of the rig, in its safe state.
pub struct Board {
    /// Cam motor H-bridge (disabled).
    pub motor: CamMotor,
    /// Cam shaft encoder.
    pub encoder: CamEncoder,
    /// Motor current samples.
    pub current: CurrentSense,
    /// Host link over the ST-LINK virtual COM port.
    pub host_link: HostLink,
    /// Physical release input.
    pub release_button: ReleaseButton,
    /// Heartbeat LED LD2 (off).
    pub led: Output<'static>,
    /// Independent watchdog, configured but not yet started.
    pub watchdog: IndependentWatchdog<'static, IWDG>,
    /// The calibration store's window of the internal flash.
    pub storage: CalibrationFlash,
}

impl Board {
    /// Builds every driver from the pin map above. Call once, right after `embassy_stm32::init`.
    pub fn new(p: Peripherals) -> Self {
        // Motor first: it takes the bridge pins from floating to driven-off as early as possible.
        let motor = CamMotor::new(p.TIM1, p.PA8, p.PB5, p.PA9);

        let current_buf =
            defmt::unwrap!(cortex_m::singleton!(: [u16; CURRENT_DMA_LEN] = [0; CURRENT_DMA_LEN]));
        let host_rx_buf =
            defmt::unwrap!(cortex_m::singleton!(: [u8; HOST_RX_DMA_LEN] = [0; HOST_RX_DMA_LEN]));

        Self {
            motor,
            encoder: CamEncoder::new(p.TIM4, p.PB6, p.PB7),
            current: CurrentSense::new(p.ADC1, p.PA0, p.DMA1_CH1, p.TIM6, current_buf),
            host_link: HostLink::new(p.USART2, p.PA2, p.PA3, p.DMA1_CH2, p.DMA1_CH3, host_rx_buf),
            release_button: ReleaseButton::new(p.PC13, p.EXTI13),
            led: Output::new(p.PA5, Level::Low, Speed::Low),
            watchdog: IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US),
            storage: calibration_flash(Flash::new_blocking(p.FLASH)),
        }
    }
}
