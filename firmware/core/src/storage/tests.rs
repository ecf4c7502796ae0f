//! Storage tests on an in-memory NOR flash that can lose power at any program step.

use super::*;

const PAGE: usize = 2048;
const WRITE: usize = 8;
const REGION: usize = 8 * PAGE;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MemError {
    NotAligned,
    OutOfBounds,
    /// Programming over bytes that are not erased (the STM32's PROGERR).
    NotErased,
    /// Power is gone.
    PowerLost,
}

impl NorFlashError for MemError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            MemError::NotAligned => NorFlashErrorKind::NotAligned,
            MemError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// NOR flash in RAM, STM32G4-like: 2 KiB pages, 8-byte program units that must be erased
/// first. With `cut_at = Some(k)`, power fails during the k-th program step (one page
/// erase or one 8-byte unit): that step is left half done and everything after fails.
#[derive(Debug, Clone)]
struct MemFlash {
    data: Vec<u8>,
    steps: usize,
    cut_at: Option<usize>,
    /// Offsets of program units left half programmed (their ECC does not match).
    torn: Vec<usize>,
    /// Reading a torn unit raises a double-ECC error (the STM32G4's NMI), reported through
    /// [`take_ecc_error`].
    ecc_on_torn: bool,
}

std::thread_local! {
    static ECC_ERROR: core::cell::Cell<bool> = const { core::cell::Cell::new(false) };
}

/// The test's stand-in for the binary's NMI flag.
fn take_ecc_error() -> bool {
    ECC_ERROR.with(|f| f.replace(false))
}

impl MemFlash {
    fn new() -> Self {
        Self {
            data: vec![0xFF; REGION],
            steps: 0,
            cut_at: None,
            torn: Vec::new(),
            ecc_on_torn: false,
        }
    }

    /// The same chip after a power cycle.
    fn rebooted(&self) -> Self {
        Self {
            data: self.data.clone(),
            steps: 0,
            cut_at: None,
            torn: self.torn.clone(),
            ecc_on_torn: self.ecc_on_torn,
        }
    }

    /// Advances one program step; `Err` when power fails at (or has failed before) it.
    fn step(&mut self) -> Result<(), bool> {
        let k = self.steps;
        self.steps += 1;
        match self.cut_at {
            Some(cut) if k == cut => Err(true),
            Some(cut) if k > cut => Err(false),
            _ => Ok(()),
        }
    }
}

impl ErrorType for MemFlash {
    type Error = MemError;
}

impl ReadNorFlash for MemFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MemError> {
        let at = offset as usize;
        let src = self
            .data
            .get(at..at + bytes.len())
            .ok_or(MemError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        let end = at + bytes.len();
        if self.ecc_on_torn && self.torn.iter().any(|&u| u < end && u + WRITE > at) {
            ECC_ERROR.with(|f| f.set(true));
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.data.len()
    }
}

impl NorFlash for MemFlash {
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), MemError> {
        let (from, to) = (from as usize, to as usize);
        if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) || from > to {
            return Err(MemError::NotAligned);
        }
        if to > self.data.len() {
            return Err(MemError::OutOfBounds);
        }
        for page in (from..to).step_by(PAGE) {
            match self.step() {
                Ok(()) => {
                    self.data[page..page + PAGE].fill(0xFF);
                    self.torn.retain(|&u| u < page || u >= page + PAGE);
                }
                Err(cut_here) => {
                    if cut_here {
                        // Half erased: the rest keeps scrambled bits of the old contents.
                        for (i, b) in self.data[page..page + PAGE].iter_mut().enumerate() {
                            *b = if i < PAGE / 2 { 0xFF } else { *b ^ 0x5A };
                        }
                    }
                    return Err(MemError::PowerLost);
                }
            }
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), MemError> {
        let at = offset as usize;
        if !at.is_multiple_of(WRITE) || !bytes.len().is_multiple_of(WRITE) {
            return Err(MemError::NotAligned);
        }
        if at + bytes.len() > self.data.len() {
            return Err(MemError::OutOfBounds);
        }
        for (unit, chunk) in bytes.chunks(WRITE).enumerate() {
            let dst = at + unit * WRITE;
            if self.data[dst..dst + WRITE].iter().any(|&b| b != 0xFF) {
                return Err(MemError::NotErased);
            }
            match self.step() {
                Ok(()) => self.data[dst..dst + WRITE].copy_from_slice(chunk),
                Err(cut_here) => {
                    if cut_here {
                        // Half programmed: only some of the bits that should clear did.
                        for (d, &s) in self.data[dst..dst + WRITE].iter_mut().zip(chunk) {
                            *d = s | 0x0F;
                        }
                        self.torn.push(dst);
                    }
                    return Err(MemError::PowerLost);
                }
            }
        }
        Ok(())
    }
}

fn calibration(k: u16) -> RigParameters {
    RigParameters {
        c1_nmm_per_a: 60.0 + f32::from(k),
        max_release_load_nm: 1.0 + f32::from(k) * 0.1,
        ..RigParameters::paper()
    }
}

fn load(flash: &MemFlash) -> Loaded {
    CalibrationStore::new(flash.rebooted()).load()
}

#[test]
fn blank_flash_gives_defaults() {
    let loaded = load(&MemFlash::new());
    assert_eq!(loaded.status, ParametersStatus::Defaults);
    assert_eq!(loaded.calibration, RigParameters::paper());
}

#[test]
fn saves_alternate_slots_and_the_newest_wins() {
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    for k in 0..5 {
        store.save(&calibration(k)).unwrap();
        let flash = store.into_inner();
        let loaded = load(&flash);
        assert_eq!(loaded.status, ParametersStatus::Valid);
        assert_eq!(loaded.calibration, calibration(k));
        // Record k went to slot k % 2 with sequence k + 1.
        let slot = (k as usize % 2) * PAGE;
        assert_eq!(&flash.data[slot..slot + 4], b"RCAL");
        assert_eq!(flash.data[slot + 8], k as u8 + 1);
        store = CalibrationStore::new(flash);
        store.load();
    }
}

#[test]
fn sequence_compare_survives_wrapping() {
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    store.newest = Some((1, u32::MAX));
    store.save(&calibration(7)).unwrap();
    let flash = store.into_inner();
    assert_eq!(flash.data[8..12], 0u32.to_le_bytes());
    assert_eq!(load(&flash).calibration, calibration(7));
}

#[test]
fn power_cut_at_every_step_keeps_the_previous_calibration() {
    // Three generations, so both slots get overwritten once with a cut at every step.
    let mut flash = MemFlash::new();
    let mut previous: Option<RigParameters> = None;
    for generation in 0..3u16 {
        let next = calibration(generation);
        let mut cuts = 0;
        loop {
            let mut trial = flash.rebooted();
            trial.cut_at = Some(cuts);
            let mut store = CalibrationStore::new(trial);
            store.load();
            let result = store.save(&next);
            let after = store.into_inner();
            let loaded = load(&after);
            if result.is_ok() {
                assert_eq!(loaded.calibration, next);
                // The cut-free save completes; a rebooted chip keeps that state.
                flash = after;
                break;
            }
            match previous {
                Some(prev) => {
                    assert_eq!(loaded.status, ParametersStatus::Valid, "cut at {cuts}");
                    assert_eq!(loaded.calibration, prev, "cut at {cuts}");
                }
                // Nothing stored before: a torn first save is not a calibration.
                None => assert_eq!(loaded.status, ParametersStatus::Defaults, "cut at {cuts}"),
            }
            // After the cut, a full save from the torn state still works.
            let mut retry = CalibrationStore::new(after.rebooted());
            retry.load();
            retry.save(&next).unwrap();
            assert_eq!(load(&retry.into_inner()).calibration, next);
            cuts += 1;
        }
        // Erase + 14 body units + 2 commit units.
        assert_eq!(cuts, 17, "generation {generation}");
        previous = Some(next);
    }
}

#[test]
fn corrupt_record_is_invalid_unless_the_other_slot_is_good() {
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    store.save(&calibration(1)).unwrap();
    let mut flash = store.into_inner();
    flash.data[20] ^= 0x01; // a bit of C1 rots
    let loaded = load(&flash);
    assert_eq!(loaded.status, ParametersStatus::Invalid);
    assert_eq!(loaded.calibration, RigParameters::paper());

    // A second, good record in the other slot is used.
    let mut store = CalibrationStore::new(flash);
    store.load();
    store.save(&calibration(2)).unwrap();
    let loaded = load(&store.into_inner());
    assert_eq!(loaded.status, ParametersStatus::Valid);
    assert_eq!(loaded.calibration, calibration(2));
}

#[test]
fn other_schema_or_invalid_values_are_invalid() {
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    store.save(&calibration(1)).unwrap();
    let mut flash = store.into_inner();
    // A record of another layout version (CRC recomputed so only the version differs).
    flash.data[4] = 3;
    let crc = crc32(&flash.data[..BODY_LEN]);
    flash.data[BODY_LEN..CRC_END].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(load(&flash).status, ParametersStatus::Invalid);

    // A well-formed record whose values fail validation (mu_d > mu_s).
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    let bad = RigParameters {
        mu_d: 0.5,
        ..RigParameters::paper()
    };
    store.save(&bad).unwrap();
    assert_eq!(load(&store.into_inner()).status, ParametersStatus::Invalid);
}

/// A committed schema-1 record (firmware before the profile shifts) of `c` at `slot`, as
/// that firmware wrote it: payload 68 (no shifts), CRC over 0..80, marker at 96.
fn write_schema_1(flash: &mut MemFlash, slot: usize, seq: u32, c: &RigParameters) {
    let mut payload = [0u8; PAYLOAD_LEN];
    encode(c, &mut payload);
    let at = slot * PAGE;
    let r = &mut flash.data[at..at + PAGE];
    r.fill(0xFF);
    r[..4].copy_from_slice(b"RCAL");
    r[4..6].copy_from_slice(&1u16.to_le_bytes());
    r[6..8].copy_from_slice(&68u16.to_le_bytes());
    r[8..12].copy_from_slice(&seq.to_le_bytes());
    r[12..80].copy_from_slice(&payload[..68]);
    let crc = crc32(&r[..80]);
    r[80..84].copy_from_slice(&crc.to_le_bytes());
    r[96..112].copy_from_slice(&COMMIT);
}

#[test]
fn a_schema_1_record_reads_as_standard_gears_and_the_next_save_is_schema_2() {
    let old = RigParameters {
        z: [52, 48, 50, 50],
        ..calibration(4)
    };
    let mut flash = MemFlash::new();
    write_schema_1(&mut flash, 0, 7, &old);
    let loaded = load(&flash);
    assert_eq!(loaded.status, ParametersStatus::Valid);
    assert_eq!(loaded.calibration, old);
    assert_eq!(loaded.calibration.profile_shift, [0.0; 4]);

    // Saving a shifted gear writes schema 2 in the other slot; it wins (sequence 8), and
    // the old slot still reads as before.
    let shifted = RigParameters {
        z: [49, 51, 51, 50],
        profile_shift: [0.2, 0.3, 0.0, -0.017],
        ..calibration(5)
    };
    let mut store = CalibrationStore::new(flash);
    store.load();
    store.save(&shifted).unwrap();
    let flash = store.into_inner();
    assert_eq!(flash.data[PAGE + 4..PAGE + 6], STORAGE_SCHEMA.to_le_bytes());
    assert_eq!(flash.data[PAGE + 8], 8);
    assert_eq!(load(&flash).calibration, shifted);
    assert_eq!(
        CalibrationStore::new(flash).read_slot(0),
        Slot::Valid {
            seq: 7,
            calibration: old
        }
    );
}

#[test]
fn a_record_is_never_read_with_the_other_schemas_layout() {
    // A schema-2 record relabelled schema 1 (CRC and marker where schema 2 keeps them):
    // schema 1's marker place (96) holds the CRC, so the slot is empty, not misread.
    let mut store = CalibrationStore::new(MemFlash::new());
    store.load();
    store.save(&calibration(1)).unwrap();
    let mut flash = store.into_inner();
    flash.data[4] = 1;
    assert_eq!(load(&flash).status, ParametersStatus::Defaults);

    // A schema-1 record relabelled schema 2: no marker at 112, empty too.
    let mut flash = MemFlash::new();
    write_schema_1(&mut flash, 0, 1, &calibration(1));
    flash.data[4] = 2;
    assert_eq!(load(&flash).status, ParametersStatus::Defaults);

    // Schema 1's header with schema 2's payload length: corrupt, never decoded.
    let mut flash = MemFlash::new();
    write_schema_1(&mut flash, 0, 1, &calibration(1));
    flash.data[6] = 84;
    assert_eq!(load(&flash).status, ParametersStatus::Invalid);
}

#[test]
fn partition_offsets_and_bounds() {
    let mut p = Partition::new(MemFlash::new(), 4 * PAGE as u32, 2 * PAGE as u32);
    assert_eq!(p.capacity(), 2 * PAGE);
    let mut store = CalibrationStore::new(p);
    store.load();
    store.save(&calibration(3)).unwrap();
    p = store.into_inner();
    assert_eq!(&p.flash.data[4 * PAGE..4 * PAGE + 4], b"RCAL");
    assert_eq!(
        p.write(2 * PAGE as u32 - 8, &[0; 16]),
        Err(PartitionError::OutOfBounds)
    );
    assert_eq!(
        p.erase(PAGE as u32, 3 * PAGE as u32),
        Err(PartitionError::OutOfBounds)
    );
    let loaded = CalibrationStore::new(p).load();
    assert_eq!(loaded.calibration, calibration(3));
}

#[test]
fn too_small_a_region_refuses() {
    let p = Partition::new(MemFlash::new(), 0, PAGE as u32);
    let mut store = CalibrationStore::new(p);
    assert_eq!(store.load().status, ParametersStatus::Invalid);
    assert_eq!(
        store.save(&calibration(1)),
        Err(StorageError::RegionTooSmall)
    );
}

#[test]
fn torn_units_raising_ecc_errors_count_as_corrupt() {
    // A cut at every program step of the second generation's save, on a chip whose torn
    // units raise a double-ECC error when read: the torn slot counts as corrupt, and the
    // other slot's record is used.
    let mut flash = MemFlash::new();
    flash.ecc_on_torn = true;
    let mut store = CalibrationStore::with_ecc_check(flash, take_ecc_error);
    store.load();
    store.save(&calibration(1)).unwrap();
    let flash = store.into_inner();
    let mut ecc_seen = 0;
    for cut in 0..17 {
        let mut trial = flash.rebooted();
        trial.cut_at = Some(cut);
        let mut store = CalibrationStore::with_ecc_check(trial, take_ecc_error);
        store.load();
        assert!(store.save(&calibration(2)).is_err());
        let after = store.into_inner();
        if !after.torn.is_empty() {
            ecc_seen += 1;
        }
        let mut reader = CalibrationStore::with_ecc_check(after.rebooted(), take_ecc_error);
        let loaded = reader.load();
        assert_eq!(loaded.status, ParametersStatus::Valid, "cut at {cut}");
        assert_eq!(loaded.calibration, calibration(1), "cut at {cut}");
        // A retry rewrites the torn slot (erase first) and wins.
        reader.save(&calibration(2)).unwrap();
        let mut again = CalibrationStore::with_ecc_check(reader.into_inner(), take_ecc_error);
        assert_eq!(again.load().calibration, calibration(2), "cut at {cut}");
    }
    // Every program cut (16 of the 17 steps; the first is the erase) left a torn unit.
    assert_eq!(ecc_seen, 16);

    // Nothing valid anywhere but an unreadable slot: the defaults, flagged invalid.
    let mut flash = MemFlash::new();
    flash.ecc_on_torn = true;
    flash.cut_at = Some(1);
    let mut store = CalibrationStore::with_ecc_check(flash, take_ecc_error);
    store.load();
    assert!(store.save(&calibration(1)).is_err());
    let mut flash = store.into_inner().rebooted();
    // Tear the commit marker's unit too, as a cut during it would.
    let commit_unit = COMMIT_AT;
    flash.data[commit_unit..commit_unit + 16].copy_from_slice(&COMMIT);
    flash.torn.push(commit_unit);
    let loaded = CalibrationStore::with_ecc_check(flash, take_ecc_error).load();
    assert_eq!(loaded.status, ParametersStatus::Invalid);
    assert_eq!(loaded.calibration, RigParameters::paper());
}
