//! Flash and static RAM use of an ELF, from its allocated sections.

use std::path::Path;

use object::{Object, ObjectSection, SectionFlags, SectionKind};

/// Flash budget of the release firmware, bytes: 64 KiB of the 496 KiB below the calibration
/// store (issue 11 set 48 KiB; issue 30 raised it for the braking image and the stream to
/// come). `cargo xtask firmware` and `cargo xtask target-bench` check the same number, for
/// both images ([`crate::Image`]).
pub const FLASH_BUDGET: u64 = 64 * 1024;
/// Static RAM budget of the release firmware (capture buffer included), bytes.
pub const RAM_BUDGET: u64 = 64 * 1024;

/// Memory use of a firmware image, bytes.
#[derive(Debug, Clone, Copy)]
pub struct Usage {
    /// Bytes stored in flash: code, read-only data and the initial values of `.data`.
    pub flash: u64,
    /// Static RAM: `.data`, `.bss` and `.uninit` (the stack is what is left over).
    pub ram: u64,
}

/// Reads the section table of `elf`.
pub fn measure(elf: &Path) -> Result<Usage, String> {
    let bytes = std::fs::read(elf).map_err(|e| format!("cannot read {}: {e}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .map_err(|e| format!("{} is not an ELF: {e}", elf.display()))?;
    let mut usage = Usage { flash: 0, ram: 0 };
    for section in file.sections() {
        let allocated = match section.flags() {
            SectionFlags::Elf { sh_flags } => sh_flags & u64::from(object::elf::SHF_ALLOC) != 0,
            _ => false,
        };
        if !allocated || section.size() == 0 {
            continue;
        }
        let in_ram = (0x2000_0000..0x4000_0000).contains(&section.address());
        match section.kind() {
            SectionKind::UninitializedData | SectionKind::UninitializedTls => {
                usage.ram += section.size()
            }
            _ if in_ram => {
                // `.data`: lives in RAM, its initial values are stored in flash.
                usage.ram += section.size();
                usage.flash += section.size();
            }
            _ => usage.flash += section.size(),
        }
    }
    Ok(usage)
}
