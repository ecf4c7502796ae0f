//! Flashing the rig's firmware and reading its log through a debug probe (`rig flash`,
//! `rig log`), and the firmware's build identity.
//!
//! - [`memory`]: the board's flash, RAM and calibration-store regions, from the workspace's
//!   `memory.x` (the file the firmware is linked with).
//! - [`image`]: the checks an ELF passes before anything touches the chip.
//! - [`identity`]: the version and build record the firmware carries, and the check after
//!   flashing that the board runs the flashed image ([`identity::confirm`]).
//! - [`workspace`]: finding and building the release firmware when no `--elf` is given.
//! - [`help`]: what to check when no probe is found, the Linux udev rules.
//! - `probe` and `log` (cargo feature `probe`, on by default): the probe-rs library
//!   (programming only the sectors the image touches, never a chip erase; attaching without
//!   a reset) and defmt-decoder.

pub mod help;
pub mod identity;
pub mod image;
#[cfg(feature = "probe")]
pub mod log;
pub mod memory;
#[cfg(feature = "probe")]
pub mod probe;
pub mod workspace;

use std::path::Path;

use crate::RigError;
pub use image::FirmwareImage;
pub use memory::MemoryMap;

/// The board's chip, as probe-rs names it.
pub const DEFAULT_CHIP: &str = "STM32G474RETx";

/// Reads and checks the firmware ELF at `path` against the board's memory map.
pub fn load(path: &Path, map: &MemoryMap) -> Result<(Vec<u8>, FirmwareImage), RigError> {
    let bytes = std::fs::read(path).map_err(|source| RigError::File {
        action: "read the firmware ELF",
        path: path.display().to_string(),
        source,
    })?;
    let image = image::validate(&bytes, map).map_err(|e| RigError::BadValue {
        what: format!("firmware image {}", path.display()),
        why: e.to_string(),
    })?;
    Ok((bytes, image))
}

/// The board's memory map, or the error for a damaged build of rig.
pub fn board_map() -> Result<MemoryMap, RigError> {
    MemoryMap::board().map_err(|why| RigError::BadValue {
        what: "rig".into(),
        why,
    })
}

/// How programming went.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FlashTimes {
    /// Erasing, s.
    pub erase_s: f64,
    /// Programming, s.
    pub program_s: f64,
    /// Reading back, s.
    pub verify_s: f64,
    /// Everything, from the first sector erased to the reset, s.
    pub total_s: f64,
}
