//! The board's memory layout, read from the workspace's `memory.x` (the one the firmware is
//! linked with), so the host checks images against the same numbers.

use std::fmt;

/// The workspace's linker memory layout, embedded at compile time.
pub const MEMORY_X: &str = include_str!("../../../memory.x");

/// One `MEMORY` region: `[origin, origin + length)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Region {
    /// First address.
    pub origin: u32,
    /// Size, bytes.
    pub length: u32,
}

impl Region {
    /// One past the last address.
    pub fn end(&self) -> u64 {
        u64::from(self.origin) + u64::from(self.length)
    }

    /// Whether `addr` lies in the region.
    pub fn contains(&self, addr: u64) -> bool {
        addr >= u64::from(self.origin) && addr < self.end()
    }

    /// Whether `[start, end)` lies wholly in the region (an empty range at its end counts).
    pub fn contains_range(&self, start: u64, end: u64) -> bool {
        start >= u64::from(self.origin) && end <= self.end() && start <= end
    }

    /// Whether `[start, end)` shares a byte with the region.
    pub fn overlaps(&self, start: u64, end: u64) -> bool {
        start < self.end() && end > u64::from(self.origin)
    }
}

impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#010x}..{:#010x}", self.origin, self.end())
    }
}

/// The regions `rig flash` needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct MemoryMap {
    /// Program flash (the image must fit here).
    pub flash: Region,
    /// The calibration store at the end of flash (never erased by `rig flash`).
    pub storage: Region,
    /// RAM (the initial stack pointer points into it).
    pub ram: Region,
}

impl MemoryMap {
    /// The board's layout from the embedded [`MEMORY_X`].
    pub fn board() -> Result<Self, String> {
        Self::parse(MEMORY_X).map_err(|e| format!("memory.x built into rig: {e}"))
    }

    /// Reads the `FLASH`, `STORAGE` and `RAM` regions of a linker script's `MEMORY` block
    /// (`NAME [(attrs)] : ORIGIN = 0x..., LENGTH = 16K`; hex or decimal, `K`/`M` suffixes).
    pub fn parse(script: &str) -> Result<Self, String> {
        let text = strip_comments(script);
        let start = text
            .find("MEMORY")
            .ok_or("no MEMORY block (expected `MEMORY { FLASH : ORIGIN = ..., LENGTH = ... }`)")?;
        let body = &text[start..];
        let open = body.find('{').ok_or("MEMORY block without `{`")?;
        let close = body.find('}').ok_or("MEMORY block without `}`")?;
        let body = &body[open + 1..close];
        let mut regions = Vec::new();
        for line in body.lines().map(str::trim).filter(|l| !l.is_empty()) {
            regions.push(parse_region(line)?);
        }
        let find = |name: &str| {
            regions
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, r)| *r)
                .ok_or_else(|| format!("MEMORY has no {name} region"))
        };
        let map = Self {
            flash: find("FLASH")?,
            storage: find("STORAGE")?,
            ram: find("RAM")?,
        };
        if map
            .flash
            .overlaps(u64::from(map.storage.origin), map.storage.end())
        {
            return Err(format!(
                "FLASH {} overlaps STORAGE {}: the calibration store must lie outside the program flash",
                map.flash, map.storage
            ));
        }
        Ok(map)
    }
}

/// Removes `/* ... */` and `// ...` comments.
fn strip_comments(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        rest = match rest[i + 2..].find("*/") {
            Some(j) => &rest[i + 2 + j + 2..],
            None => "",
        };
    }
    out.push_str(rest);
    out.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `FLASH (rx) : ORIGIN = 0x08000000, LENGTH = 496K` -> ("FLASH", region).
fn parse_region(line: &str) -> Result<(String, Region), String> {
    let (name, rest) = line
        .split_once(':')
        .ok_or_else(|| format!("`{line}`: expected `NAME : ORIGIN = ..., LENGTH = ...`"))?;
    let name = name.split('(').next().unwrap_or("").trim().to_owned();
    let mut origin = None;
    let mut length = None;
    for part in rest.split(',') {
        let Some((key, value)) = part.split_once('=') else {
            continue;
        };
        let key = key.trim().to_ascii_uppercase();
        let v = parse_number(value.trim()).map_err(|e| format!("{name} {key}: {e}"))?;
        match key.as_str() {
            "ORIGIN" | "ORG" | "O" => origin = Some(v),
            "LENGTH" | "LEN" | "L" => length = Some(v),
            _ => {}
        }
    }
    let origin = origin.ok_or_else(|| format!("{name}: no ORIGIN"))?;
    let length = length.ok_or_else(|| format!("{name}: no LENGTH"))?;
    let region = Region {
        origin: u32::try_from(origin).map_err(|_| format!("{name}: ORIGIN beyond 32 bits"))?,
        length: u32::try_from(length).map_err(|_| format!("{name}: LENGTH beyond 32 bits"))?,
    };
    if region.end() > 1 << 32 {
        return Err(format!("{name}: ends beyond the 32-bit address space"));
    }
    Ok((name, region))
}

/// `0x0807C000`, `16K`, `1M`, `4096`.
fn parse_number(s: &str) -> Result<u64, String> {
    let (digits, scale) = match s.chars().last() {
        Some('K' | 'k') => (&s[..s.len() - 1], 1024),
        Some('M' | 'm') => (&s[..s.len() - 1], 1024 * 1024),
        _ => (s, 1),
    };
    let digits = digits.trim();
    let v = if let Some(hex) = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        u64::from_str_radix(hex, 16)
    } else {
        digits.parse()
    }
    .map_err(|_| format!("`{s}` is not a number (hex 0x..., decimal, optional K or M)"))?;
    v.checked_mul(scale)
        .ok_or_else(|| format!("`{s}` is too large"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_workspace_memory_x_is_the_g474re() {
        let m = MemoryMap::board().unwrap();
        assert_eq!(
            m.flash,
            Region {
                origin: 0x0800_0000,
                length: 496 * 1024
            }
        );
        assert_eq!(
            m.storage,
            Region {
                origin: 0x0807_C000,
                length: 16 * 1024
            }
        );
        assert_eq!(
            m.ram,
            Region {
                origin: 0x2000_0000,
                length: 96 * 1024
            }
        );
        // The store is the last 16 KiB of the 512 KiB part, right after the program flash.
        assert_eq!(m.flash.end(), u64::from(m.storage.origin));
        assert_eq!(m.storage.end(), 0x0808_0000);
    }

    #[test]
    fn attributes_comments_and_units_are_understood() {
        let m = MemoryMap::parse(
            "/* a */ MEMORY {\n FLASH (rx) : ORIGIN = 0x0, LENGTH = 1M // x\n \
             STORAGE : ORIGIN = 1048576, LENGTH = 4k\n RAM (rwx) : org = 0x20000000, len = 8K\n}",
        )
        .unwrap();
        assert_eq!(m.flash.end(), 1 << 20);
        assert_eq!(m.storage.length, 4096);
        assert_eq!(m.ram.length, 8192);
    }

    #[test]
    fn bad_layouts_name_the_problem() {
        let e = MemoryMap::parse("MEMORY { FLASH : ORIGIN = 0, LENGTH = 8K }").unwrap_err();
        assert!(e.contains("STORAGE"), "{e}");
        let e = MemoryMap::parse(
            "MEMORY { FLASH : ORIGIN = 0, LENGTH = 8K\n STORAGE : ORIGIN = 4K, LENGTH = 8K\n RAM : ORIGIN = 0x20000000, LENGTH = 1K }",
        )
        .unwrap_err();
        assert!(e.contains("overlaps"), "{e}");
        let e = MemoryMap::parse("MEMORY { FLASH : ORIGIN = zz, LENGTH = 8K }").unwrap_err();
        assert!(e.contains("not a number"), "{e}");
        assert!(MemoryMap::parse("nothing").is_err());
    }
}
