//! Small ELF files for the image checks, written byte by byte after the ELF specification
//! (ELF32 header, program headers, optional `.ARM.attributes`), so a test can make exactly
//! the image it needs: a valid Cortex-M one, one overlapping the calibration store, one for
//! another architecture.
#![allow(dead_code)]

/// A loadable segment: `data` programmed at `paddr`, living at `vaddr` (`memsz` bytes).
pub struct Seg {
    /// Load (flash) address.
    pub paddr: u32,
    /// Run-time address.
    pub vaddr: u32,
    /// Bytes in the file.
    pub data: Vec<u8>,
    /// Bytes at run time (>= data.len(); more for .bss).
    pub memsz: u32,
}

impl Seg {
    /// Data that lives where it is loaded (code, read-only data).
    pub fn flash(addr: u32, data: Vec<u8>) -> Self {
        let memsz = data.len() as u32;
        Self {
            paddr: addr,
            vaddr: addr,
            data,
            memsz,
        }
    }
}

/// `EM_ARM`.
pub const EM_ARM: u16 = 40;
/// `EM_X86_64`.
pub const EM_X86_64: u16 = 62;

fn u16le(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}
fn u32le(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// An `.ARM.attributes` section body naming `cpu_arch` (13 = ARMv7E-M, 11 = ARMv6-M).
fn arm_attributes(cpu_arch: u8) -> Vec<u8> {
    // Tag_conformance "2.09", Tag_CPU_arch, Tag_CPU_arch_profile 'M'.
    let attrs = [&[67u8][..], b"2.09\0", &[6, cpu_arch, 7, b'M']].concat();
    let mut file_sub = vec![1u8];
    u32le(&mut file_sub, 5 + attrs.len() as u32);
    file_sub.extend_from_slice(&attrs);
    let mut vendor = Vec::new();
    u32le(&mut vendor, 4 + 6 + file_sub.len() as u32);
    vendor.extend_from_slice(b"aeabi\0");
    vendor.extend_from_slice(&file_sub);
    [&b"A"[..], &vendor].concat()
}

/// An executable ELF32 little-endian file for `machine` with `segs` and `entry`.
pub fn build(machine: u16, entry: u32, segs: &[Seg], cpu_arch: Option<u8>) -> Vec<u8> {
    const EHDR: u32 = 52;
    const PHDR: u32 = 32;
    const SHDR: u32 = 40;
    let phoff = EHDR;
    let mut data_off = phoff + PHDR * segs.len() as u32;
    let mut offsets = Vec::new();
    for s in segs {
        data_off = data_off.next_multiple_of(4);
        offsets.push(data_off);
        data_off += s.data.len() as u32;
    }
    let attrs = cpu_arch.map(arm_attributes);
    let shstrtab = b"\0.ARM.attributes\0.shstrtab\0".to_vec();
    let attrs_off = data_off.next_multiple_of(4);
    let attrs_len = attrs.as_ref().map_or(0, |a| a.len() as u32);
    let shstr_off = attrs_off + attrs_len;
    let shoff = (shstr_off + shstrtab.len() as u32).next_multiple_of(4);
    let shnum: u16 = if attrs.is_some() { 3 } else { 2 };

    let mut out = Vec::new();
    out.extend_from_slice(&[0x7f, b'E', b'L', b'F', 1, 1, 1, 0]);
    out.extend_from_slice(&[0; 8]);
    u16le(&mut out, 2); // ET_EXEC
    u16le(&mut out, machine);
    u32le(&mut out, 1);
    u32le(&mut out, entry);
    u32le(&mut out, phoff);
    u32le(&mut out, shoff);
    u32le(&mut out, 0x0500_0400); // EABI5, hard float
    u16le(&mut out, EHDR as u16);
    u16le(&mut out, PHDR as u16);
    u16le(&mut out, segs.len() as u16);
    u16le(&mut out, SHDR as u16);
    u16le(&mut out, shnum);
    u16le(&mut out, shnum - 1); // .shstrtab is the last section
    for (s, off) in segs.iter().zip(&offsets) {
        u32le(&mut out, 1); // PT_LOAD
        u32le(&mut out, *off);
        u32le(&mut out, s.vaddr);
        u32le(&mut out, s.paddr);
        u32le(&mut out, s.data.len() as u32);
        u32le(&mut out, s.memsz.max(s.data.len() as u32));
        u32le(&mut out, 5); // R + X
        u32le(&mut out, 4);
    }
    for (s, off) in segs.iter().zip(&offsets) {
        out.resize(*off as usize, 0);
        out.extend_from_slice(&s.data);
    }
    out.resize(attrs_off as usize, 0);
    if let Some(a) = &attrs {
        out.extend_from_slice(a);
    }
    out.extend_from_slice(&shstrtab);
    out.resize(shoff as usize, 0);
    let section = |out: &mut Vec<u8>, name: u32, kind: u32, off: u32, size: u32| {
        for v in [name, kind, 0, 0, off, size, 0, 0, 1, 0] {
            u32le(out, v);
        }
    };
    section(&mut out, 0, 0, 0, 0);
    if attrs.is_some() {
        section(&mut out, 1, 0x7000_0003, attrs_off, attrs_len); // SHT_ARM_ATTRIBUTES
    }
    section(&mut out, 17, 3, shstr_off, shstrtab.len() as u32); // SHT_STRTAB
    out
}

/// Flash origin of the board.
pub const FLASH: u32 = 0x0800_0000;
/// Top of the board's RAM (the initial stack pointer).
pub const STACK_TOP: u32 = 0x2001_8000;
/// Start of the calibration store.
pub const STORAGE: u32 = 0x0807_C000;

/// A Cortex-M image as the firmware's linker lays it out: vector table at the start of
/// flash (initial SP at the top of RAM, reset handler right after the table), a little
/// code with the identity record, and `.data` loaded in flash for RAM. `code_len` pads the
/// code to make the image as long as a test needs.
pub fn cortex_m(code_len: usize) -> Vec<u8> {
    let reset = FLASH + 0x1d8;
    let mut vectors = Vec::new();
    u32le(&mut vectors, STACK_TOP);
    u32le(&mut vectors, reset | 1);
    vectors.resize(0x1d8, 0);
    let mut code = b"rig firmware 9.8.7 build tiny000001\0".to_vec();
    code.resize(code_len.max(code.len()), 0xbf); // filler bytes
    let text_end = reset + code.len() as u32;
    let segs = [
        Seg::flash(FLASH, vectors),
        Seg::flash(reset, code),
        Seg {
            paddr: text_end.next_multiple_of(8),
            vaddr: 0x2000_0000,
            data: vec![1, 2, 3, 4],
            memsz: 4,
        },
        Seg {
            paddr: 0x2000_0004,
            vaddr: 0x2000_0004,
            data: Vec::new(),
            memsz: 0x100,
        },
    ];
    build(EM_ARM, reset | 1, &segs, Some(13))
}

/// The image of [`cortex_m`] made long enough that its code runs `overlap` bytes into the
/// calibration store.
pub fn cortex_m_into_storage(overlap: usize) -> Vec<u8> {
    let reset = FLASH + 0x1d8;
    cortex_m((STORAGE - reset) as usize + overlap)
}
