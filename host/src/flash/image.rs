//! Checks a firmware ELF before anything touches the chip: an ARM Thumb (ARMv7E-M) image
//! whose vector table sits at the start of flash, whose loadable data lies in program flash
//! and ends below the calibration store, and what it carries (build identity, RTT control
//! block, defmt table).

use std::fmt;

use object::elf;
use object::read::elf::{ElfFile32, FileHeader, ProgramHeader};
use object::{Endianness, Object, ObjectSection, ObjectSymbol};

use super::identity::{BuildIdentity, IDENTITY_SYMBOL};
use super::memory::MemoryMap;

/// Symbol of the RTT control block (defmt-rtt, rtt-target).
pub const RTT_SYMBOL: &str = "_SEGGER_RTT";

/// `Tag_CPU_arch` value of ARMv7E-M (Cortex-M4/M7) in `.ARM.attributes`.
const CPU_ARCH_V7EM: u64 = 13;

/// Bytes programmed at one address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Segment {
    /// Flash address of the first byte (the segment's load address).
    pub address: u32,
    /// The bytes.
    pub data: Vec<u8>,
}

impl Segment {
    /// One past the last byte.
    pub fn end(&self) -> u64 {
        u64::from(self.address) + self.data.len() as u64
    }
}

/// A firmware image that passed every check.
#[derive(Debug, Clone)]
pub struct FirmwareImage {
    /// ELF entry point (odd: Thumb).
    pub entry: u32,
    /// Initial stack pointer, the vector table's first word.
    pub initial_sp: u32,
    /// Reset handler, the vector table's second word (odd: Thumb).
    pub reset_vector: u32,
    /// What gets programmed, in address order.
    pub segments: Vec<Segment>,
    /// Version and build the image carries, when it was built with them.
    pub identity: Option<BuildIdentity>,
    /// RAM address of the RTT control block, when the image has one.
    pub rtt_address: Option<u32>,
    /// Whether the image has a defmt table (`rig log` needs it).
    pub has_defmt: bool,
}

impl FirmwareImage {
    /// Lowest programmed address.
    pub fn start(&self) -> u32 {
        self.segments.first().map_or(0, |s| s.address)
    }

    /// One past the highest programmed address.
    pub fn end(&self) -> u64 {
        self.segments.iter().map(Segment::end).max().unwrap_or(0)
    }

    /// Bytes programmed.
    pub fn size(&self) -> u64 {
        self.segments.iter().map(|s| s.data.len() as u64).sum()
    }

    /// The programmed bytes at `[address, address + len)`, when one segment holds them all.
    pub fn read(&self, address: u64, len: usize) -> Option<&[u8]> {
        self.segments.iter().find_map(|s| {
            let off = usize::try_from(address.checked_sub(u64::from(s.address))?).ok()?;
            s.data.get(off..off.checked_add(len)?)
        })
    }
}

/// Why a file is not a firmware image for this board.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ElfError {
    /// Not an ELF file at all.
    NotElf {
        /// What it looks like instead.
        looks_like: &'static str,
    },
    /// An ELF for another kind of machine.
    WrongMachine {
        /// `32-bit`/`64-bit`, endianness and architecture.
        what: String,
    },
    /// An ELF object or library, not a linked program.
    NotExecutable,
    /// An ARM ELF that is not for ARMv7E-M.
    WrongArchitecture {
        /// The `Tag_CPU_arch` found.
        cpu_arch: u64,
    },
    /// The ELF is damaged.
    Malformed(String),
    /// Entry point not a Thumb address in flash.
    BadEntry {
        /// The entry point.
        entry: u32,
    },
    /// Nothing to program.
    NoLoadableData,
    /// Loadable data that would land in the calibration store.
    OverlapsStorage {
        /// First byte of the offending segment.
        start: u64,
        /// One past its last byte.
        end: u64,
        /// The store.
        storage: String,
    },
    /// Loadable data outside program flash.
    OutsideFlash {
        /// First byte of the offending segment.
        start: u64,
        /// One past its last byte.
        end: u64,
        /// The program flash.
        flash: String,
    },
    /// A run-time (RAM) segment outside RAM and flash.
    OutsideRam {
        /// First byte of the offending segment.
        start: u64,
        /// One past its last byte.
        end: u64,
        /// RAM.
        ram: String,
    },
    /// No vector table at the start of flash.
    NoVectorTable {
        /// Where it must be.
        flash_start: u32,
    },
    /// The vector table's initial stack pointer is not in RAM.
    BadStackPointer {
        /// The value found.
        sp: u32,
        /// RAM.
        ram: String,
    },
    /// The vector table's reset handler is not a Thumb address in flash.
    BadResetVector {
        /// The value found.
        reset: u32,
    },
}

impl fmt::Display for ElfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const FIX: &str = "build the firmware for thumbv7em-none-eabihf with `cargo fw-build` (or run `rig flash` without --elf)";
        match self {
            Self::NotElf { looks_like } => write!(
                f,
                "not an ELF file ({looks_like}); give the firmware ELF (target/thumbv7em-none-eabihf/release/firmware), not a .bin or .hex"
            ),
            Self::WrongMachine { what } => write!(
                f,
                "a {what} program, not the firmware for the STM32G474 (an ARM Cortex-M4): {FIX}"
            ),
            Self::NotExecutable => {
                write!(f, "an ELF object or library, not a linked program: {FIX}")
            }
            Self::WrongArchitecture { cpu_arch } => write!(
                f,
                "an ARM image for another CPU (Tag_CPU_arch {cpu_arch}, {}): the STM32G474 needs ARMv7E-M (thumbv7em-none-eabihf); {FIX}",
                cpu_arch_name(*cpu_arch)
            ),
            Self::Malformed(why) => write!(f, "damaged ELF: {why}; rebuild it"),
            Self::BadEntry { entry } => write!(
                f,
                "entry point {entry:#010x} is not a Thumb address in flash (a Cortex-M program's is odd and in flash): {FIX}"
            ),
            Self::NoLoadableData => write!(f, "the ELF has nothing to program: {FIX}"),
            Self::OverlapsStorage {
                start,
                end,
                storage,
            } => write!(
                f,
                "the image's data at {start:#010x}..{end:#010x} reaches into the calibration store {storage}: flashing it would erase the stored calibration; make the firmware smaller (see `cargo xtask firmware`) or check memory.x"
            ),
            Self::OutsideFlash { start, end, flash } => write!(
                f,
                "the image's data at {start:#010x}..{end:#010x} lies outside the program flash {flash}: it is not linked for this board (memory.x); {FIX}"
            ),
            Self::OutsideRam { start, end, ram } => write!(
                f,
                "the image's RAM segment {start:#010x}..{end:#010x} lies outside RAM {ram}: it is not linked for this board (memory.x); {FIX}"
            ),
            Self::NoVectorTable { flash_start } => write!(
                f,
                "no vector table at the start of flash ({flash_start:#010x}): the board boots from there; {FIX}"
            ),
            Self::BadStackPointer { sp, ram } => write!(
                f,
                "the vector table's initial stack pointer {sp:#010x} is not in RAM {ram}: not linked for this board (memory.x); {FIX}"
            ),
            Self::BadResetVector { reset } => write!(
                f,
                "the vector table's reset handler {reset:#010x} is not a Thumb address in flash: {FIX}"
            ),
        }
    }
}

impl std::error::Error for ElfError {}

/// Name of an ARM `Tag_CPU_arch` value.
fn cpu_arch_name(arch: u64) -> &'static str {
    match arch {
        0 => "pre-ARMv4",
        1..=9 => "ARMv4 to ARMv6 (application cores)",
        10 => "ARMv7 (Cortex-A/R or Cortex-M3)",
        11 => "ARMv6-M (Cortex-M0/M0+)",
        12 => "ARMv6S-M",
        13 => "ARMv7E-M (Cortex-M4/M7)",
        14 => "ARMv8-A",
        16 => "ARMv8-M baseline (Cortex-M23)",
        17 => "ARMv8-M mainline (Cortex-M33)",
        _ => "unknown",
    }
}

/// What a non-ELF file looks like, for the message.
fn looks_like(bytes: &[u8]) -> &'static str {
    if bytes.is_empty() {
        "the file is empty"
    } else if bytes.starts_with(b"MZ") {
        "a Windows program"
    } else if bytes.starts_with(&[0xcf, 0xfa, 0xed, 0xfe])
        || bytes.starts_with(&[0xca, 0xfe, 0xba, 0xbe])
    {
        "a macOS program"
    } else if bytes.starts_with(b":") {
        "looks like Intel HEX"
    } else if bytes.starts_with(b"#!") || bytes.iter().take(256).all(|b| b.is_ascii()) {
        "looks like text"
    } else {
        "raw bytes, perhaps a .bin image"
    }
}

/// Checks `bytes` as a firmware ELF for the board described by `map`.
pub fn validate(bytes: &[u8], map: &MemoryMap) -> Result<FirmwareImage, ElfError> {
    if bytes.len() < 16 || !bytes.starts_with(b"\x7fELF") {
        return Err(ElfError::NotElf {
            looks_like: looks_like(bytes),
        });
    }
    let (class, data) = (bytes[4], bytes[5]);
    if class != elf::ELFCLASS32 || data != elf::ELFDATA2LSB {
        let arch = object::File::parse(bytes)
            .map(|f| format!("{:?}", f.architecture()))
            .unwrap_or_else(|_| "unknown".into());
        let bits = if class == elf::ELFCLASS64 {
            "64-bit"
        } else {
            "32-bit"
        };
        let endian = if data == elf::ELFDATA2MSB {
            "big-endian"
        } else {
            "little-endian"
        };
        return Err(ElfError::WrongMachine {
            what: format!("{bits} {endian} {} ELF", arch_name(&arch)),
        });
    }
    let file =
        ElfFile32::<Endianness>::parse(bytes).map_err(|e| ElfError::Malformed(e.to_string()))?;
    let endian = file.endian();
    let header = file.elf_header();
    let machine = header.e_machine(endian);
    if machine != elf::EM_ARM {
        return Err(ElfError::WrongMachine {
            what: format!(
                "32-bit {} ELF (e_machine {machine})",
                arch_name(&format!("{:?}", file.architecture()))
            ),
        });
    }
    if header.e_type(endian) != elf::ET_EXEC {
        return Err(ElfError::NotExecutable);
    }
    if let Some(arch) = cpu_arch(&file)
        && arch != CPU_ARCH_V7EM
    {
        return Err(ElfError::WrongArchitecture { cpu_arch: arch });
    }
    let entry = header.e_entry(endian);
    if entry & 1 == 0 || !map.flash.contains(u64::from(entry & !1)) {
        return Err(ElfError::BadEntry { entry });
    }

    let mut segments = Vec::new();
    for ph in file.elf_program_headers() {
        if ph.p_type(endian) != elf::PT_LOAD {
            continue;
        }
        let filesz = u64::from(ph.p_filesz(endian));
        let memsz = u64::from(ph.p_memsz(endian));
        let paddr = u64::from(ph.p_paddr(endian));
        let vaddr = u64::from(ph.p_vaddr(endian));
        if filesz > 0 {
            check_flash(map, paddr, paddr + filesz)?;
            let data = ph.data(endian, bytes).map_err(|()| {
                ElfError::Malformed("a segment's data lies past the end of the file".into())
            })?;
            segments.push(Segment {
                address: ph.p_paddr(endian),
                data: data.to_vec(),
            });
        }
        // Where it lives at run time (.data, .bss in RAM; code in flash).
        if memsz > 0 && !map.ram.contains_range(vaddr, vaddr + memsz) {
            if filesz > 0 && vaddr == paddr {
                continue; // checked as flash above
            }
            return Err(ElfError::OutsideRam {
                start: vaddr,
                end: vaddr + memsz,
                ram: map.ram.to_string(),
            });
        }
    }
    if segments.is_empty() {
        return Err(ElfError::NoLoadableData);
    }
    segments.sort_by_key(|s| s.address);
    for pair in segments.windows(2) {
        if pair[0].end() > u64::from(pair[1].address) {
            return Err(ElfError::Malformed(format!(
                "two segments overlap at {:#010x}",
                pair[1].address
            )));
        }
    }

    let mut image = FirmwareImage {
        entry,
        initial_sp: 0,
        reset_vector: 0,
        segments,
        identity: None,
        rtt_address: None,
        has_defmt: file.section_by_name(".defmt").is_some(),
    };
    let vectors = image
        .read(u64::from(map.flash.origin), 8)
        .ok_or(ElfError::NoVectorTable {
            flash_start: map.flash.origin,
        })?;
    let word =
        |i: usize| u32::from_le_bytes([vectors[i], vectors[i + 1], vectors[i + 2], vectors[i + 3]]);
    let (sp, reset) = (word(0), word(4));
    let sp_ok =
        u64::from(sp) > u64::from(map.ram.origin) && u64::from(sp) <= map.ram.end() && sp % 4 == 0;
    if !sp_ok {
        return Err(ElfError::BadStackPointer {
            sp,
            ram: map.ram.to_string(),
        });
    }
    if reset & 1 == 0 || !map.flash.contains(u64::from(reset & !1)) {
        return Err(ElfError::BadResetVector { reset });
    }
    image.initial_sp = sp;
    image.reset_vector = reset;

    image.identity = identity(&file, &image);
    image.rtt_address = symbol(&file, RTT_SYMBOL)
        .map(|(addr, _)| addr)
        .and_then(|a| u32::try_from(a).ok());
    Ok(image)
}

/// Readable architecture for a `object::Architecture` debug name.
fn arch_name(debug: &str) -> String {
    match debug {
        "X86_64" | "X86_64_X32" => "x86-64".into(),
        "I386" => "x86".into(),
        "Aarch64" | "Aarch64_Ilp32" => "AArch64 (64-bit ARM)".into(),
        "Arm" => "ARM".into(),
        "Riscv32" | "Riscv64" => "RISC-V".into(),
        other => other.to_owned(),
    }
}

/// Loadable data at `[start, end)` must lie in program flash, clear of the store.
fn check_flash(map: &MemoryMap, start: u64, end: u64) -> Result<(), ElfError> {
    if map.storage.overlaps(start, end) {
        return Err(ElfError::OverlapsStorage {
            start,
            end,
            storage: map.storage.to_string(),
        });
    }
    if !map.flash.contains_range(start, end) {
        return Err(ElfError::OutsideFlash {
            start,
            end,
            flash: map.flash.to_string(),
        });
    }
    Ok(())
}

/// A defined symbol's address and size.
fn symbol(file: &ElfFile32<'_, Endianness>, name: &str) -> Option<(u64, u64)> {
    file.symbols()
        .find(|s| s.name() == Ok(name) && !s.is_undefined())
        .map(|s| (s.address(), s.size()))
}

/// The identity record: at its symbol, else searched for in the programmed bytes.
fn identity(file: &ElfFile32<'_, Endianness>, image: &FirmwareImage) -> Option<BuildIdentity> {
    if let Some((addr, size)) = symbol(file, IDENTITY_SYMBOL)
        && let Some(bytes) = image.read(addr, usize::try_from(size).ok()?)
        && let Some(id) = BuildIdentity::parse(bytes)
    {
        return Some(id);
    }
    image
        .segments
        .iter()
        .find_map(|s| BuildIdentity::find_in(&s.data))
}

/// `Tag_CPU_arch` from the `.ARM.attributes` section, when present and readable.
fn cpu_arch(file: &ElfFile32<'_, Endianness>) -> Option<u64> {
    let data = file.section_by_name(".ARM.attributes")?.data().ok()?;
    let mut rest = data.strip_prefix(b"A")?;
    // Vendor subsections: u32 length (itself included), NUL-terminated vendor name, body.
    while rest.len() >= 4 {
        let len = u32::from_le_bytes(rest[..4].try_into().ok()?) as usize;
        let sub = rest.get(4..len)?;
        rest = &rest[len.max(4)..];
        let nul = sub.iter().position(|&b| b == 0)?;
        if &sub[..nul] != b"aeabi" {
            continue;
        }
        let mut body = &sub[nul + 1..];
        // Sub-subsections: tag (1 = whole file), u32 length, attributes.
        while body.len() >= 5 {
            let tag = body[0];
            let len = u32::from_le_bytes(body[1..5].try_into().ok()?) as usize;
            let attrs = body.get(5..len)?;
            body = &body[len.max(5)..];
            if tag == 1 {
                return find_cpu_arch(attrs);
            }
        }
    }
    None
}

/// Walks `tag value` pairs to `Tag_CPU_arch` (6).
fn find_cpu_arch(mut attrs: &[u8]) -> Option<u64> {
    while !attrs.is_empty() {
        let tag = uleb(&mut attrs)?;
        match tag {
            6 => return uleb(&mut attrs),
            // NUL-terminated strings: CPU_raw_name, CPU_name, conformance.
            4 | 5 | 67 => {
                let nul = attrs.iter().position(|&b| b == 0)?;
                attrs = &attrs[nul + 1..];
            }
            // Tag_compatibility: a number then a string.
            32 => {
                uleb(&mut attrs)?;
                let nul = attrs.iter().position(|&b| b == 0)?;
                attrs = &attrs[nul + 1..];
            }
            // Unknown tags >= 32 follow the parity rule: odd = string, even = number.
            t if t >= 32 && t % 2 == 1 => {
                let nul = attrs.iter().position(|&b| b == 0)?;
                attrs = &attrs[nul + 1..];
            }
            _ => {
                uleb(&mut attrs)?;
            }
        }
    }
    None
}

/// Reads one unsigned LEB128 number.
fn uleb(bytes: &mut &[u8]) -> Option<u64> {
    let mut value = 0u64;
    for (i, &b) in bytes.iter().enumerate().take(10) {
        value |= u64::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            *bytes = &bytes[i + 1..];
            return Some(value);
        }
    }
    None
}

#[cfg(test)]
#[path = "../../tests/support/tiny_elf.rs"]
mod tiny_elf;

#[cfg(test)]
mod tests {
    use super::tiny_elf::{self, EM_ARM, FLASH, STACK_TOP, STORAGE, Seg};
    use super::*;

    fn map() -> MemoryMap {
        MemoryMap::board().unwrap()
    }

    fn vectors(sp: u32, reset: u32) -> Vec<u8> {
        let mut v = sp.to_le_bytes().to_vec();
        v.extend_from_slice(&reset.to_le_bytes());
        v.resize(0x40, 0);
        v
    }

    #[test]
    fn a_cortex_m_image_passes_and_is_described() {
        let image = validate(&tiny_elf::cortex_m(1000), &map()).unwrap();
        assert_eq!(image.initial_sp, STACK_TOP);
        assert_eq!(image.reset_vector, FLASH + 0x1d9);
        assert_eq!(image.entry, image.reset_vector);
        assert_eq!(image.start(), FLASH);
        // vectors + code + .data's initial values (loaded in flash, copied to RAM at boot)
        assert_eq!(image.size(), 0x1d8 + 1000 + 4);
        assert_eq!(image.segments.len(), 3);
        let id = image.identity.unwrap();
        assert_eq!(
            (id.version.as_str(), id.build.as_str()),
            ("9.8.7", "tiny000001")
        );
        assert!(!image.has_defmt && image.rtt_address.is_none());
    }

    #[test]
    fn a_host_program_is_refused_by_name() {
        let me = std::fs::read(std::env::current_exe().unwrap()).unwrap();
        let e = validate(&me, &map()).unwrap_err();
        assert!(matches!(e, ElfError::WrongMachine { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("64-bit") && text.contains("not the firmware"),
            "{text}"
        );
        let x86 = tiny_elf::build(3, 0x1000, &[Seg::flash(0x1000, vec![0; 8])], None);
        assert!(
            validate(&x86, &map())
                .unwrap_err()
                .to_string()
                .contains("e_machine 3")
        );
    }

    #[test]
    fn non_elf_files_say_what_they_look_like() {
        let e = validate(b"#!/bin/sh\necho hi\n", &map()).unwrap_err();
        assert!(e.to_string().contains("text"), "{e}");
        let e = validate(&[], &map()).unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e = validate(&[0x00, 0x80, 0x01, 0x20, 0xd9, 0x01, 0x00, 0x08], &map()).unwrap_err();
        assert!(e.to_string().contains(".bin"), "{e}");
    }

    #[test]
    fn an_image_reaching_into_the_calibration_store_is_refused() {
        let e = validate(&tiny_elf::cortex_m_into_storage(256), &map()).unwrap_err();
        match &e {
            ElfError::OverlapsStorage { start, end, .. } => {
                assert_eq!(*start, u64::from(FLASH + 0x1d8));
                assert_eq!(*end, u64::from(STORAGE) + 256);
            }
            other => panic!("{other}"),
        }
        assert!(
            e.to_string()
                .contains("calibration store 0x0807c000..0x08080000")
        );
    }

    #[test]
    fn an_image_ending_exactly_at_the_store_passes() {
        // Code up to STORAGE - 8 leaves room for the 4 bytes of .data (8-aligned).
        let reset = FLASH + 0x1d8;
        let bytes = tiny_elf::cortex_m((STORAGE - 8 - reset) as usize);
        let image = validate(&bytes, &map()).unwrap();
        assert!(image.end() <= u64::from(STORAGE));
    }

    #[test]
    fn data_outside_flash_or_ram_is_refused() {
        let segs = [
            Seg::flash(FLASH, vectors(STACK_TOP, FLASH + 0x41)),
            Seg::flash(0x0900_0000, vec![0; 16]),
        ];
        let e = validate(
            &tiny_elf::build(EM_ARM, FLASH + 0x41, &segs, Some(13)),
            &map(),
        )
        .unwrap_err();
        assert!(matches!(e, ElfError::OutsideFlash { .. }), "{e}");
        let segs = [
            Seg::flash(FLASH, vectors(STACK_TOP, FLASH + 0x41)),
            Seg {
                paddr: 0x3000_0000,
                vaddr: 0x3000_0000,
                data: Vec::new(),
                memsz: 64,
            },
        ];
        let e = validate(
            &tiny_elf::build(EM_ARM, FLASH + 0x41, &segs, Some(13)),
            &map(),
        )
        .unwrap_err();
        assert!(matches!(e, ElfError::OutsideRam { .. }), "{e}");
    }

    #[test]
    fn entry_vector_table_and_architecture_are_checked() {
        let ok = |sp, reset, entry, arch| {
            let segs = [Seg::flash(FLASH, vectors(sp, reset))];
            validate(&tiny_elf::build(EM_ARM, entry, &segs, arch), &map())
        };
        assert!(ok(STACK_TOP, FLASH + 0x41, FLASH + 0x41, Some(13)).is_ok());
        // No attributes section: the other checks still apply.
        assert!(ok(STACK_TOP, FLASH + 0x41, FLASH + 0x41, None).is_ok());
        let e = ok(STACK_TOP, FLASH + 0x41, FLASH + 0x40, Some(13)).unwrap_err();
        assert!(matches!(e, ElfError::BadEntry { .. }), "{e}");
        let e = ok(0x0800_1000, FLASH + 0x41, FLASH + 0x41, Some(13)).unwrap_err();
        assert!(matches!(e, ElfError::BadStackPointer { .. }), "{e}");
        let e = ok(STACK_TOP, FLASH + 0x40, FLASH + 0x41, Some(13)).unwrap_err();
        assert!(matches!(e, ElfError::BadResetVector { .. }), "{e}");
        let e = ok(STACK_TOP, 0x2000_0001, FLASH + 0x41, Some(13)).unwrap_err();
        assert!(matches!(e, ElfError::BadResetVector { .. }), "{e}");
        let e = ok(STACK_TOP, FLASH + 0x41, FLASH + 0x41, Some(11)).unwrap_err();
        assert!(e.to_string().contains("ARMv6-M"), "{e}");
        // A table elsewhere than the start of flash does not boot.
        let segs = [Seg::flash(
            FLASH + 0x1000,
            vectors(STACK_TOP, FLASH + 0x1041),
        )];
        let e = validate(
            &tiny_elf::build(EM_ARM, FLASH + 0x1041, &segs, Some(13)),
            &map(),
        )
        .unwrap_err();
        assert!(matches!(e, ElfError::NoVectorTable { .. }), "{e}");
    }
}
