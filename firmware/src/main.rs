//! Firmware binary of the backdrive rig (Nucleo-G474RE, STM32G474RE).
//!
//! Thin on purpose: bring up the clocks and `board` drivers in their safe state (vibration
//! off), load the calibration from flash, then run tasks that only move data between the
//! peripherals and the control core (`firmware_core::Core`):
//!
//! | task            | executor                 | does                                                    |
//! |-----------------|--------------------------|---------------------------------------------------------|
//! | `control`       | interrupt (UART4, P6)    | 1 kHz, paced by the ADC DMA: samples, encoder, button -> `Core::step` -> H-bridge |
//! | `host_rx`       | thread                   | UART bytes -> `Core::receive`                            |
//! | `host_tx`       | thread                   | `Core::transmit` -> UART                                 |
//! | `persist`       | thread                   | writes a calibration to flash, reports the outcome       |
//! | `status_led`    | thread                   | LD2: 1 Hz blink locked, on while vibrating, 5 Hz on a fault; logs state changes |
//! | `watchdog_feeder` | thread                 | feeds the IWDG only when control, host_rx and host_tx all checked in |
//!
//! The control task runs on a higher-priority interrupt executor so that a flash erase
//! (blocking, ~20 ms, in thread mode) or a long UART write never delays a control step.
//! The core is shared through a critical-section mutex; each access is one short call.
//!
//! On the host this builds as a stub that says how to build and flash, so that
//! `cargo build --workspace` and `cargo test --workspace` work without the thumb target.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Firmware version, reported at boot (and to the host in `Info`).
const VERSION: &str = env!("CARGO_PKG_VERSION");

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "rig firmware {VERSION} runs on the Nucleo-G474RE (STM32G474RE); this host build is a stub.\n\
         build:  cargo fw-build   (cargo build -p firmware --release --target thumbv7em-none-eabihf)\n\
         flash:  cargo fw-flash   (probe-rs run --chip STM32G474RETx; `cargo install probe-rs-tools`)\n\
         target: rustup target add thumbv7em-none-eabihf"
    );
}

#[cfg(target_os = "none")]
mod board;

#[cfg(target_os = "none")]
mod app {
    use core::cell::RefCell;
    use core::mem::MaybeUninit;
    use core::sync::atomic::{AtomicU8, Ordering};

    use cortex_m::peripheral::DWT;

    use defmt::{error, info, unwrap, warn};
    use embassy_executor::{InterruptExecutor, Spawner};
    use embassy_futures::select::{Either, select};
    use embassy_stm32::gpio::Output;
    use embassy_stm32::interrupt;
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    use embassy_stm32::mode::Async;
    use embassy_stm32::peripherals::IWDG;
    use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, Instant, Ticker, Timer};
    use firmware_core::storage::{CalibrationStore, StorageError};
    use firmware_core::{BootInfo, Core, CoreConfig, Inputs, Outputs};
    use protocol::{ParametersStatus, ResetCause, RigParameters, SupervisorState};
    use {defmt_rtt as _, panic_probe as _};

    use crate::board::{self, CalibrationFlash, CamEncoder, CamMotor, CurrentSense, Direction};

    /// The control core, shared by the tasks.
    type SharedCore = Mutex<CriticalSectionRawMutex, RefCell<&'static mut Core>>;

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

    /// The build identifier `Info` reports: `RIG_FIRMWARE_BUILD` when the build script
    /// provides it (the git short hash, `-dirty` for a changed tree), else `unknown`.
    const BUILD_ID: &str = match option_env!("RIG_FIRMWARE_BUILD") {
        Some(build) => build,
        None => BootInfo::UNKNOWN_BUILD,
    };

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
        // Before anything else can reset or clear them.
        let reset = board::ResetCause::take();
        let p = embassy_stm32::init(board::config());
        // The cycle counter times each control step for the health sample (it reads 0,
        // "not measured", if the core peripherals were already taken).
        if let Some(mut cp) = cortex_m::Peripherals::take() {
            cp.DCB.enable_trace();
            cp.DWT.enable_cycle_counter();
        }
        let board::Board {
            motor,
            encoder,
            current,
            host_link,
            release_button,
            led,
            watchdog,
            storage,
        } = board::Board::new(p);

        info!(
            "rig firmware v{} booted; last reset by the watchdog: {}",
            crate::VERSION,
            reset.watchdog
        );
        if reset.watchdog {
            warn!("the previous run stalled long enough for the IWDG to reset it");
        }
        info!("reset flags: {}", reset);

        let mut store = CalibrationStore::new(storage);
        let loaded = store.load();
        match loaded.status {
            ParametersStatus::Valid => info!("calibration loaded from flash"),
            ParametersStatus::Defaults => info!("no calibration stored: the paper's values"),
            _ => error!("stored calibration is invalid: the paper's values, motor locked"),
        }
        let boot = BootInfo {
            reset_cause: reset_cause(&reset),
            firmware_build: BUILD_ID,
            parameters: loaded.calibration,
            parameters_status: loaded.status,
        };
        // The core (~43 KiB, mostly the capture buffer) is built straight into its static
        // slot (no stack temporary); the tasks share a reference to it through the mutex.
        let slot = unwrap!(cortex_m::singleton!(: MaybeUninit<Core> = MaybeUninit::uninit()));
        let core_ref: &'static mut Core = slot.write(Core::new(CoreConfig::default(), boot));
        let core: &'static SharedCore =
            unwrap!(cortex_m::singleton!(: SharedCore = Mutex::new(RefCell::new(core_ref))));

        info!(
            "board up: motor off (max duty {}), encoder at {}, current ADC @ {} Hz, host link @ {} Bd",
            motor.max_duty(),
            encoder.count(),
            board::CURRENT_SAMPLE_RATE.0,
            board::HOST_BAUD_RATE,
        );

        interrupt::UART4.set_priority(Priority::P6);
        let control_spawner = CONTROL_EXECUTOR.start(interrupt::UART4);
        control_spawner.spawn(unwrap!(control(
            core,
            motor,
            encoder,
            current,
            release_button
        )));
        spawner.spawn(unwrap!(host_rx(core, host_link.rx)));
        spawner.spawn(unwrap!(host_tx(core, host_link.tx)));
        spawner.spawn(unwrap!(persist(core, store)));
        spawner.spawn(unwrap!(status_led(core, led)));
        spawner.spawn(unwrap!(watchdog_feeder(watchdog)));
    }

    /// The 1 kHz control loop, paced by the ADC: every block of 10 current samples is one
    /// step of the core, whose outputs go straight to the H-bridge.
    #[embassy_executor::task]
    async fn control(
        core: &'static SharedCore,
        mut motor: CamMotor,
        encoder: CamEncoder,
        mut current: CurrentSense,
        button: board::ReleaseButton,
    ) {
        let mut block = [0u16; board::CURRENT_BLOCK_LEN];
        let full_scale = motor.max_duty() as f32;
        loop {
            let samples: &[u16] = match current.read_block(&mut block).await {
                Ok(()) => &block,
                Err(board::SampleOverrun) => {
                    // The step comes late; the core flags CONTROL_OVERRUN from the time.
                    warn!("current samples lost (ADC DMA overrun)");
                    &[]
                }
            };
            let inputs = Inputs {
                now_us: Instant::now().as_micros(),
                current_adc: samples,
                encoder_count: encoder.count(),
                release_button: button.is_held(),
            };
            let out = core.lock(|c| {
                let mut c = c.borrow_mut();
                let start = DWT::cycle_count();
                let out = c.step(&inputs);
                c.record_step_cycles(DWT::cycle_count().wrapping_sub(start));
                out
            });
            drive(&mut motor, &out, full_scale);
            if let Some(calibration) = out.persist {
                PERSIST.signal(calibration);
            }
            CHECK_INS.fetch_or(CONTROL, Ordering::Relaxed);
        }
    }

    /// Applies the core's command to the bridge; disabled is the safe state.
    fn drive(motor: &mut CamMotor, out: &Outputs, full_scale: f32) {
        if !out.enable {
            motor.stop();
            return;
        }
        motor.set_direction(if out.duty < 0.0 {
            Direction::Reverse
        } else {
            Direction::Forward
        });
        motor.set_duty((out.duty.abs().min(1.0) * full_scale) as u32);
        motor.enable();
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

    /// The core's frames out to the host, polled every millisecond when idle.
    #[embassy_executor::task]
    async fn host_tx(core: &'static SharedCore, mut tx: UartTx<'static, Async>) {
        let mut buf = [0u8; 256];
        let mut idle = Ticker::every(Duration::from_millis(1));
        loop {
            let n = core.lock(|c| c.borrow_mut().transmit(&mut buf));
            if n == 0 {
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

    /// LD2 shows the supervisor state; state and fault changes are logged.
    #[embassy_executor::task]
    async fn status_led(core: &'static SharedCore, mut led: Output<'static>) {
        let mut ticker = Ticker::every(Duration::from_millis(100));
        let mut tick = 0u32;
        let mut last = (SupervisorState::Locked, 0u32);
        loop {
            let (state, faults) = core.lock(|c| {
                let s = c.borrow().status();
                (s.state, s.latched_faults.bits())
            });
            if (state, faults) != last {
                info!("supervisor: {} (faults {:#010x})", state.name(), faults);
                last = (state, faults);
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
