//! The one place that converts between the device's calibration record
//! (`protocol::RigParameters`: C1-C6 in the paper's units as `f32`, geometry, friction and
//! limits), the SI [`model::Calibration`] and the rig file. Every verb that reads or writes
//! the device's record goes through here.
//!
//! `f32` values become the shortest decimal that reads back to the same `f32` (62.1, not
//! 62.099998474121094), so a record read from the device and written to a file reads as the
//! numbers that were sent.

use crate::paper_units;
use crate::{RigFile, RigFileError};

/// An `f32` of the record as the decimal a person wrote.
fn decimal(v: f32) -> f64 {
    reporting::human_f64(f64::from(v))
}

/// C1-C6 of the device's record in SI.
pub fn constants(record: &protocol::RigParameters) -> model::Calibration {
    paper_units::from_paper(record.constants().map(reporting::human_f64))
}

/// `base` with C1-C6 replaced by `c`.
pub fn with_constants(
    base: &protocol::RigParameters,
    c: &model::Calibration,
) -> protocol::RigParameters {
    let [c1, c2, c3, c4, c5, c6] = paper_units::to_paper(c).map(|v| v as f32);
    protocol::RigParameters {
        c1_nmm_per_a: c1,
        c2_nmm: c2,
        c3_nmm_s_per_rad: c3,
        c4_nmm: c4,
        c5_a_s_per_rad: c5,
        c6_a: c6,
        ..*base
    }
}

/// The record of `rig` without range checks (tooth counts above 65535 saturate).
pub(crate) fn record_unchecked(rig: &RigFile) -> protocol::RigParameters {
    let f = |v: f64| v as f32;
    with_constants(
        &protocol::RigParameters {
            z: rig.gear.z.map(|z| u16::try_from(z).unwrap_or(u16::MAX)),
            module_mm: f(rig.gear.module_mm),
            pressure_angle_deg: f(rig.gear.pressure_angle_deg),
            eccentricity_mm: f(rig.cam.eccentricity_mm),
            carrier_mass_kg: f(rig.cam.carrier_mass_kg),
            mu_s: f(rig.friction.mu_s),
            mu_d: f(rig.friction.mu_d),
            max_release_load_nm: f(rig.limits.max_release_load_nm),
            max_current_a: f(rig.limits.max_current_a),
            max_freq_hz: f(rig.limits.max_freq_hz),
            profile_shift: rig.gear.profile_shift.map(f),
            ..protocol::RigParameters::paper()
        },
        &rig.calibration.constants,
    )
}

impl RigFile {
    /// The device's calibration record this file describes: C1-C6, geometry, friction and
    /// limits, exactly what `rig calibration set` sends. Checked as the firmware checks it.
    pub fn to_wire(&self) -> Result<protocol::RigParameters, RigFileError> {
        self.check()?;
        Ok(record_unchecked(self))
    }

    /// The paper's rig file with everything the device's record carries taken from `record`.
    pub fn from_wire(record: &protocol::RigParameters) -> Self {
        Self::paper().with_wire(record)
    }

    /// This file with everything the device's record carries replaced by `record`; the rest
    /// (calibration temperature, `[model]`, kept sections) stays. `[calibration.fit]` stays
    /// only while C1-C6 are the ones it describes.
    pub fn with_wire(&self, record: &protocol::RigParameters) -> Self {
        let mut r = self.clone();
        r.gear.z = record.z.map(u32::from);
        r.gear.module_mm = decimal(record.module_mm);
        r.gear.pressure_angle_deg = decimal(record.pressure_angle_deg);
        r.gear.profile_shift = record.profile_shift.map(decimal);
        r.cam.eccentricity_mm = decimal(record.eccentricity_mm);
        r.cam.carrier_mass_kg = decimal(record.carrier_mass_kg);
        r.friction.mu_s = decimal(record.mu_s);
        r.friction.mu_d = decimal(record.mu_d);
        r.limits.max_release_load_nm = decimal(record.max_release_load_nm);
        r.limits.max_current_a = decimal(record.max_current_a);
        r.limits.max_freq_hz = decimal(record.max_freq_hz);
        let c = constants(record);
        let same = with_constants(record, &self.calibration.constants) == *record;
        if !same {
            r.calibration.fit = None;
        }
        r.calibration.constants = c;
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_rig_is_the_devices_default_record() {
        let wire = RigFile::paper().to_wire().unwrap();
        assert_eq!(wire, protocol::RigParameters::paper());
        assert_eq!(RigFile::from_wire(&wire), RigFile::paper());
        assert_eq!(constants(&wire), model::Calibration::PAPER);
    }

    #[test]
    fn a_record_reads_as_the_numbers_sent() {
        let record = protocol::RigParameters {
            c1_nmm_per_a: 60.5,
            mu_d: 0.15,
            max_freq_hz: 12.0,
            z: [52, 48, 50, 50],
            ..protocol::RigParameters::paper()
        };
        let rig = RigFile::from_wire(&record);
        let text = rig.to_toml().unwrap();
        assert!(text.contains("c1 = 60.5\n"), "{text}");
        assert!(text.contains("mu_d = 0.15\n"), "{text}");
        assert!(text.contains("max_freq_hz = 12.0\n"), "{text}");
        let back = RigFile::parse(&text, "t.toml").unwrap();
        assert_eq!(back.to_wire().unwrap(), record);
    }

    #[test]
    fn a_shifted_gear_reaches_the_record_and_back() {
        // Z1 + Z2 = 100, Z3 + Z4 = 101: one working centre distance through the shifts.
        let text = "[gear]\nz = [49, 51, 51, 50]\nprofile_shift = [0.2, 0.3, 0.0, -0.017]\n";
        let rig = RigFile::parse(text, "shifted.toml").unwrap();
        let record = rig.to_wire().unwrap();
        assert_eq!(record.z, [49, 51, 51, 50]);
        assert_eq!(record.profile_shift, [0.2, 0.3, 0.0, -0.017]);
        let back = RigFile::from_wire(&record);
        assert_eq!(back.gear.profile_shift, [0.2, 0.3, 0.0, -0.017]);
        assert_eq!(back.gear_set().unwrap(), rig.gear_set().unwrap());
        // The paper's standard gear stays all zero on the wire.
        assert_eq!(RigFile::paper().to_wire().unwrap().profile_shift, [0.0; 4]);
    }

    #[test]
    fn new_constants_drop_the_old_fit_but_keep_the_model() {
        let mut rig = RigFile::paper().with_model(0.25, Vec::new());
        rig.calibration.fit = Some(crate::tests::a_fit());
        let same = rig.with_wire(&protocol::RigParameters::paper());
        assert!(same.calibration.fit.is_some() && same.model.is_some());
        let other = rig.with_wire(&protocol::RigParameters {
            c1_nmm_per_a: 61.0,
            ..protocol::RigParameters::paper()
        });
        assert!(other.calibration.fit.is_none() && other.model.is_some());
    }
}
