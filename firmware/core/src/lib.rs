//! Hardware-free control core of the rig firmware: the cam-speed loop, the per-revolution
//! tau_cam estimator, the release supervisor, faults, the protocol server, the raw capture
//! and the calibration store.
//!
//! The core is a state machine with time passed in (no I/O, no heap, no embassy): the
//! binary calls [`Core::step`] at `control_hz` with the current samples, encoder count and
//! release button, applies the returned [`Outputs`] to the H-bridge, feeds host bytes to
//! [`Core::receive`] and sends what [`Core::transmit`] yields. A simulator drives it the
//! same way with `model::plant::Plant` in place of the hardware.
//!
//! ```
//! use firmware_core::{BootInfo, Core, CoreConfig, Inputs};
//!
//! let mut core = Core::new(CoreConfig::default(), BootInfo::default());
//! let samples = [2068u16; 10]; // 1 ms of ADC samples at zero current
//! let out = core.step(&Inputs {
//!     now_us: 1000,
//!     current_adc: &samples,
//!     encoder_count: 0,
//!     release_button: false,
//! });
//! assert!(!out.enable && out.duty == 0.0); // vibration off: the safe state
//! ```
//!
//! Everything on the target's path is integer or f32 arithmetic (the Cortex-M4F has a
//! single-precision FPU; no soft double, no f64 trigonometry): the revolution estimate
//! evaluates [`Coefficients`] derived once per parameter record, whose f64 counterpart
//! ([`EstimatorModel`], the model's own functions) the tests hold them to. Telemetry and
//! health samples are taken by the step and framed by [`Core::transmit`].
//! `cargo xtask target-bench` measures the cycles on an emulated Cortex-M4.
//!
//! # Board inputs (issue 10)
//! Besides [`Inputs`], the binary hands over what else the board measures with
//! [`Core::set_board_inputs`] before a step ([`BoardInputs`]; kept out of [`Inputs`] so a
//! binary that does not read them yet keeps building): TIM1's break flag after the COMP3
//! overcurrent trip (`hw_break`, latches `HW_OVERCURRENT`; re-arm MOE only while
//! [`Core::break_latched`] is false), VDDA from VREFINT (`vdda_v`, the current-sensor zero
//! window), the bridge bus voltage (`bus_voltage_v`, feed-forward and open-loop duty =
//! volts / Vbus, Health), the motor NTC (`motor_temp_c`, Health) and a flash ECC error
//! flag. The step's DWT cycle count goes to [`Core::record_step_cycles`]; the storage
//! layer's ECC hook is [`storage::CalibrationStore::with_ecc_check`]. NaN means "not
//! measured" throughout. The host's calibration check and `SetParameters` share
//! [`check_rules`] (the model's `BoardLimits::check` and `Calibration::check`).
//!
//! # The continuous stream (issue 35)
//! `StartStream { rate_hz }` sends every ADC sample (10 kHz, or 10 kHz divided by a whole
//! number) with its step's cam and output counts, duty, tau_cam, status and state as
//! `StreamBlock`s. The step only copies its readings into a ring of
//! [`STREAM_RING_STEPS`] records; [`Core::transmit`] packs and frames the blocks. The
//! stream stops on `StopStream`, without an accepted request for the comms timeout, and
//! on [`Core::link_closed`].
//!
//! # Safety policy
//! The motor runs only in `SpinUp` and `Vibrating`, only while a release is live (a host
//! `Release` kept alive by its owner session's accepted drive requests within
//! `comms_timeout_us`, or the held
//! button), and never while a fault is latched. Faults latch until `ClearFaults`, which clears
//! only those whose condition is gone; for `fault_hold_us` after a fault every request
//! other than `Hello`, `GetInfo`, `GetFaults` and `ClearFaults` is refused.
//!
//! # Memory
//! [`Core`] holds the capture buffer ([`CAPTURE_CAPACITY`] samples of 4 bytes, 40 000
//! bytes, 1.0 s at 10 kHz; the output encoder rides in the ADC codes' spare bits, see
//! [`OUTPUT_GROUP_MIN`]) and is 43 000 bytes in all on the target; the release image
//! uses ~50 KiB of static RAM (`cargo xtask firmware`). Build it in place with
//! [`Core::new_in`] into a static slot, as the binary does, never on the stack.
#![cfg_attr(not(test), no_std)]
// No silent numeric narrowing on the target (as in `model` and `protocol`): every cast that
// can truncate, lose a sign or wrap is written so it cannot, or carries an `allow` with its
// reason.
#![deny(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

pub mod bridge;
mod capture;
mod config;
mod controller;
mod current;
mod encoder;
mod estimator;
mod faults;
mod link;
mod output_encoder;
mod release;
mod server;
mod speed_loop;
pub mod storage;
mod stream;
mod supervisor;
mod tx_queue;

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests;

pub use capture::{CAPTURE_CAPACITY, MIN_SAMPLE_RATE_HZ, OUTPUT_GROUP_MIN};
pub use config::{
    CoreConfig, CurrentSensorConfig, EstimatorConfig, FaultConfig, MotorConfig, MotorRules,
    SpeedLoopConfig, SupervisorConfig,
};
pub use controller::{BoardInputs, BootInfo, Core, Inputs, Outputs, Status, check_rules};
pub use estimator::{Coefficients, EstimatorModel, RevolutionEstimate};
pub use link::{MAX_BAUD_ERROR_PERMILLE, usart_brr_over8};
pub use output_encoder::{OutputEncoder, OutputEncoderConfig};
pub use server::FIRMWARE_VERSION;
pub use speed_loop::FeedForward;
pub use stream::{STREAM_RING_STEPS, STREAM_STEP_SAMPLES};
pub use tx_queue::TX_QUEUE_LEN;
