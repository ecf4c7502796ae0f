//! The calibration file: TOML with the device's calibration record in the paper's units
//! (the field names of [`protocol::RigParameters`]), written by `rig calibrate` and
//! `rig calibration get`, read by `rig calibration set`.
//!
//! Every field is optional when reading: a missing one keeps the device's value. Unknown
//! keys are errors (a typo must not pass silently). A `[fit]` table (the statistics
//! `rig calibrate` writes) is kept for the reader and ignored when setting.

use std::path::Path;

use protocol::RigParameters as Calibration;
use serde::Deserialize;

use crate::RigError;

/// The file's fields, each optional.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct CalibrationFile {
    c1_nmm_per_a: Option<f32>,
    c2_nmm: Option<f32>,
    c3_nmm_s_per_rad: Option<f32>,
    c4_nmm: Option<f32>,
    c5_a_s_per_rad: Option<f32>,
    c6_a: Option<f32>,
    z: Option<[u16; 4]>,
    module_mm: Option<f32>,
    pressure_angle_deg: Option<f32>,
    eccentricity_mm: Option<f32>,
    carrier_mass_kg: Option<f32>,
    mu_s: Option<f32>,
    mu_d: Option<f32>,
    max_release_load_nm: Option<f32>,
    max_current_a: Option<f32>,
    max_freq_hz: Option<f32>,
    #[allow(dead_code)]
    fit: Option<toml::Value>,
}

/// A calibration read from a file, on top of a base record.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedCalibration {
    /// The resulting record (validated).
    pub calibration: Calibration,
    /// The fields the file set.
    pub set_fields: Vec<&'static str>,
}

/// What a field must be, for messages.
fn rule(field: &str) -> &'static str {
    match field {
        "c1_nmm_per_a" => "a positive number (N mm/A; the paper's is 62.1)",
        "c2_nmm" | "c4_nmm" => "a finite number (N mm)",
        "c3_nmm_s_per_rad" | "c5_a_s_per_rad" | "c6_a" => "zero or positive",
        "z" => "four tooth counts of at least 4 with Z1 Z3 != Z2 Z4, e.g. [49, 51, 50, 50]",
        "pressure_angle_deg" => "between 0 and 45 degrees (standard gears: 20)",
        "mu_s" => "between 0 and 1",
        "mu_d" => "positive and not above mu_s",
        _ => "a positive number",
    }
}

/// Reads calibration file `path`, filling fields it does not set from `base`.
pub fn read(path: &Path, base: &Calibration) -> Result<ParsedCalibration, RigError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| RigError::CalibrationFile {
        file: name.clone(),
        why: format!("cannot read it ({e})"),
    })?;
    parse(&text, &name, base)
}

/// Parses calibration TOML `text` (named `file` in messages) on top of `base`.
pub fn parse(text: &str, file: &str, base: &Calibration) -> Result<ParsedCalibration, RigError> {
    let bad = |why: String| RigError::CalibrationFile {
        file: file.to_owned(),
        why,
    };
    let f: CalibrationFile = toml::from_str(text).map_err(|e| {
        let msg = e.message().to_owned();
        let at = e
            .span()
            .map(|s| {
                let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}: ")
            })
            .unwrap_or_default();
        bad(format!("{at}{msg}"))
    })?;
    let mut cal = *base;
    let mut set = Vec::new();
    macro_rules! take {
        ($($field:ident),*) => {$(
            if let Some(v) = f.$field {
                cal.$field = v;
                set.push(stringify!($field));
            }
        )*};
    }
    take!(
        c1_nmm_per_a,
        c2_nmm,
        c3_nmm_s_per_rad,
        c4_nmm,
        c5_a_s_per_rad,
        c6_a,
        z,
        module_mm,
        pressure_angle_deg,
        eccentricity_mm,
        carrier_mass_kg,
        mu_s,
        mu_d,
        max_release_load_nm,
        max_current_a,
        max_freq_hz
    );
    if set.is_empty() {
        return Err(bad(
            "it sets no calibration field (expected keys such as c1_nmm_per_a = 62.1; `rig calibration get FILE` writes a complete example)".into(),
        ));
    }
    if let Err(rejection) = cal.validate() {
        let field = rejection.field.name();
        let value = if set.contains(&field) {
            "is out of range"
        } else {
            "(kept from the device) is out of range with the file's other values"
        };
        return Err(bad(format!(
            "`{field}` {value}: it must be {}",
            rule(field)
        )));
    }
    Ok(ParsedCalibration {
        calibration: cal,
        set_fields: set,
    })
}

fn num(v: f32) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v:?}")
    }
}

/// The calibration as a commented TOML document; `fit` (already TOML) is appended as the
/// `[fit]` table when given.
pub fn to_toml(cal: &Calibration, header: &str, fit: Option<&str>) -> String {
    let z = cal.z.map(|v| v.to_string()).join(", ");
    let mut s = String::new();
    for line in header.lines() {
        s.push_str(&format!("# {line}\n"));
    }
    s.push_str(&format!(
        "# Units as in the paper's Table 2. `rig calibration set FILE` writes it to the device;\n\
         # keys left out keep the device's values.\n\
         \n\
         # Vibrator, Eqs. (15)-(17)\n\
         c1_nmm_per_a = {}        # C1: |tau_cam| = C1 i_in + C2\n\
         c2_nmm = {}\n\
         c3_nmm_s_per_rad = {}    # C3: |tau_loss| = C3 w_n + C4\n\
         c4_nmm = {}\n\
         c5_a_s_per_rad = {}      # C5: |i_loss| = C5 w_n + C6\n\
         c6_a = {}\n\
         \n\
         # Gear and carrier\n\
         z = [{z}]                 # Z1 (fixed), Z2, Z3 (planet), Z4 (output)\n\
         module_mm = {}\n\
         pressure_angle_deg = {}\n\
         eccentricity_mm = {}\n\
         carrier_mass_kg = {}\n\
         mu_s = {}\n\
         mu_d = {}\n\
         \n\
         # Limits the firmware enforces\n\
         max_release_load_nm = {}\n\
         max_current_a = {}\n\
         max_freq_hz = {}\n",
        num(cal.c1_nmm_per_a),
        num(cal.c2_nmm),
        num(cal.c3_nmm_s_per_rad),
        num(cal.c4_nmm),
        num(cal.c5_a_s_per_rad),
        num(cal.c6_a),
        num(cal.module_mm),
        num(cal.pressure_angle_deg),
        num(cal.eccentricity_mm),
        num(cal.carrier_mass_kg),
        num(cal.mu_s),
        num(cal.mu_d),
        num(cal.max_release_load_nm),
        num(cal.max_current_a),
        num(cal.max_freq_hz),
    ));
    if let Some(fit) = fit {
        s.push_str("\n# How rig calibrate got these values (ignored when setting)\n[fit]\n");
        s.push_str(fit);
        if !fit.ends_with('\n') {
            s.push('\n');
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_every_field() {
        let mut cal = Calibration::paper();
        cal.c4_nmm = -0.5;
        let text = to_toml(&cal, "test", Some("r2 = 0.99\n"));
        let base = Calibration {
            c1_nmm_per_a: 1.0,
            ..Calibration::paper()
        };
        let parsed = parse(&text, "t.toml", &base).unwrap();
        assert_eq!(parsed.calibration, cal);
        assert_eq!(parsed.set_fields.len(), 16);
    }

    #[test]
    fn partial_file_keeps_the_base() {
        let p = parse("c1_nmm_per_a = 60\n", "t.toml", &Calibration::paper()).unwrap();
        assert_eq!(p.calibration.c1_nmm_per_a, 60.0);
        assert_eq!(p.calibration.c2_nmm, -138.0);
        assert_eq!(p.set_fields, vec!["c1_nmm_per_a"]);
    }

    #[test]
    fn malformed_files_say_what_is_wrong() {
        let base = Calibration::paper();
        let err = |text: &str| parse(text, "bad.toml", &base).unwrap_err().to_string();
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
    }
}
