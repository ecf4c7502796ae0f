//! The calibration as a file: the rig file (`docs/rig-file.md`), written by `rig calibrate`
//! and `rig calibration get`, read by `rig calibration set`. The older flat calibration file
//! (`c1_nmm_per_a = ...`) still loads. Conversions to and from the device's record are
//! [`rigfile::wire`]'s.

use std::path::Path;

use rigfile::{Loaded, RigFile, RigFileError};

use crate::RigError;

/// A rig file's problem as a calibration-file error (whose message adds that nothing was
/// written to the device).
fn for_device(file: &str, e: RigFileError) -> RigError {
    match e {
        RigFileError::RigFile { why, .. } => RigError::CalibrationFile {
            file: file.to_owned(),
            why,
        },
        other => RigError::CalibrationFile {
            file: file.to_owned(),
            why: other.to_string(),
        },
    }
}

/// Parses rig-file text (named `file` in messages) for `rig calibration set`: every key the
/// device carries comes from the file or, left out, from the defaults (the paper's values).
/// A file that sets none of them is refused.
pub fn parse(text: &str, file: &str) -> Result<Loaded, RigError> {
    let loaded = RigFile::parse_detailed(text, file).map_err(|e| for_device(file, e))?;
    if loaded.set_on_device().is_empty() {
        return Err(RigError::CalibrationFile {
            file: file.to_owned(),
            why: "it sets no calibration field (expected a rig file with sections such as [calibration] c1 = 62.1, see docs/rig-file.md; `rig calibration get FILE` writes a complete example)".into(),
        });
    }
    loaded.rig.to_wire().map_err(|e| for_device(file, e))?;
    Ok(loaded)
}

/// Reads calibration file `path` (see [`parse`]).
pub fn read(path: &Path) -> Result<Loaded, RigError> {
    let name = path.display().to_string();
    let text =
        rigfile::text_input::read_text(path, rigfile::MAX_RIG_FILE_BYTES, "a rig file (TOML)")
            .map_err(|why| RigError::CalibrationFile {
                file: name.clone(),
                why,
            })?;
    parse(&text, &name)
}

/// What writing a device's record to a path does to the file there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// No file there: a new one.
    New,
    /// A rig file there: updated, what the device does not carry kept.
    Updated,
    /// A file there that is not a readable rig file: replaced.
    Replaced {
        /// Why it could not be read.
        why: String,
    },
}

/// The rig file to write for the device's record `record` at `path`: the rig file already
/// there (its calibration temperature, `[model]` and other sections kept) with everything
/// the record carries replaced, or a new one.
pub fn for_record(record: &protocol::RigParameters, path: Option<&Path>) -> (RigFile, Target) {
    match path.filter(|p| p.exists()).map(RigFile::load) {
        Some(Ok(existing)) => (existing.with_wire(record), Target::Updated),
        Some(Err(e)) => (
            RigFile::from_wire(record),
            Target::Replaced { why: e.to_string() },
        ),
        None => (RigFile::from_wire(record), Target::New),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::RigParameters as Calibration;

    #[test]
    fn round_trip_keeps_every_field() {
        let mut cal = Calibration::paper();
        cal.c4_nmm = -0.5;
        let text = RigFile::from_wire(&cal)
            .to_toml_with_comment("test")
            .unwrap();
        let parsed = parse(&text, "t.toml").unwrap();
        assert_eq!(parsed.rig.to_wire().unwrap(), cal);
        assert_eq!(parsed.set_on_device().len(), 16);
        assert!(parsed.defaulted().is_empty());
    }

    #[test]
    fn partial_file_takes_the_defaults() {
        let p = parse("c1_nmm_per_a = 60\n", "t.toml").unwrap();
        let cal = p.rig.to_wire().unwrap();
        assert_eq!(cal.c1_nmm_per_a, 60.0);
        assert_eq!(cal.c2_nmm, -138.0);
        let set: Vec<_> = p.set_on_device().iter().map(|k| k.wire).collect();
        assert_eq!(set, [Some("c1_nmm_per_a")]);
        assert_eq!(p.defaulted().len(), 15);
        let p = parse(
            "[calibration]\nc1 = 60\n[limits]\nmax_freq_hz = 12\n",
            "t.toml",
        )
        .unwrap();
        let set: Vec<String> = p.set_on_device().iter().map(|k| k.path()).collect();
        assert_eq!(set, ["[calibration] c1", "[limits] max_freq_hz"]);
    }

    #[test]
    fn malformed_files_say_what_is_wrong() {
        let err = |text: &str| parse(text, "bad.toml").unwrap_err().to_string();
        let e = err("c1_nmm_per_a = \"lots\"\n");
        assert!(e.contains("bad.toml") && e.contains("line 1"), "{e}");
        let e = err("c7 = 1.0\n");
        assert!(e.contains("unknown field `c7`"), "{e}");
        let e = err("c1_nmm_per_a = -62.1\n");
        assert!(e.contains("`c1_nmm_per_a` is out of range"), "{e}");
        assert!(e.contains("nothing was written"), "{e}");
        let e = err("c1_nmm_per_a = [1\n");
        assert!(e.contains("bad.toml"), "{e}");
        let e = err("# nothing\n");
        assert!(e.contains("sets no calibration field"), "{e}");
        let e = err("z = [50, 50, 50, 50]\n");
        assert!(e.contains("`z`"), "{e}");
        // The same mistakes in the rig file's own format.
        let e = err("[calibration]\nc7 = 1.0\n");
        assert!(e.contains("`c7`") && e.contains("[calibration]"), "{e}");
        let e = err("[friction]\nmu_d = 0.5\n");
        assert!(e.contains("[friction] `mu_d` is out of range"), "{e}");
        // Sections the device does not carry alone set nothing.
        let e = err("[model]\nmu = 0.2\n");
        assert!(e.contains("sets no calibration field"), "{e}");
    }

    #[test]
    fn an_existing_file_keeps_what_the_device_does_not_carry() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rig.toml");
        let mut rig = RigFile::paper().with_model(0.25, Vec::new());
        rig.calibration.temperature_c = 31.0;
        let mut notes = toml::Table::new();
        notes.insert("who".into(), toml::Value::String("kept".into()));
        rig.extra.insert("notes".into(), toml::Value::Table(notes));
        rig.save(&path).unwrap();
        let record = Calibration {
            max_freq_hz: 12.0,
            ..Calibration::paper()
        };
        let (updated, target) = for_record(&record, Some(&path));
        assert_eq!(target, Target::Updated);
        assert_eq!(updated.to_wire().unwrap(), record);
        assert_eq!(updated.calibration.temperature_c, 31.0);
        assert_eq!(updated.model, rig.model);
        assert_eq!(updated.extra, rig.extra);
        let (fresh, target) = for_record(&record, Some(&dir.path().join("new.toml")));
        assert_eq!(target, Target::New);
        assert_eq!(fresh, RigFile::from_wire(&record));
        std::fs::write(&path, "not = [toml\n").unwrap();
        let (fresh, target) = for_record(&record, Some(&path));
        assert!(matches!(target, Target::Replaced { .. }), "{target:?}");
        assert_eq!(fresh, RigFile::from_wire(&record));
    }
}
