//! The firmware's flash calibration record (`firmware_core::storage`): arbitrary bytes as
//! the two slots of the store, then the same bytes as the payload of a well-formed,
//! committed record with a valid CRC (random bytes almost never pass the CRC and the
//! commit marker, so the payload decoder and the calibration checks see arbitrary input too).
//! Loading may never panic; a calibration it reports valid must pass the protocol's checks;
//! a valid calibration saved again must load back the same.
#![no_main]

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use firmware_core::storage::{CalibrationStore, STORAGE_SCHEMA};
use libfuzzer_sys::fuzz_target;
use protocol::ParametersStatus as CalibrationStatus;

/// One slot: a record is 112 bytes (see the layout in `firmware_core::storage`).
const SLOT: usize = 128;
/// The record layout, as `firmware_core::storage` documents it.
const PAYLOAD: usize = 68;
const BODY: usize = 12 + PAYLOAD;
const COMMIT_AT: usize = 96;
const COMMIT: &[u8; 16] = b"RCAL-COMMITTED!\n";

#[derive(Debug, Clone, Copy)]
struct OutOfBounds;

impl NorFlashError for OutOfBounds {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::OutOfBounds
    }
}

/// Two slots of NOR flash in RAM.
struct MemFlash(Vec<u8>);

impl ErrorType for MemFlash {
    type Error = OutOfBounds;
}

impl MemFlash {
    fn range(&self, offset: u32, len: usize) -> Result<std::ops::Range<usize>, OutOfBounds> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(OutOfBounds)?;
        if end > self.0.len() {
            return Err(OutOfBounds);
        }
        Ok(start..end)
    }
}

impl ReadNorFlash for MemFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), OutOfBounds> {
        let r = self.range(offset, bytes.len())?;
        bytes.copy_from_slice(&self.0[r]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.0.len()
    }
}

impl NorFlash for MemFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = SLOT;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), OutOfBounds> {
        let r = self.range(from, (to.saturating_sub(from)) as usize)?;
        self.0[r].fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), OutOfBounds> {
        let r = self.range(offset, bytes.len())?;
        // NOR programming only clears bits.
        for (cell, b) in self.0[r].iter_mut().zip(bytes) {
            *cell &= b;
        }
        Ok(())
    }
}

/// Loads the store on `flash`; checks what it reports, and that a valid calibration
/// survives being saved again.
fn check(flash: MemFlash) {
    let mut store = CalibrationStore::new(flash);
    let loaded = store.load();
    if loaded.status != CalibrationStatus::Valid {
        assert_eq!(loaded.calibration, protocol::RigParameters::paper());
        return;
    }
    assert!(loaded.calibration.validate().is_ok());
    store
        .save(&loaded.calibration)
        .expect("a RAM flash of two slots takes a save");
    let again = CalibrationStore::new(store.into_inner()).load();
    assert_eq!(again.status, CalibrationStatus::Valid);
    // Compare bits: a valid calibration has no NaN, but bits say exactly "the same".
    let bits = |c: &protocol::RigParameters| {
        protocol::encode_frame_vec(0, &protocol::Request::SetParameters(*c)).unwrap()
    };
    assert_eq!(bits(&again.calibration), bits(&loaded.calibration));
}

/// `payload` (padded with zeros) as slot 0's committed record with a valid CRC.
fn well_formed(seq: u32, payload: &[u8]) -> MemFlash {
    let mut flash = vec![0xFF; 2 * SLOT];
    let record = &mut flash[..SLOT];
    record[..4].copy_from_slice(b"RCAL");
    record[4..6].copy_from_slice(&STORAGE_SCHEMA.to_le_bytes());
    record[6..8].copy_from_slice(&(PAYLOAD as u16).to_le_bytes());
    record[8..12].copy_from_slice(&seq.to_le_bytes());
    record[12..BODY].fill(0);
    let n = payload.len().min(PAYLOAD);
    record[12..12 + n].copy_from_slice(&payload[..n]);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&record[..BODY]);
    record[BODY..BODY + 4].copy_from_slice(&crc.to_le_bytes());
    record[COMMIT_AT..COMMIT_AT + COMMIT.len()].copy_from_slice(COMMIT);
    MemFlash(flash)
}

fuzz_target!(|data: &[u8]| {
    let mut raw = vec![0xFF; 2 * SLOT];
    let n = data.len().min(raw.len());
    raw[..n].copy_from_slice(&data[..n]);
    check(MemFlash(raw));

    let seq = data
        .get(..4)
        .map_or(1, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    check(well_formed(seq, data.get(4..).unwrap_or(&[])));
});
