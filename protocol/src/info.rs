//! Device identity: the reply to `Hello` and `GetInfo`.

use core::fmt;

use heapless::String;
use serde::{Deserialize, Serialize};

use crate::flags::flag_set;
use crate::sizes::{F32, TAG, U8, U16, U32};

/// Longest board name [`DeviceInfo::board`] can carry, bytes.
pub const BOARD_NAME_LEN: usize = 16;

/// Longest build identifier [`DeviceInfo::firmware_build`] can carry, bytes: a 12-digit
/// short commit hash plus `-dirty` fits.
pub const FIRMWARE_BUILD_LEN: usize = 20;

/// Device identity and versions, the reply to `Hello` and `GetInfo`.
///
/// `protocol_version` and `schema_hash` come first and stay first in every later protocol
/// version, so any host can read them (see [`crate::identify_peer`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// The firmware's [`crate::PROTOCOL_VERSION`].
    pub protocol_version: u16,
    /// The firmware's [`crate::SCHEMA_HASH`].
    pub schema_hash: u32,
    /// Firmware version (the firmware crate's).
    pub firmware_version: FirmwareVersion,
    /// The build: short git commit of the firmware's source, with a `-dirty` suffix when
    /// the tree had uncommitted changes (e.g. `1a2b3c4d5e6f-dirty`); `unknown` outside git.
    pub firmware_build: String<FIRMWARE_BUILD_LEN>,
    /// Board name, e.g. `nucleo-g474re` or `virtual`.
    pub board: String<BOARD_NAME_LEN>,
    /// Source of the active rig parameters.
    pub parameters_status: ParametersStatus,
    /// Why the device last reset.
    pub reset_cause: ResetCause,
    /// Seconds since that reset.
    pub uptime_s: u32,
    /// Optional hardware this board has fitted.
    pub capabilities: Capabilities,
    /// Device seconds per wall-clock second: 1 on a board; a virtual rig served faster (or
    /// slower) than real time says how much (`rig sim serve --speed`). Every time in the
    /// protocol (the comms timeout, the fault hold, `device_time_us`) is device time, so a
    /// host divides its heartbeat interval by this.
    pub time_scale: f32,
    /// The fastest link rate the device switches to on `Request::SetBaud`, Bd
    /// ([`crate::FAST_BAUD_RATE`] on the Nucleo firmware; [`crate::DEFAULT_BAUD_RATE`] on a
    /// device that cannot switch).
    pub max_baud: u32,
}

impl DeviceInfo {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = U16
        + U32
        + 3 * U8
        + (TAG + FIRMWARE_BUILD_LEN)
        + (TAG + BOARD_NAME_LEN)
        + TAG
        + TAG
        + U32
        + U16
        + F32
        + U32;
}

/// Firmware version, semantic-versioning style.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct FirmwareVersion {
    /// Incompatible changes.
    pub major: u8,
    /// Compatible additions.
    pub minor: u8,
    /// Fixes.
    pub patch: u8,
}

impl fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// Where the active rig parameters came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ParametersStatus {
    /// A stored record passed its checks and is in use.
    Valid,
    /// Nothing stored: the paper's values are in use.
    Defaults,
    /// The stored record failed its checks: the paper's values are in use.
    Invalid,
}

impl ParametersStatus {
    /// Lower-case name for text and JSON.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Valid => "valid",
            Self::Defaults => "defaults",
            Self::Invalid => "invalid",
        }
    }
}

/// Why the microcontroller last reset (from its reset-flag register).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ResetCause {
    /// Power was applied.
    PowerOn,
    /// The reset pin (the board's reset button, or a debug probe).
    Pin,
    /// The firmware asked for it (e.g. after a fault handler put the bridge in its safe state).
    Software,
    /// A watchdog expired: the control loop stalled.
    Watchdog,
    /// The supply dipped below the brown-out threshold.
    BrownOut,
    /// The core locked up (a fault inside a fault handler).
    Lockup,
    /// None of the above, or the flags were unreadable.
    Other,
}

impl ResetCause {
    /// Lower-case name for text and JSON (`power-on`, `pin`, `software`, `watchdog`,
    /// `brown-out`, `lockup`, `other`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::PowerOn => "power-on",
            Self::Pin => "pin",
            Self::Software => "software",
            Self::Watchdog => "watchdog",
            Self::BrownOut => "brown-out",
            Self::Lockup => "lockup",
            Self::Other => "other",
        }
    }
}

flag_set! {
    /// Optional hardware fitted to the board, a `u16` varint on the wire. Telemetry values
    /// that need hardware the board lacks are NaN.
    pub struct Capabilities(u16) {
        /// A quadrature encoder on the output shaft: output angle and speed, backdrive
        /// detection and the output-overspeed fault.
        const OUTPUT_ENCODER = 0
            => "an encoder on the output shaft: output angle and speed, backdrive detection, output overspeed";
        /// A divider measuring the motor supply: bus voltage in telemetry, used by the
        /// speed loop's feed-forward and by open-loop volts.
        const BUS_VOLTAGE = 1
            => "the motor supply is measured: bus voltage in health, feed-forward and open-loop volts use it";
        /// A thermistor on the motor: motor temperature in telemetry.
        const MOTOR_TEMP = 2
            => "a thermistor on the motor: motor temperature in health";
        /// The device is the virtual rig (a simulation), which accepts
        /// `Request::Simulation` commands.
        const SIMULATION = 3
            => "the device is the virtual rig: it accepts simulation commands";
        /// The bridge brakes in the PWM's off-time (slow decay, the Pololu G2): the current
        /// may reverse and the carrier's inertial power returns through the gearhead, which
        /// the estimator's kappa takes (`model::effects::KAPPA_BRAKING_DRIVE`). Clear: a
        /// bridge that coasts and returns nothing.
        const BRAKING_DECAY = 4
            => "the bridge brakes in the PWM's off-time (slow decay): power returns to the supply, the estimator's kappa is the braking drive's";
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_distinct() {
        let causes = [
            ResetCause::PowerOn,
            ResetCause::Pin,
            ResetCause::Software,
            ResetCause::Watchdog,
            ResetCause::BrownOut,
            ResetCause::Lockup,
            ResetCause::Other,
        ];
        let mut names: std::vec::Vec<_> = causes.iter().map(|c| c.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), causes.len());
        assert_eq!(
            (Capabilities::OUTPUT_ENCODER | Capabilities::SIMULATION).to_string(),
            "OUTPUT_ENCODER | SIMULATION"
        );
        assert_eq!(ParametersStatus::Defaults.name(), "defaults");
    }
}
