//! Processor in the loop: the firmware's own ELF, instruction by instruction, on an
//! emulated STM32G474 whose peripherals are driven by the rig's simulated plant.
//!
//! The CPU is the Unicorn engine's Cortex-M4 with its FPU (loaded at run
//! time from the pinned PyPI wheel). Unicorn has the instruction set but none of the
//! Cortex-M system: this crate adds the NVIC (priorities, pending, BASEPRI/PRIMASK, exception
//! entry and return with the FP frame, tail-chaining), SysTick, DWT's cycle counter, the MPU's
//! stack guard, and the STM32G474 peripherals the firmware uses, modelled from RM0440 as far
//! as it uses them ([`periph`]). Anything the image touches outside them is recorded by
//! address ([`Machine::unmodelled`]), never read silently as zero.
//!
//! Time is the instruction count at 170 MHz: one instruction is one cycle (the Cortex-M4's
//! loads, branches and divisions take 2 to 12 on silicon, so the emulated image runs its
//! code up to about 1.5x faster than the board; the target bench's cycle table is the
//! measure of the real cost). WFI and WFE skip to the next peripheral event.
//!
//! [`Board`] closes the loop with [`model::plant::Plant`]: TIM1's compare, main output and
//! the enable and direction pins are the bridge's drive; the ADC converts the plant's
//! ACS714 output, bus voltage and NTC; the encoder timers count the plant's angles; COMP3
//! compares the current sensor's pin with DAC3 and breaks TIM1 in hardware; USART2's bytes
//! are the host link at the configured baud.

pub mod board;
pub mod elf;
pub mod machine;
pub mod periph;
mod unicorn;

pub use board::{Board, BoardConfig};
pub use machine::Machine;
pub use unicorn::{UNICORN_VERSION, candidates as emulator_candidates};

/// Where the Unicorn library was loaded from, or why it cannot be (with what to do).
pub fn emulator() -> Result<std::path::PathBuf, EmuError> {
    unicorn::Api::get().map(|api| api.path.clone())
}

/// What can go wrong loading or running an image.
#[derive(Debug, thiserror::Error)]
pub enum EmuError {
    /// The Unicorn library is missing (the message says how to install it).
    #[error("{0}")]
    NoEmulator(String),
    /// The engine refused an operation.
    #[error("emulator: {0}")]
    Engine(String),
    /// The ELF cannot be read or is not a firmware image for this chip.
    #[error("firmware image {path}: {why}")]
    Image {
        /// The file.
        path: String,
        /// What is wrong with it.
        why: String,
    },
    /// The image stopped in a way the board cannot continue from.
    #[error("the emulated board stopped at pc {pc:#010x}: {why}")]
    Stopped {
        /// Where.
        pc: u32,
        /// Why.
        why: String,
    },
}
