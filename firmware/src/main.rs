//! Firmware binary of the backdrive rig (Nucleo-G474RE, STM32G474RE).
//!
//! Thin on purpose: bring up the clocks and [`board`] drivers in their safe state (vibration
//! off), then run tasks that only move data between peripherals and the control core.
//! On the host this builds as a stub that says how to build and flash, so that
//! `cargo build --workspace` and `cargo test --workspace` work without the thumb target.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Firmware version, reported at boot (and later to the host).
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
#[allow(
    dead_code,
    reason = "driver API for the control and comms tasks, which are not written yet"
)]
mod board;

#[cfg(target_os = "none")]
use {
    defmt::{info, unwrap, warn},
    defmt_rtt as _,
    embassy_executor::Spawner,
    embassy_stm32::{gpio::Output, peripherals::IWDG, wdg::IndependentWatchdog},
    embassy_time::{Duration, Ticker},
    panic_probe as _,
};

/// Half-period of the LD2 heartbeat blink.
#[cfg(target_os = "none")]
const HEARTBEAT_HALF_PERIOD: Duration = Duration::from_millis(500);
/// Watchdog feed period: well inside the ~250 ms IWDG timeout.
#[cfg(target_os = "none")]
const WATCHDOG_FEED_PERIOD: Duration = Duration::from_millis(100);

#[cfg(target_os = "none")]
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Before anything else can reset or clear them.
    let reset = board::ResetCause::take();
    let p = embassy_stm32::init(board::config());
    let board::Board {
        motor,
        encoder,
        current,
        host_link,
        release_button,
        led,
        watchdog,
    } = board::Board::new(p);

    info!(
        "rig firmware v{} booted; last reset by the watchdog: {}",
        VERSION, reset.watchdog
    );
    if reset.watchdog {
        warn!("the previous run stalled long enough for the IWDG to reset it");
    }
    info!("reset flags: {}", reset);

    spawner.spawn(unwrap!(heartbeat(led)));
    spawner.spawn(unwrap!(watchdog_feeder(watchdog)));

    info!(
        "board up: motor off (max duty {}), encoder at {}, current ADC @ {} Hz, host link @ {} Bd, release button held: {}",
        motor.max_duty(),
        encoder.count(),
        board::CURRENT_SAMPLE_RATE.0,
        board::HOST_BAUD_RATE,
        release_button.is_held(),
    );

    // Held, not dropped, until the control and comms tasks take them: dropping a driver would
    // release its pins or stop its peripheral, and the motor must stay driven off.
    let _awaiting_control_core = (motor, encoder, current, host_link, release_button);
    core::future::pending::<()>().await;
}

/// Blinks LD2 so a glance at the board shows the executor is alive.
#[cfg(target_os = "none")]
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    let mut ticker = Ticker::every(HEARTBEAT_HALF_PERIOD);
    loop {
        led.toggle();
        ticker.next().await;
    }
}

/// Starts the IWDG and keeps it fed.
#[cfg(target_os = "none")]
#[embassy_executor::task]
async fn watchdog_feeder(mut watchdog: IndependentWatchdog<'static, IWDG>) {
    watchdog.unleash();
    let mut ticker = Ticker::every(WATCHDOG_FEED_PERIOD);
    loop {
        // For now only the executor's liveness is proven. Once they exist, the control task and
        // the comms task must both check in (e.g. bits in an AtomicU8) since the last feed
        // before it is fed, so that either one stalling resets the board into the safe state.
        watchdog.pet();
        ticker.next().await;
    }
}
