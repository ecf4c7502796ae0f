//! The calibration in flash: two slots (A/B), each one erase unit, written alternately.
//!
//! A slot holds one record, little-endian:
//!
//! ```text
//! 0   magic "RCAL"            4
//! 4   schema version u16      2   (STORAGE_SCHEMA, 2)
//! 6   payload length u16      2   (84)
//! 8   sequence u32            4   (the newer record wins; wrapping compare)
//! 12  calibration             84  (19 f32 and 4 u16 in protocol::RigParameters's field
//!                                  order, the four profile shifts last)
//! 96  CRC-32/ISO-HDLC of 0..96 4
//! 100 0xFF padding to 112
//! 112 commit marker           16  (written last, in a separate write)
//! ```
//!
//! Schema 1 (firmware before protocol v7) is the same without the shifts: payload 68, CRC
//! at 80, commit marker at 96. The schema in the header says where a slot's marker and CRC
//! are, so such a record is still read, as standard gears (zero shift); it is never read
//! with the other layout. Saving always writes schema 2 (firmware before v7 sees such a
//! slot as empty: no marker at 96).
//!
//! Saving erases the slot that does not hold the newest record, writes the body, reads it
//! back, then writes the commit marker. Power lost at any point leaves the previous record
//! intact in the other slot; a slot without its commit marker is ignored. A committed
//! record that fails its checks makes the load report [`ParametersStatus::Invalid`] (with
//! the paper's defaults) unless the other slot holds a good one.

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use protocol::{ParametersStatus, RigParameters};

/// Layout version of the stored record; bump on any change to the layout above.
pub const STORAGE_SCHEMA: u16 = 2;

const MAGIC: [u8; 4] = *b"RCAL";
const PAYLOAD_LEN: usize = 84;
const BODY_LEN: usize = 12 + PAYLOAD_LEN;
const CRC_END: usize = BODY_LEN + 4;
const COMMIT_AT: usize = 112;

/// Where a record of one schema keeps its CRC and commit marker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    schema: u16,
    payload_len: usize,
    commit_at: usize,
}

impl Layout {
    /// What [`CalibrationStore::save`] writes.
    const CURRENT: Self = Self {
        schema: STORAGE_SCHEMA,
        payload_len: PAYLOAD_LEN,
        commit_at: COMMIT_AT,
    };
    /// Schema 1, before the profile shifts (read as zero shift).
    const SCHEMA_1: Self = Self {
        schema: 1,
        payload_len: 68,
        commit_at: 96,
    };

    /// The layout the header's schema field names; any other value is read as the current
    /// one (and then fails its header check).
    fn of(schema: u16) -> Self {
        if schema == Self::SCHEMA_1.schema {
            Self::SCHEMA_1
        } else {
            Self::CURRENT
        }
    }

    const fn body_len(self) -> usize {
        12 + self.payload_len
    }
}
const _: () = assert!(Layout::SCHEMA_1.body_len() + 4 <= Layout::SCHEMA_1.commit_at);
const _: () = assert!(Layout::SCHEMA_1.commit_at + COMMIT.len() <= RECORD_LEN);
/// [`PAYLOAD_LEN`] and [`COMMIT_AT`] as the record's u16 field and a flash offset.
#[allow(
    clippy::cast_possible_truncation,
    reason = "small constants, asserted below"
)]
const PAYLOAD_LEN_U16: u16 = PAYLOAD_LEN as u16;
#[allow(
    clippy::cast_possible_truncation,
    reason = "small constants, asserted below"
)]
const COMMIT_AT_U32: u32 = COMMIT_AT as u32;
const _: () = assert!(PAYLOAD_LEN < COMMIT_AT);
const _: () = assert!(COMMIT_AT <= 0xFFFF);
const COMMIT: [u8; 16] = *b"RCAL-COMMITTED!\n";
const RECORD_LEN: usize = COMMIT_AT + COMMIT.len();

/// The record's CRC-32/ISO-HDLC (the frames' checksum: a 64-byte nibble table on the
/// target, shared with the framing, rather than a second, bitwise implementation).
fn crc32(bytes: &[u8]) -> u32 {
    protocol::crc32::checksum(bytes)
}

/// Why a save failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageError {
    /// The flash reported an error.
    Flash(NorFlashErrorKind),
    /// The region is smaller than two erase units, or an erase unit than a record.
    RegionTooSmall,
    /// What was read back differs from what was written.
    Verify,
}

/// What [`CalibrationStore::load`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Loaded {
    /// The calibration to use (the paper's when nothing valid is stored).
    pub calibration: RigParameters,
    /// Where it came from.
    pub status: ParametersStatus,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    Empty,
    Corrupt,
    Valid {
        seq: u32,
        calibration: RigParameters,
    },
}

/// The calibration store on a flash region of at least two erase units.
#[derive(Debug)]
pub struct CalibrationStore<F> {
    flash: F,
    newest: Option<(usize, u32)>,
    ecc_error: fn() -> bool,
}

/// No ECC reporting: reads never raise ECC errors.
fn no_ecc_error() -> bool {
    false
}

impl<F: NorFlash> CalibrationStore<F> {
    /// A store on `flash` (offset 0 is the region's start).
    pub fn new(flash: F) -> Self {
        Self::with_ecc_check(flash, no_ecc_error)
    }

    /// A store whose reads are checked for flash ECC errors: `ecc_error` returns (and
    /// clears) whether a double-ECC error was raised since it was last called. On the
    /// STM32G4 a double error in a torn program unit raises the NMI; the binary's NMI
    /// handler recognises FLASH_ECCR.ECCD in the storage region, records it in a flag this
    /// function takes, and returns, so boot does not hang: the slot being read counts as
    /// corrupt and the other slot (or the defaults) is used.
    pub fn with_ecc_check(flash: F, ecc_error: fn() -> bool) -> Self {
        Self {
            flash,
            newest: None,
            ecc_error,
        }
    }

    /// Gives the flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    fn slot_offset(slot: usize) -> u32 {
        // Two slots of a page: far below 4 GiB (an impossible overflow fails the flash call).
        u32::try_from(slot * F::ERASE_SIZE).unwrap_or(u32::MAX)
    }

    fn fits(&self) -> bool {
        const { assert!(COMMIT_AT.is_multiple_of(16)) };
        F::ERASE_SIZE >= RECORD_LEN
            && self.flash.capacity() >= 2 * F::ERASE_SIZE
            && 16usize.is_multiple_of(F::WRITE_SIZE)
            && 16usize.is_multiple_of(F::READ_SIZE)
    }

    fn read_slot(&mut self, slot: usize) -> Slot {
        let mut record = [0u8; RECORD_LEN];
        // A stale flag from before this read is not this slot's.
        let _ = (self.ecc_error)();
        let read = self.flash.read(Self::slot_offset(slot), &mut record);
        if read.is_err() || (self.ecc_error)() {
            return Slot::Corrupt;
        }
        // The schema says where the marker is; a torn header (still erased) finds none.
        let layout = Layout::of(u16::from_le_bytes([record[4], record[5]]));
        if record[layout.commit_at..layout.commit_at + COMMIT.len()] != COMMIT {
            return Slot::Empty;
        }
        let body = layout.body_len();
        let crc = u32::from_le_bytes([
            record[body],
            record[body + 1],
            record[body + 2],
            record[body + 3],
        ]);
        let header_ok = record[..4] == MAGIC
            && u16::from_le_bytes([record[4], record[5]]) == layout.schema
            && usize::from(u16::from_le_bytes([record[6], record[7]])) == layout.payload_len;
        if !header_ok || crc32(&record[..body]) != crc {
            return Slot::Corrupt;
        }
        // Schema 1's payload is schema 2's without the shifts at its end: zero bytes there
        // read as 0.0, standard gears.
        let mut payload = [0u8; PAYLOAD_LEN];
        payload[..layout.payload_len].copy_from_slice(&record[12..body]);
        let calibration = decode(&payload);
        if calibration.validate().is_err() {
            return Slot::Corrupt;
        }
        let seq = u32::from_le_bytes([record[8], record[9], record[10], record[11]]);
        Slot::Valid { seq, calibration }
    }

    /// Reads both slots: the newest valid record, or the paper's defaults with
    /// `Defaults` (nothing stored) or `Invalid` (something stored failed its checks).
    pub fn load(&mut self) -> Loaded {
        self.newest = None;
        let defaults = |status| Loaded {
            calibration: RigParameters::paper(),
            status,
        };
        if !self.fits() {
            return defaults(ParametersStatus::Invalid);
        }
        let slots = [self.read_slot(0), self.read_slot(1)];
        let mut best: Option<(usize, u32, RigParameters)> = None;
        for (i, slot) in slots.iter().enumerate() {
            if let Slot::Valid { seq, calibration } = *slot {
                let newer = best.is_none_or(|(_, b, _)| seq.wrapping_sub(b).cast_signed() > 0);
                if newer {
                    best = Some((i, seq, calibration));
                }
            }
        }
        match best {
            Some((slot, seq, calibration)) => {
                self.newest = Some((slot, seq));
                Loaded {
                    calibration,
                    status: ParametersStatus::Valid,
                }
            }
            None if slots.contains(&Slot::Corrupt) => defaults(ParametersStatus::Invalid),
            None => defaults(ParametersStatus::Defaults),
        }
    }

    /// Stores `calibration` as the newest record (call [`CalibrationStore::load`] first).
    pub fn save(&mut self, calibration: &RigParameters) -> Result<(), StorageError> {
        if !self.fits() {
            return Err(StorageError::RegionTooSmall);
        }
        let (slot, seq) = match self.newest {
            Some((newest, seq)) => (1 - newest, seq.wrapping_add(1)),
            None => (0, 1),
        };
        let mut body = [0xFFu8; COMMIT_AT];
        body[..4].copy_from_slice(&MAGIC);
        body[4..6].copy_from_slice(&STORAGE_SCHEMA.to_le_bytes());
        body[6..8].copy_from_slice(&PAYLOAD_LEN_U16.to_le_bytes());
        body[8..12].copy_from_slice(&seq.to_le_bytes());
        encode(calibration, &mut body[12..BODY_LEN]);
        let crc = crc32(&body[..BODY_LEN]);
        body[BODY_LEN..CRC_END].copy_from_slice(&crc.to_le_bytes());

        let offset = Self::slot_offset(slot);
        let flash_err = |e: F::Error| StorageError::Flash(e.kind());
        self.flash
            .erase(
                offset,
                offset.saturating_add(u32::try_from(F::ERASE_SIZE).unwrap_or(u32::MAX)),
            )
            .map_err(flash_err)?;
        self.flash.write(offset, &body).map_err(flash_err)?;
        let mut check = [0u8; COMMIT_AT];
        self.flash.read(offset, &mut check).map_err(flash_err)?;
        if check != body {
            return Err(StorageError::Verify);
        }
        self.flash
            .write(offset + COMMIT_AT_U32, &COMMIT)
            .map_err(flash_err)?;
        self.newest = Some((slot, seq));
        Ok(())
    }
}

fn encode(c: &RigParameters, out: &mut [u8]) {
    let floats = [
        c.c1_nmm_per_a,
        c.c2_nmm,
        c.c3_nmm_s_per_rad,
        c.c4_nmm,
        c.c5_a_s_per_rad,
        c.c6_a,
    ];
    let rest = [
        c.module_mm,
        c.pressure_angle_deg,
        c.eccentricity_mm,
        c.carrier_mass_kg,
        c.mu_s,
        c.mu_d,
        c.max_release_load_nm,
        c.max_current_a,
        c.max_freq_hz,
    ];
    let mut w = 0;
    for v in floats {
        out[w..w + 4].copy_from_slice(&v.to_le_bytes());
        w += 4;
    }
    for z in c.z {
        out[w..w + 2].copy_from_slice(&z.to_le_bytes());
        w += 2;
    }
    for v in rest.into_iter().chain(c.profile_shift) {
        out[w..w + 4].copy_from_slice(&v.to_le_bytes());
        w += 4;
    }
}

/// The calibration in `b` (a schema 1 payload reads with its missing shifts as zeros).
fn decode(b: &[u8; PAYLOAD_LEN]) -> RigParameters {
    let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    let z = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    RigParameters {
        c1_nmm_per_a: f(0),
        c2_nmm: f(4),
        c3_nmm_s_per_rad: f(8),
        c4_nmm: f(12),
        c5_a_s_per_rad: f(16),
        c6_a: f(20),
        z: [z(24), z(26), z(28), z(30)],
        module_mm: f(32),
        pressure_angle_deg: f(36),
        eccentricity_mm: f(40),
        carrier_mass_kg: f(44),
        mu_s: f(48),
        mu_d: f(52),
        max_release_load_nm: f(56),
        max_current_a: f(60),
        max_freq_hz: f(64),
        profile_shift: [f(68), f(72), f(76), f(80)],
    }
}

/// A window `[base, base + len)` of a larger flash, addressed from 0: the binary's
/// STORAGE region of the whole-chip flash driver.
#[derive(Debug)]
pub struct Partition<F> {
    flash: F,
    base: u32,
    len: u32,
}

/// Errors of a [`Partition`]: the flash's own, or an access outside the window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartitionError<E> {
    /// The underlying flash failed.
    Flash(E),
    /// Offset or length outside the partition.
    OutOfBounds,
}

impl<E: NorFlashError> NorFlashError for PartitionError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::Flash(e) => e.kind(),
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
        }
    }
}

impl<F: NorFlash> Partition<F> {
    /// The window of `flash` from `base` (an offset in `flash`) for `len` bytes.
    pub fn new(flash: F, base: u32, len: u32) -> Self {
        Self { flash, base, len }
    }

    fn check(&self, offset: u32, len: usize) -> Result<u32, PartitionError<F::Error>> {
        let end = u64::from(offset) + len as u64;
        if end > u64::from(self.len) {
            return Err(PartitionError::OutOfBounds);
        }
        Ok(self.base + offset)
    }
}

impl<F: NorFlash> ErrorType for Partition<F> {
    type Error = PartitionError<F::Error>;
}

impl<F: NorFlash> ReadNorFlash for Partition<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = self.check(offset, bytes.len())?;
        self.flash.read(at, bytes).map_err(PartitionError::Flash)
    }

    fn capacity(&self) -> usize {
        self.len as usize
    }
}

impl<F: NorFlash> NorFlash for Partition<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let start = self.check(from, to.saturating_sub(from) as usize)?;
        self.flash
            .erase(start, start + (to - from))
            .map_err(PartitionError::Flash)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let at = self.check(offset, bytes.len())?;
        self.flash.write(at, bytes).map_err(PartitionError::Flash)
    }
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests;
