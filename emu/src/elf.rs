//! The firmware ELF: its loadable segments and its symbols.

use std::collections::BTreeMap;
use std::path::Path;

use object::{Object, ObjectSegment, ObjectSymbol, SymbolKind};

use crate::EmuError;

/// An image ready to load.
#[derive(Debug, Clone)]
pub struct Image {
    /// (physical address, bytes) of each loadable segment.
    pub segments: Vec<(u32, Vec<u8>)>,
    /// Function symbols by start address (Thumb bit cleared): (end, name).
    pub functions: BTreeMap<u32, (u32, String)>,
    /// Every symbol's address by name.
    pub symbols: BTreeMap<String, u32>,
}

impl Image {
    /// Reads the ELF at `path`.
    pub fn load(path: &Path) -> Result<Self, EmuError> {
        let bad = |why: String| EmuError::Image {
            path: path.display().to_string(),
            why,
        };
        let data = std::fs::read(path).map_err(|e| bad(format!("cannot read it: {e}")))?;
        let file = object::File::parse(&*data).map_err(|e| {
            bad(format!(
                "not an ELF file ({e}); give the firmware ELF `cargo xtask firmware` builds"
            ))
        })?;
        if file.architecture() != object::Architecture::Arm {
            return Err(bad(format!(
                "built for {:?}, not for the Cortex-M4 (thumbv7em-none-eabihf)",
                file.architecture()
            )));
        }
        let mut segments = Vec::new();
        for seg in file.segments() {
            let bytes = seg.data().map_err(|e| bad(e.to_string()))?;
            if bytes.is_empty() {
                continue;
            }
            // Load at the physical address (.data's initial values sit in flash).
            let (offset, _) = seg.file_range();
            let paddr = load_address(&data, offset).unwrap_or(seg.address());
            let addr = u32::try_from(paddr).map_err(|_| bad(format!("segment at {paddr:#x}")))?;
            segments.push((addr, bytes.to_vec()));
        }
        if segments.is_empty() {
            return Err(bad("no loadable segments".into()));
        }
        let mut functions = BTreeMap::new();
        let mut symbols = BTreeMap::new();
        for s in file.symbols() {
            let Ok(name) = s.name() else { continue };
            let addr = s.address() as u32;
            symbols.insert(name.to_string(), addr);
            if s.kind() == SymbolKind::Text {
                let start = addr & !1;
                functions.insert(start, (start + s.size().max(1) as u32, name.to_string()));
            }
        }
        Ok(Self {
            segments,
            functions,
            symbols,
        })
    }

    /// The function containing `pc`, demangled loosely (its mangled name).
    pub fn function_at(&self, pc: u32) -> Option<&str> {
        let (_, (end, name)) = self.functions.range(..=pc & !1).next_back()?;
        (pc & !1 < *end).then_some(name.as_str())
    }
}

/// The physical address of the program header whose file offset is `offset` (ELF32, LE).
fn load_address(data: &[u8], offset: u64) -> Option<u64> {
    let u32_at = |at: usize| -> Option<u32> {
        Some(u32::from_le_bytes(data.get(at..at + 4)?.try_into().ok()?))
    };
    let u16_at = |at: usize| -> Option<u16> {
        Some(u16::from_le_bytes(data.get(at..at + 2)?.try_into().ok()?))
    };
    let phoff = u32_at(28)? as usize;
    let phentsize = u16_at(42)? as usize;
    let phnum = u16_at(44)? as usize;
    for k in 0..phnum {
        let ph = phoff + k * phentsize;
        if u32_at(ph)? == 1 && u64::from(u32_at(ph + 4)?) == offset {
            return Some(u64::from(u32_at(ph + 12)?));
        }
    }
    None
}
