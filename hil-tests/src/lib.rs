//! Rig scenarios run in the loop. By default they run software-in-the-loop: the firmware's
//! control core and the simulated plant in closed loop, in virtual time, through the real
//! wire protocol. With `RIG_PORT` naming a serial port (for example
//! `RIG_PORT=/dev/ttyACM0 cargo test -p hil-tests`) the hardware tests run the same
//! checks against a real rig; without it they are skipped with a message.

/// Where the scenarios run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// The simulated rig (firmware core + plant).
    Simulated,
    /// A real rig on this serial port.
    Serial(String),
}

/// The target chosen by the environment: `RIG_PORT` set and non-empty selects a real rig.
pub fn target() -> Target {
    match std::env::var("RIG_PORT") {
        Ok(port) if !port.trim().is_empty() => Target::Serial(port.trim().to_string()),
        _ => Target::Simulated,
    }
}

/// The real rig's port, or `None` after printing why the hardware test is skipped.
pub fn real_rig_or_skip(test: &str) -> Option<String> {
    match target() {
        Target::Serial(port) => Some(port),
        Target::Simulated => {
            eprintln!(
                "{test}: skipped, no rig: set RIG_PORT to the rig's serial port (see `rig ports`) to run it on hardware"
            );
            None
        }
    }
}
