//! Firmware binary of the backdrive rig (Nucleo-G474RE, STM32G474RE).
//!
//! Thin on purpose: bring up the clocks and `board` drivers in their safe state (vibration
//! off), load the calibration from flash, then run tasks that only move data between the
//! peripherals and the control core (`firmware_core::Core`):
//!
//! | task            | executor                 | does                                                    |
//! |-----------------|--------------------------|---------------------------------------------------------|
//! | `control`       | interrupt (UART4, P6)    | 1 kHz, paced by the ADC DMA (itself triggered by the PWM timer): samples, encoder, button, break flag -> `Core::step` -> H-bridge; feeds the 2 ms stall watchdog; counts cycles |
//! | `host_rx`       | thread                   | UART bytes -> `Core::receive`                            |
//! | `host_tx`       | thread                   | `Core::transmit` -> UART                                 |
//! | `persist`       | thread                   | writes a calibration to flash, reports the outcome       |
//! | `monitor`       | thread                   | LD2: 1 Hz blink locked, on while vibrating, 5 Hz on a fault; logs state changes and, every 10 s, the board's health |
//! | `watchdog_feeder` | thread                 | feeds the IWDG only when control, host_rx and host_tx all checked in |
//!
//! The control task runs on a higher-priority interrupt executor so that a flash erase
//! (blocking, ~20 ms, in thread mode) or a long UART write never delays a control step.
//! The core is shared through a priority-ceiling mutex (BASEPRI at the control executor's
//! priority, `safety::CeilingMutex`); each access is one short call, and the trip's and
//! the WWDG's interrupts, above the ceiling, never wait for it.
//!
//! Failures end in the safe state (vibration off) by direct register writes, then a reset:
//! see `safety` (panic, HardFault, NMI, unhandled interrupts, a stalled control loop) and
//! `trip` (overcurrent, in hardware). defmt-rtt is built with `disable-blocking-mode`: a log
//! line never waits for a probe, attached, dead or absent, and nothing here calls
//! `defmt::flush`.
//!
//! On the host this builds as a stub that says how to build and flash, so that
//! `cargo build --workspace` and `cargo test --workspace` work without the thumb target.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Firmware version, reported at boot (and to the host in `Info`).
const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The firmware's build identifier, the one constant for it: the git commit it was built
/// from (short hash, `-dirty` when the work tree had uncommitted changes), the value of
/// `RIG_FIRMWARE_BUILD` at build time when set, or `unknown`; computed by `build.rs` (at
/// most 20 bytes, what `Info` carries). Logged at boot, reported in `Info` and part of
/// [`IDENTITY`].
const BUILD: &str = env!("RIG_FIRMWARE_BUILD");

/// [`IDENTITY`]'s parts.
const IDENTITY_PARTS: [&str; 4] = ["rig firmware ", VERSION, " build ", BUILD];
/// [`IDENTITY`]'s length, bytes.
const IDENTITY_LEN: usize = {
    let mut len = 0;
    let mut i = 0;
    while i < IDENTITY_PARTS.len() {
        len += IDENTITY_PARTS[i].len();
        i += 1;
    }
    len
};

/// [`IDENTITY`] as a NUL-terminated array (a `const fn`: fixed at compile time).
const fn identity_bytes() -> [u8; IDENTITY_LEN + 1] {
    let mut out = [0u8; IDENTITY_LEN + 1];
    let mut at = 0;
    let mut part = 0;
    while part < IDENTITY_PARTS.len() {
        let bytes = IDENTITY_PARTS[part].as_bytes();
        let mut i = 0;
        while i < bytes.len() {
            out[at] = bytes[i];
            at += 1;
            i += 1;
        }
        part += 1;
    }
    out
}

/// [`identity_bytes`], computed once.
const IDENTITY_BYTES: [u8; IDENTITY_LEN + 1] = identity_bytes();

/// Version and build as one record, `rig firmware <version> build <build>` (the image
/// carries it as [`IDENTITY_BYTES`]; the host stub prints it).
#[cfg_attr(target_os = "none", allow(dead_code))]
const IDENTITY: &str = match core::str::from_utf8(IDENTITY_BYTES.split_at(IDENTITY_LEN).0) {
    Ok(text) => text,
    Err(_) => panic!("the identity is made of UTF-8 strings"),
};

/// [`IDENTITY`] in the image under a fixed symbol: `rig flash` reads it from the ELF (and
/// `rig log` from the running chip) to tell which firmware a file or a board holds.
#[cfg(target_os = "none")]
#[used]
#[allow(unsafe_code)] // `no_mangle`: a fixed name for the host to look up; nothing else uses it.
#[unsafe(no_mangle)]
static RIG_FIRMWARE_ID: [u8; IDENTITY_LEN + 1] = IDENTITY_BYTES;

/// Device seconds per wall-clock second, as `Info` reports it (`time_scale`): 1.0 on
/// silicon. The emulated board (`rig sim serve --firmware`, crate `emu`) runs slower than
/// real time and writes its pace into this flash word before boot, so clients scale their
/// heartbeats by it; read volatile so the value is taken from the image, not folded in.
#[cfg(target_os = "none")]
#[used]
#[allow(unsafe_code)] // `no_mangle`: a fixed name for the emulator to look up.
#[unsafe(no_mangle)]
static RIG_TIME_SCALE: f32 = 1.0;

/// [`RIG_TIME_SCALE`] as the image holds it (1.0 unless an emulator set its pace).
#[cfg(target_os = "none")]
pub fn time_scale() -> f32 {
    // SAFETY: a plain read of an aligned, initialised static (never written by code).
    #[allow(unsafe_code)]
    let scale = unsafe { core::ptr::read_volatile(&raw const RIG_TIME_SCALE) };
    if scale.is_finite() && scale > 0.0 {
        scale
    } else {
        1.0
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "rig firmware {VERSION} runs on the Nucleo-G474RE (STM32G474RE); this host build is a stub.\n\
         build:  cargo fw-build   (cargo build -p firmware --release --target thumbv7em-none-eabihf)\n\
         flash:  rig flash        (builds it, checks the image and flashes through the probe)\n\
         logs:   rig log          (the defmt log over the probe)\n\
         target: rustup target add thumbv7em-none-eabihf\n\
         identity: {IDENTITY}"
    );
}

/// The TIM1 compare value for the core's duty `duty` (sign: direction, magnitude up to 1)
/// at `full_scale` counts; `None` for a non-finite duty, which the bridge refuses (off):
/// `f32::NAN.min(1.0)` is 1.0, full drive.
#[cfg(any(target_os = "none", test))]
fn duty_compare(duty: f32, full_scale: f32) -> Option<u32> {
    if !duty.is_finite() || !full_scale.is_finite() || full_scale < 0.0 {
        return None;
    }
    // In [0, full_scale] by the clamp: the cast cannot truncate beyond the range.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    Some((duty.abs().min(1.0) * full_scale) as u32)
}

/// The host link's baud rate at boot, Bd (USART2 at 921,600 8N1 on the ST-LINK's VCP;
/// `SetBaud` may switch it to `protocol::FAST_BAUD_RATE`, `set_host_baud`).
#[cfg(any(target_os = "none", test))]
const HOST_BAUD: u32 = 921_600;

/// USART2's kernel clock, Hz: PCLK1 = SYSCLK, 170 MHz from the HSE crystal.
#[cfg(any(target_os = "none", test))]
const USART_KERNEL_HZ: u32 = 170_000_000;

/// USART2's BRR for `baud` at `kernel_hz` as embassy-stm32 rounds it (16x oversampling)
/// and the baud rate that gives, Bd.
#[cfg(any(target_os = "none", test))]
const fn usart_baud(kernel_hz: u32, baud: u32) -> (u32, u32) {
    let brr = (kernel_hz + baud / 2) / baud;
    (brr, (kernel_hz + brr / 2) / brr)
}

/// The host link's baud error from the divider alone, ppm (the crystal adds tens of ppm;
/// HSI16 would have added up to ±10,000): +2,509 ppm, BRR 184, 923,913 Bd.
#[cfg(any(target_os = "none", test))]
const HOST_BAUD_ERROR_PPM: i32 = {
    let (_, actual) = usart_baud(USART_KERNEL_HZ, HOST_BAUD);
    // Both below 2^31: the difference times 1e6 fits i64.
    ((actual as i64 - HOST_BAUD as i64) * 1_000_000 / HOST_BAUD as i64) as i32
};

#[cfg(any(target_os = "none", test))]
mod analog;
#[cfg(target_os = "none")]
mod board;
#[cfg(target_os = "none")]
#[allow(unsafe_code)] // fault handlers and the safe state write registers directly
mod safety;
#[cfg(any(target_os = "none", test))]
mod stack_guard;
#[cfg(target_os = "none")]
mod trip;

#[cfg(target_os = "none")]
mod app {
    use core::cell::{Cell, RefCell};
    use core::mem::MaybeUninit;
    use core::sync::atomic::{AtomicU8, Ordering};

    use cortex_m::peripheral::DWT;
    use defmt::{error, info, unwrap, warn};
    use defmt_rtt as _;
    use embassy_executor::{InterruptExecutor, SpawnError, SpawnToken, Spawner};
    use embassy_futures::select::{Either, select};
    use embassy_stm32::gpio::Output;
    use embassy_stm32::interrupt;
    use embassy_stm32::interrupt::InterruptExt;
    use embassy_stm32::mode::Async;
    use embassy_stm32::peripherals::IWDG;
    use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use firmware_core::storage::{CalibrationStore, StorageError};
    use firmware_core::{BoardInputs, BootInfo, Core, Inputs, Outputs};
    use protocol::{ParametersStatus, ResetCause, RigParameters, SupervisorState};

    use crate::analog;
    use crate::board::{
        self, AnalogSense, CalibrationFlash, CamEncoder, CamMotor, Direction, SamplingPoint,
    };
    use crate::safety::{self, CrashCause, StallWatchdog};
    use crate::trip::OvercurrentTrip;

    /// The control core, shared by the tasks, behind the priority ceiling's lock
    /// (`safety::CeilingMutex`: BASEPRI, so the trip and the WWDG's early wakeup never wait).
    type SharedCore = Mutex<safety::CeilingMutex, RefCell<&'static mut Core>>;

    /// Watchdog check-in bits: each task sets its own; the feeder needs all of them.
    const CONTROL: u8 = 1 << 0;
    const HOST_RX: u8 = 1 << 1;
    const HOST_TX: u8 = 1 << 2;
    const ALL_TASKS: u8 = CONTROL | HOST_RX | HOST_TX;
    static CHECK_INS: AtomicU8 = AtomicU8::new(0);

    /// Watchdog feed period: well inside the ~250 ms IWDG timeout.
    const WATCHDOG_FEED_PERIOD: Duration = Duration::from_millis(100);

    /// A calibration the core wants written to flash.
    static PERSIST: Signal<CriticalSectionRawMutex, RigParameters> = Signal::new();

    // `Info` carries the build in a fixed field: `build.rs` keeps it within.
    const _: () = assert!(crate::BUILD.len() <= protocol::FIRMWARE_BUILD_LEN);

    /// The reset flags as the protocol names the cause. The G4 sets BORRSTF at power-on
    /// as well as after a brown-out, and every internal reset also pulls NRST, so the
    /// flags are read from the most specific down.
    fn reset_cause(reset: &board::ResetCause) -> ResetCause {
        if reset.watchdog {
            ResetCause::Watchdog
        } else if reset.software {
            ResetCause::Software
        } else if reset.brown_out {
            ResetCause::PowerOn
        } else if reset.pin {
            ResetCause::Pin
        } else {
            ResetCause::Other
        }
    }

    /// Control steps per health snapshot: one second.
    const HEALTH_STEPS: u32 = 1000;

    /// What the board measures besides the core's inputs, once a second.
    #[derive(Clone, Copy, Debug, Default, defmt::Format)]
    struct Health {
        /// VDDA from VREFINT, V (0 when implausible).
        vdda_v: f32,
        /// Bridge supply, V.
        bus_v: f32,
        /// Motor temperature, deg C, when an NTC is fitted.
        motor_temp_c: Option<f32>,
        /// Mean cycles of a control step (DWT CYCCNT, from the data to the bridge command).
        step_cycles_mean: u32,
        /// Largest cycles of a control step.
        step_cycles_max: u32,
        /// Hardware overcurrent trips since boot.
        hw_trips: u32,
    }

    static HEALTH: Mutex<CriticalSectionRawMutex, Cell<Health>> = Mutex::new(Cell::new(Health {
        vdda_v: 0.0,
        bus_v: 0.0,
        motor_temp_c: None,
        step_cycles_mean: 0,
        step_cycles_max: 0,
        hw_trips: 0,
    }));

    /// Runs the control task above the thread-mode tasks.
    static CONTROL_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

    #[interrupt]
    #[allow(unsafe_code, non_snake_case)]
    unsafe fn UART4() {
        // SAFETY: UART4's vector is dedicated to this executor (the UART itself is unused).
        unsafe { CONTROL_EXECUTOR.on_interrupt() }
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        // The stack guard and the lockup-to-break link first: every later fault ends in
        // the safe state.
        safety::arm_last_resort();
        // Before anything else can reset or clear them.
        let reset = board::ResetCause::take();
        let crash = safety::take_crash();
        let p = embassy_stm32::init(board::config());
        // The init pulsed SYSCFG's reset, which cleared CLL: set again, read back, logged.
        let lockup_break = safety::arm_lockup_break();
        let config = board::core_config();
        let trip_limit_a = config.faults.overcurrent_a * board::HW_TRIP_MARGIN;
        let board::Board {
            motor,
            trip,
            encoder,
            output_encoder,
            sense,
            host_link,
            release_button,
            led,
            watchdog,
            stall,
            storage,
        } = board::Board::new(p, trip_limit_a);

        let mut cp = unwrap!(cortex_m::Peripherals::take());
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();

        // Keeps the identity record in the image for the host (the linker would drop it).
        core::hint::black_box(&crate::RIG_FIRMWARE_ID);
        info!(
            "rig firmware {=str} build {=str} booted; last reset by the watchdog: {}",
            crate::VERSION,
            crate::BUILD,
            reset.watchdog
        );
        if reset.watchdog {
            warn!("the previous run stalled long enough for the IWDG to reset it");
        }
        info!("reset flags: {}", reset);
        if let Some(crash) = crash {
            error!("the previous run ended in the safe state: {}", crash);
        }
        if lockup_break {
            info!("SYSCFG_CFGR2.CLL set after init: a lockup breaks TIM1");
        } else {
            error!("SYSCFG_CFGR2.CLL reads clear after init: a lockup leaves TIM1 switching");
        }
        let stalled =
            reset.window_watchdog || crash.is_some_and(|c| c.cause == CrashCause::ControlStall);

        // A read that raised a double-ECC NMI in the store counts as a corrupt slot.
        let mut store = CalibrationStore::with_ecc_check(storage, safety::take_flash_ecc_error);
        let loaded = store.load();
        match loaded.status {
            ParametersStatus::Valid => info!("calibration loaded from flash"),
            ParametersStatus::Defaults => info!("no calibration stored: the paper's values"),
            _ => error!("stored calibration is invalid: the paper's values, motor locked"),
        }
        let boot = BootInfo {
            reset_cause: if stalled {
                ResetCause::Watchdog
            } else {
                reset_cause(&reset)
            },
            firmware_build: crate::BUILD,
            parameters: loaded.calibration,
            parameters_status: loaded.status,
        };
        // The core (~43 KiB, mostly the capture buffer) is built in its static slot, never
        // on this task's stack (`core_in_place`): the boot trace of the target bench
        // measures the lowest stack pointer's margin to the guard (at least 2 KiB).
        let core_ref = core_in_place(
            unwrap!(cortex_m::singleton!(: MaybeUninit<Core> = MaybeUninit::uninit())),
            config,
            boot,
        );
        let core: &'static SharedCore =
            unwrap!(cortex_m::singleton!(: SharedCore = Mutex::new(RefCell::new(core_ref))));

        info!(
            "board up: motor off (max duty {}), {} ({} decay), encoder at {}; current sampled in step with the PWM at {} ({} Hz); overcurrent trip at {} A (DAC {}); host link @ {} Bd ({} ppm from the divider, HSE clock)",
            motor.max_duty(),
            board::BRIDGE.name,
            board::BRIDGE.decay.name(),
            encoder.count(),
            motor.sampling_point(),
            board::CURRENT_SAMPLE_RATE_HZ,
            trip.limit_a(),
            trip.threshold_counts(),
            board::HOST_BAUD_RATE,
            crate::HOST_BAUD_ERROR_PPM,
        );
        if motor.sampling_point() == SamplingPoint::Unknown {
            error!("TIM1 does not count: no current samples will come");
        }

        interrupt::UART4.set_priority(safety::CORE_CEILING);
        let control_spawner = CONTROL_EXECUTOR.start(interrupt::UART4);
        control_spawner.spawn(spawned(control(
            core,
            ControlIo {
                motor,
                trip,
                encoder,
                output_encoder,
                sense,
                button: release_button,
                stall,
            },
        )));
        spawner.spawn(spawned(host_rx(core, host_link.rx)));
        spawner.spawn(spawned(host_tx(core, host_link.tx)));
        spawner.spawn(spawned(persist(core, store)));
        spawner.spawn(spawned(monitor(core, led)));
        spawner.spawn(spawned(watchdog_feeder(watchdog)));
    }

    /// Builds the core in `slot` (`Core::new_in`: field by field, the capture buffer
    /// zero-filled in place), never in a stack temporary that `main`'s frame would have to
    /// hold (44,288 B before, 188 B above the stack guard).
    fn core_in_place(
        slot: &'static mut MaybeUninit<Core>,
        config: firmware_core::CoreConfig,
        boot: BootInfo,
    ) -> &'static mut Core {
        Core::new_in(slot, config, boot)
    }

    /// A task's spawn token. Each task has a pool of one and is spawned once, at boot, so a
    /// refusal is a bug that shows on the first boot; it ends in the panic handler's safe
    /// state through one shared path (not one `unwrap!` per task, ~30 B of flash each).
    fn spawned<S>(token: Result<SpawnToken<S>, SpawnError>) -> SpawnToken<S> {
        match token {
            Ok(token) => token,
            Err(_) => spawn_failed(),
        }
    }

    /// [`spawned`]'s failure.
    #[cold]
    #[inline(never)]
    fn spawn_failed() -> ! {
        defmt::panic!("a task could not be spawned: its pool is full")
    }

    /// The drivers the control task owns.
    struct ControlIo {
        motor: CamMotor,
        trip: OvercurrentTrip,
        encoder: CamEncoder,
        output_encoder: board::OutputEncoder,
        sense: AnalogSense,
        button: board::ReleaseButton,
        stall: StallWatchdog,
    }

    /// Cycle counts of the control steps over one health period.
    struct StepCycles {
        sum: u32,
        max: u32,
        steps: u32,
    }

    impl StepCycles {
        fn record(&mut self, cycles: u32) {
            self.sum = self.sum.wrapping_add(cycles);
            self.max = self.max.max(cycles);
            self.steps += 1;
        }

        /// (mean, max) so far, and starts over.
        fn take(&mut self) -> (u32, u32) {
            let mean = self.sum / self.steps.max(1);
            let max = self.max;
            *self = Self {
                sum: 0,
                max: 0,
                steps: 0,
            };
            (mean, max)
        }
    }

    /// The 1 kHz control loop, paced by the ADC: every block of 10 scans (triggered by TIM1,
    /// so in step with the PWM) is one step of the core, whose outputs go straight to the
    /// H-bridge.
    ///
    /// Before each step the core gets the board's other measurements (`BoardInputs`): the
    /// break flag (`motor.poll_break()`, TIM1 SR.BIF: the core latches HW_OVERCURRENT), VDDA
    /// from VREFINT (scales the current counts), the bus voltage (feed-forward, open-loop
    /// volts) and the motor NTC (Health); the step's DWT cycles go to `record_step_cycles`.
    #[embassy_executor::task]
    async fn control(core: &'static SharedCore, mut io: ControlIo) {
        let mut raw = [0u16; analog::BLOCK_LEN];
        let full_scale = io.motor.max_duty() as f32;
        let vrefint_cal = io.sense.vrefint_cal();
        let mut cycles = StepCycles {
            sum: 0,
            max: 0,
            steps: 0,
        };
        let mut health = Health::default();
        let mut zero_bits = 0u32;
        // The first block is due 1 ms after the first read starts the ADC: inside the 2 ms
        // deadline, which so also covers a PWM timer or ADC that never starts.
        io.stall.start();
        loop {
            let block = match io.sense.read_block(&mut raw).await {
                Ok(()) => Some(analog::split(&raw)),
                Err(board::SampleOverrun) => {
                    // The step comes late; the core flags CONTROL_OVERRUN from the time, and
                    // the stall watchdog has already fired unless it was barely late.
                    warn!("current samples lost (ADC DMA overrun)");
                    None
                }
            };
            let start = DWT::cycle_count();
            // The loop came round: reload the 2 ms deadline.
            io.stall.feed();

            let hw_trip = io.motor.poll_break();
            if let Some(b) = &block {
                if let Some(v) = analog::vdda_v(vrefint_cal, b.vrefint_counts) {
                    health.vdda_v = v;
                    health.bus_v = analog::bus_v(b.bus_counts, v);
                }
                health.motor_temp_c = analog::motor_temperature_c(b.ntc_counts);
            }
            let inputs = Inputs {
                now_us: Instant::now().as_micros(),
                current_adc: block.as_ref().map_or(&[], |b| &b.current[..]),
                encoder_count: io.encoder.count(),
                release_button: io.button.is_held(),
            };
            let board_inputs = BoardInputs {
                hw_break: hw_trip,
                vdda_v: if health.vdda_v > 0.0 {
                    health.vdda_v
                } else {
                    f32::NAN
                },
                bus_voltage_v: if health.vdda_v > 0.0 {
                    health.bus_v
                } else {
                    f32::NAN
                },
                motor_temp_c: health.motor_temp_c.unwrap_or(f32::NAN),
                // Storage reads are checked by the store's ECC hook
                // (`safety::take_flash_ecc_error`), which counts the slot as corrupt.
                flash_ecc_error: false,
            };
            let (out, zero) = core.lock(|c| {
                let mut c = c.borrow_mut();
                c.set_board_inputs(board_inputs);
                if board::OUTPUT_ENCODER.is_some() {
                    c.set_output_encoder_count(Some(io.output_encoder.count()));
                }
                let start = DWT::cycle_count();
                let out = c.step(&inputs);
                c.record_step_cycles(DWT::cycle_count().wrapping_sub(start));
                (out, c.measured_current_zero_adc())
            });
            // The trip takes the measured zero in the step that measured it, before this
            // step's drive: the supervisor drives only once the zero is measured, so no
            // release ever runs on the nominal zero. Without one the bridge stays off.
            if let Some(zero) = zero {
                let bits = zero.to_bits();
                if bits != zero_bits {
                    zero_bits = bits;
                    io.trip.set_zero(zero);
                }
            }
            if hw_trip && !out.enable {
                // The core stopped driving and latched HW_OVERCURRENT from the break flag:
                // the break may be cleared once the current is back under the threshold,
                // after which ClearFaults can clear the fault (its condition is gone).
                let faulted = core.lock(|c| !c.borrow().latched_faults().is_empty());
                if faulted && io.motor.rearm() {
                    warn!("overcurrent trip cleared: the core holds a latched fault");
                }
            }
            if zero.is_some() {
                drive(&mut io, &out, full_scale);
            } else {
                io.motor.stop();
            }
            if let Some(calibration) = out.persist {
                PERSIST.signal(calibration);
            }
            CHECK_INS.fetch_or(CONTROL, Ordering::Relaxed);

            cycles.record(DWT::cycle_count().wrapping_sub(start));
            if cycles.steps >= HEALTH_STEPS {
                (health.step_cycles_mean, health.step_cycles_max) = cycles.take();
                health.hw_trips = safety::HW_TRIPS.load(Ordering::Relaxed);
                HEALTH.lock(|h| h.set(health));
            }
        }
    }

    /// Applies the core's command to the bridge; disabled is the safe state.
    fn drive(io: &mut ControlIo, out: &Outputs, full_scale: f32) {
        if !out.enable {
            io.motor.stop();
            return;
        }
        let direction = if out.duty < 0.0 {
            Direction::Reverse
        } else {
            Direction::Forward
        };
        io.motor.set_direction(direction, &mut io.trip);
        // A refusal (a trip, or the comparator over its threshold) leaves the bridge off;
        // the next step's `poll_break` tells the core.
        // A non-finite duty is refused (`NaN.min(1.0)` is 1.0: full drive): the bridge off.
        let Some(compare) = crate::duty_compare(out.duty, full_scale) else {
            io.motor.stop();
            return;
        };
        io.motor.enable(compare);
    }

    /// Host bytes into the core. Checks in at least every 10 ms, link idle or not.
    #[embassy_executor::task]
    async fn host_rx(core: &'static SharedCore, mut rx: RingBufferedUartRx<'static>) {
        let mut buf = [0u8; 64];
        loop {
            match select(rx.read(&mut buf), Timer::after_millis(10)).await {
                Either::First(Ok(n)) => {
                    let now = Instant::now().as_micros();
                    core.lock(|c| c.borrow_mut().receive(now, &buf[..n]));
                }
                // The next read restarts reception; the deframer drops the torn frame.
                Either::First(Err(e)) => warn!("host link receive error: {}", e),
                Either::Second(()) => {}
            }
            CHECK_INS.fetch_or(HOST_RX, Ordering::Relaxed);
        }
    }

    /// Switches USART2 (both directions) to `baud` once its last byte has left: with 8x
    /// oversampling and the nearest even divider when it is within 1.5 % (4,000,000 Bd at
    /// 170 MHz: BRR 0x53, 3,953,488 Bd, -1.16 %; `firmware_core::usart_brr_over8`), else as
    /// embassy-stm32 rounds it. Only a board confirms what the ST-LINK V3 virtual COM port
    /// carries at the far end.
    fn set_host_baud(tx: &mut UartTx<'static, Async>, baud: u32) {
        use embassy_stm32::pac::usart::{regs, vals};
        let _ = tx.blocking_flush();
        match firmware_core::usart_brr_over8(crate::USART_KERNEL_HZ, baud) {
            Some((brr, _)) => {
                let r = embassy_stm32::pac::USART2;
                r.cr1().modify(|w| w.set_ue(false));
                r.presc().write(|w| w.set_prescaler(vals::Presc::DIV1));
                r.brr().write_value(regs::Brr(u32::from(brr)));
                r.cr1().modify(|w| {
                    w.set_over8(vals::Over8::from_bits(1));
                    w.set_ue(true);
                });
            }
            None => {
                if tx.set_baudrate(baud).is_err() {
                    warn!("host link: {} Bd refused by the USART", baud);
                }
            }
        }
        info!("host link at {} Bd", baud);
    }

    /// The core's frames out to the host, polled every millisecond when idle.
    #[embassy_executor::task]
    async fn host_tx(core: &'static SharedCore, mut tx: UartTx<'static, Async>) {
        let mut buf = [0u8; 256];
        let mut idle = Ticker::every(Duration::from_millis(1));
        loop {
            let n = core.lock(|c| c.borrow_mut().transmit(&mut buf));
            if n == 0 {
                // The line is quiet (the last write is done): a rate the host agreed with
                // `SetBaud`, or the fall-back to the default, takes effect now.
                let now = Instant::now().as_micros();
                if let Some(baud) = core.lock(|c| c.borrow_mut().take_baud_switch(now)) {
                    set_host_baud(&mut tx, baud);
                }
                idle.next().await;
            } else if let Err(e) = tx.write(&buf[..n]).await {
                warn!("host link transmit error: {}", e);
            }
            CHECK_INS.fetch_or(HOST_TX, Ordering::Relaxed);
        }
    }

    /// Writes calibrations to flash (blocking; only while the motor is off, as the core
    /// refuses `SetParameters` otherwise) and reports the outcome to the core.
    #[embassy_executor::task]
    async fn persist(core: &'static SharedCore, mut store: CalibrationStore<CalibrationFlash>) {
        loop {
            let calibration = PERSIST.wait().await;
            let result = store.save(&calibration);
            match result {
                Ok(()) => info!("calibration stored"),
                Err(StorageError::Flash(_)) => error!("calibration not stored: flash error"),
                Err(StorageError::Verify) => error!("calibration not stored: read-back differs"),
                Err(StorageError::RegionTooSmall) => {
                    error!("calibration not stored: STORAGE region too small")
                }
            }
            core.lock(|c| c.borrow_mut().persist_result(result.is_ok()));
        }
    }

    /// Health log period, in 100 ms ticks.
    const HEALTH_LOG_TICKS: u32 = 100;

    /// LD2 shows the supervisor state; state and fault changes are logged, the board's
    /// health every 10 s.
    #[embassy_executor::task]
    async fn monitor(core: &'static SharedCore, mut led: Output<'static>) {
        let mut ticker = Ticker::every(Duration::from_millis(100));
        let mut tick = 0u32;
        let mut last = (SupervisorState::Locked, 0u32);
        loop {
            // Three reads, not `status()`: the binary needs no more (and the snapshot's
            // code, ~450 B, stays out of the image).
            let (state, faults) = core.lock(|c| {
                let c = c.borrow();
                (c.state(), c.latched_faults().bits())
            });
            if (state, faults) != last {
                info!("supervisor: {} (faults {:#010x})", state.name(), faults);
                last = (state, faults);
            }
            if tick % HEALTH_LOG_TICKS == HEALTH_LOG_TICKS - 1 {
                info!("health: {}", HEALTH.lock(|h| h.get()));
            }
            let on = match state {
                SupervisorState::SpinUp | SupervisorState::Vibrating => true,
                SupervisorState::Fault => tick.is_multiple_of(2),
                _ => tick % 10 < 5,
            };
            if on {
                led.set_high();
            } else {
                led.set_low();
            }
            tick = tick.wrapping_add(1);
            ticker.next().await;
        }
    }

    /// Starts the IWDG and feeds it only when every task checked in since the last feed,
    /// so a stalled control loop or host link resets the board into the safe state.
    #[embassy_executor::task]
    async fn watchdog_feeder(mut watchdog: IndependentWatchdog<'static, IWDG>) {
        watchdog.unleash();
        let mut ticker = Ticker::every(WATCHDOG_FEED_PERIOD);
        loop {
            ticker.next().await;
            let seen = CHECK_INS.swap(0, Ordering::Relaxed);
            if seen == ALL_TASKS {
                watchdog.pet();
            } else {
                warn!("watchdog not fed: check-ins {:#05b}", seen);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_links_baud_error_is_the_dividers_a_quarter_percent() {
        // 170 MHz / 921,600 = 184.46: BRR 184, 923,913 Bd, +0.25 %, inside the UART's
        // ~2 % tolerance with the crystal's ppm on top; HSI16's +-1 % would have added up
        // to 1.25 %.
        assert_eq!(usart_baud(USART_KERNEL_HZ, HOST_BAUD), (184, 923_913));
        assert_eq!(HOST_BAUD_ERROR_PPM, 2_509);
        assert_eq!(
            u64::from(USART_KERNEL_HZ),
            model::hardware::board::SYSCLK_HZ as u64
        );
    }

    #[test]
    fn a_non_finite_duty_is_refused_never_full_drive() {
        // The review's case: `NaN.min(1.0)` is 1.0, so NaN used to become 100 %.
        assert_eq!(f32::NAN.min(1.0), 1.0);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(duty_compare(bad, 4249.0), None, "{bad}");
        }
        assert_eq!(duty_compare(0.5, 4250.0), Some(2125));
        assert_eq!(duty_compare(-0.5, 4250.0), Some(2125));
        assert_eq!(duty_compare(3.0, 4250.0), Some(4250));
        assert_eq!(duty_compare(0.0, 4250.0), Some(0));
    }

    #[test]
    fn the_identity_is_version_and_the_one_build_constant() {
        assert_eq!(IDENTITY, format!("rig firmware {VERSION} build {BUILD}"));
        // NUL-terminated for the host's reader of `RIG_FIRMWARE_ID`.
        assert_eq!(&IDENTITY_BYTES[..IDENTITY_LEN], IDENTITY.as_bytes());
        assert_eq!(IDENTITY_BYTES[IDENTITY_LEN], 0);
        // What `build.rs` makes: a commit (`-dirty` allowed), `unknown`, or a given string,
        // never longer than `Info`'s 20-byte field.
        assert!(!BUILD.is_empty() && BUILD.len() <= 20, "{BUILD}");
        assert!(BUILD.bytes().all(|b| b.is_ascii_graphic()), "{BUILD}");
    }
}
