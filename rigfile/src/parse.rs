//! Reading a rig file: the format (the rig file, or the older flat calibration file), the
//! sections kept as they are, the keys the file set, and the range checks.

use std::collections::BTreeMap;

use toml::{Spanned, Value};

use crate::keys::{self, KeySpec};
use crate::sections::FitSection;
use crate::{RigFile, RigFileError};

/// Which of the accepted formats a file had.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileFormat {
    /// The rig file: sections `[gear]`, `[cam]`, `[friction]`, `[calibration]`, `[limits]`,
    /// `[model]` (every one optional).
    RigFile,
    /// The older flat calibration file of `rig calibrate` / `rig calibration get`: the
    /// device record's field names at the top level (`c1_nmm_per_a = 62.1`), optional `[fit]`.
    CalibrationFile,
}

/// A rig file as read: the rig, its format and the keys it set.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// The rig (keys the file left out have their defaults).
    pub rig: RigFile,
    /// The file's format.
    pub format: FileFormat,
    /// The keys the file set, in [`keys::KEYS`] order.
    pub present: Vec<&'static KeySpec>,
}

impl Loaded {
    /// Whether the file set `key`.
    pub fn has(&self, key: &KeySpec) -> bool {
        self.present.contains(&key)
    }

    /// The keys the device's record carries that the file left out (they take the defaults
    /// of `docs/rig-file.md`, the paper's values).
    pub fn defaulted(&self) -> Vec<&'static KeySpec> {
        keys::wire_keys().filter(|k| !self.has(k)).collect()
    }

    /// The keys the device's record carries that the file set.
    pub fn set_on_device(&self) -> Vec<&'static KeySpec> {
        keys::wire_keys().filter(|k| self.has(k)).collect()
    }

    /// `key` as this file names it: `[section] key`, or the flat key of the older
    /// calibration file.
    pub fn name_of(&self, key: &KeySpec) -> String {
        name_in(self.format, key)
    }
}

fn name_in(format: FileFormat, key: &KeySpec) -> String {
    match (format, key.wire) {
        (FileFormat::CalibrationFile, Some(flat)) => format!("`{flat}`"),
        _ => format!("[{}] `{}`", key.section, key.key),
    }
}

fn bad(file: &str, why: String) -> RigFileError {
    RigFileError::RigFile {
        file: file.to_string(),
        why,
    }
}

/// 1-based line of byte `offset` of `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// The section header (`[name]` or `[[name]]`) in force at byte `offset`, if any.
fn section_at(text: &str, offset: usize) -> Option<String> {
    let before = &text[..offset.min(text.len())];
    before.lines().rev().find_map(|line| {
        let t = line.trim_start();
        let t = t.strip_prefix('[')?;
        let t = t.strip_prefix('[').unwrap_or(t);
        let end = t.find(']')?;
        Some(t[..end].trim().to_string())
    })
}

/// The key whose value is at byte `offset` of `text`: the name before the nearest `=`
/// on its line before it (`kappa` in `params = { kappa = 1e999 }`).
fn key_at(text: &str, offset: usize) -> Option<String> {
    let offset = offset.min(text.len());
    let start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    let before = text.get(start..offset)?;
    let eq = before.rfind('=')?;
    let name = before[..eq]
        .trim_end()
        .rsplit(|c: char| c == '{' || c == ',' || c.is_whitespace())
        .next()?
        .trim_matches('"');
    (!name.is_empty()).then(|| name.to_string())
}

/// A TOML error as one line: where (line, section, key) and what, with the key's allowed
/// range when it is one of the rig file's.
fn describe(text: &str, e: &toml::de::Error) -> String {
    let what = e.message().trim_end().to_string();
    match e.span() {
        Some(span) => {
            let line = line_of(text, span.start);
            let section = section_at(text, span.start);
            let key = key_at(text, span.start);
            let spec = match (&section, &key) {
                (Some(s), Some(k)) => keys::find(s, k),
                _ => None,
            };
            let range = spec
                .map(|k| format!("; it must be {}", k.range))
                .unwrap_or_default();
            let key = key.map(|k| format!(", `{k}`")).unwrap_or_default();
            match section {
                Some(section) => format!("line {line}, in [{section}]{key}: {what}{range}"),
                None => format!("line {line}{key}: {what}{range}"),
            }
        }
        None => what,
    }
}

/// Whether `v` is a section: a table or an array of tables.
pub(crate) fn is_section(v: &Value) -> bool {
    match v {
        Value::Table(_) => true,
        Value::Array(items) => !items.is_empty() && items.iter().all(Value::is_table),
        _ => false,
    }
}

/// See [`RigFile::parse_detailed`].
pub(crate) fn parse(text: &str, name: &str) -> Result<Loaded, RigFileError> {
    let top: BTreeMap<String, Spanned<Value>> =
        toml::from_str(text).map_err(|e| bad(name, describe(text, &e)))?;
    let mut flat = Vec::new();
    let mut sections = Vec::new();
    let mut extra = toml::Table::new();
    for (key, value) in &top {
        if keys::SECTIONS.contains(&key.as_str()) {
            sections.push(key.as_str());
        } else if is_section(value.get_ref()) {
            extra.insert(key.clone(), value.get_ref().clone());
        } else if keys::by_wire(key).is_some() {
            flat.push(key.as_str());
        } else {
            let line = line_of(text, value.span().start);
            let hint = match keys::KEYS.iter().find(|k| k.key == key.as_str()) {
                Some(k) => format!("it belongs in [{}]", k.section),
                None => "keys belong in a section such as [gear] or [calibration]".to_string(),
            };
            return Err(bad(
                name,
                format!(
                    "line {line}: unknown field `{key}` at the top level: {hint} (every section and key: docs/rig-file.md)"
                ),
            ));
        }
    }
    let loaded = if flat.is_empty() {
        let mut rig: RigFile = toml::from_str(text).map_err(|e| bad(name, describe(text, &e)))?;
        rig.extra = extra;
        let present = keys::KEYS
            .iter()
            .filter(|k| {
                lookup(&top, k.section).is_some_and(|t| {
                    std::iter::once(k.key)
                        .chain(k.aliases.iter().copied())
                        .any(|key| t.contains_key(key))
                })
            })
            .collect();
        Loaded {
            rig,
            format: FileFormat::RigFile,
            present,
        }
    } else {
        if let Some(section) = sections.first() {
            return Err(bad(
                name,
                format!(
                    "it mixes the older calibration file's flat keys ({}) with the rig file's section [{section}]: write C1 as [calibration] c1 and so on (docs/rig-file.md)",
                    flat.join(", ")
                ),
            ));
        }
        from_calibration_file(text, name, &top, extra)?
    };
    check(&loaded, name)?;
    Ok(loaded)
}

/// The table at dotted `section` (`calibration.fit`) of the top level, if any.
fn lookup<'a>(top: &'a BTreeMap<String, Spanned<Value>>, section: &str) -> Option<&'a toml::Table> {
    let mut parts = section.split('.');
    let mut table = top.get(parts.next()?)?.get_ref().as_table()?;
    for part in parts {
        table = table.get(part)?.as_table()?;
    }
    Some(table)
}

/// The older flat calibration file: each key moves to its section; its `[fit]` becomes
/// `[calibration.fit]` when it has that shape, else it is kept as it is.
fn from_calibration_file(
    text: &str,
    name: &str,
    top: &BTreeMap<String, Spanned<Value>>,
    mut extra: toml::Table,
) -> Result<Loaded, RigFileError> {
    let mut table = toml::Table::new();
    let mut present = Vec::new();
    for (key, value) in top {
        let Some(spec) = keys::by_wire(key) else {
            continue;
        };
        let line = line_of(text, value.span().start);
        let typed = if spec.key == "z" {
            value.get_ref().clone().try_into::<[u32; 4]>().map(|_| ())
        } else {
            value.get_ref().clone().try_into::<f64>().map(|_| ())
        };
        if let Err(e) = typed {
            return Err(bad(
                name,
                format!("line {line}: `{key}`: {}", e.message().trim_end()),
            ));
        }
        let section = table
            .entry(spec.section)
            .or_insert_with(|| Value::Table(toml::Table::new()));
        if let Value::Table(t) = section {
            t.insert(spec.key.to_string(), value.get_ref().clone());
        }
        present.push(spec);
    }
    if let Some(fit) = extra.remove("fit") {
        if fit.clone().try_into::<FitSection>().is_ok() {
            if let Some(Value::Table(cal)) = table.get_mut("calibration") {
                cal.insert("fit".into(), fit);
            } else {
                let mut cal = toml::Table::new();
                cal.insert("fit".into(), fit);
                table.insert("calibration".into(), Value::Table(cal));
            }
            present.extend(keys::KEYS.iter().filter(|k| k.section == "calibration.fit"));
        } else {
            extra.insert("fit".into(), fit);
        }
    }
    let mut rig: RigFile = Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| bad(name, e.message().trim_end().to_string()))?;
    rig.extra = extra;
    present.sort_by_key(|k| keys::KEYS.iter().position(|x| x == *k));
    Ok(Loaded {
        rig,
        format: FileFormat::CalibrationFile,
        present,
    })
}

/// [`RigFile::check`]: every key set, named as rig-file keys.
pub(crate) fn check_all(rig: &RigFile, name: &str) -> Result<(), RigFileError> {
    check(
        &Loaded {
            rig: rig.clone(),
            format: FileFormat::RigFile,
            present: keys::KEYS.iter().collect(),
        },
        name,
    )
}

/// The value of `key` in `rig` as the file writes it.
fn value_text(rig: &RigFile, key: &KeySpec) -> String {
    let Ok(table) = toml::Table::try_from(rig) else {
        return "?".into();
    };
    let mut t = &table;
    for part in key.section.split('.') {
        match t.get(part).and_then(Value::as_table) {
            Some(inner) => t = inner,
            None => return "?".into(),
        }
    }
    t.get(key.key).map_or("?".into(), |v| v.to_string())
}

/// The rig file's own ranges, inside the device's (which asks only for a finite 32-bit
/// number of the right sign), in the file's units: (section, key, low, high), each quoted
/// by its key's range in [`keys::KEYS`]. Wide enough for any build of this rig, narrow
/// enough that no model or simulation of it overflows (3.4e38 N mm/A fits the device's
/// record and ran the simulated motor to NaN).
pub(crate) const BOUNDED: [(&str, &str, f64, f64); 13] = [
    ("gear", "module_mm", f64::MIN, 100.0),
    ("cam", "eccentricity_mm", f64::MIN, 100.0),
    ("cam", "carrier_mass_kg", f64::MIN, 1000.0),
    ("calibration", "c1", f64::MIN, 1000.0),
    ("calibration", "c2", -10_000.0, 10_000.0),
    ("calibration", "c3", 0.0, 100.0),
    ("calibration", "c4", -10_000.0, 10_000.0),
    ("calibration", "c5", 0.0, 1.0),
    ("calibration", "c6", 0.0, 100.0),
    ("calibration", "temperature_c", -273.15, 1000.0),
    ("limits", "max_release_load_nm", f64::MIN, 1000.0),
    ("limits", "max_current_a", f64::MIN, 100.0),
    ("limits", "max_freq_hz", f64::MIN, 100.0),
];

/// The value of `key` (one of [`BOUNDED`]'s) in `rig`, in the file's units.
fn bounded_value(rig: &RigFile, key: &str) -> f64 {
    let c = crate::paper_units::to_paper(&rig.calibration.constants);
    match key {
        "module_mm" => rig.gear.module_mm,
        "eccentricity_mm" => rig.cam.eccentricity_mm,
        "carrier_mass_kg" => rig.cam.carrier_mass_kg,
        "c1" => c[0],
        "c2" => c[1],
        "c3" => c[2],
        "c4" => c[3],
        "c5" => c[4],
        "c6" => c[5],
        "temperature_c" => rig.calibration.temperature_c,
        "max_release_load_nm" => rig.limits.max_release_load_nm,
        "max_current_a" => rig.limits.max_current_a,
        "max_freq_hz" => rig.limits.max_freq_hz,
        _ => f64::NAN,
    }
}

/// The range checks of `docs/rig-file.md`; the message names the key as the file does and
/// says whether the file set it.
fn check(loaded: &Loaded, name: &str) -> Result<(), RigFileError> {
    let rig = &loaded.rig;
    let out_of_range = |section: &str, key: &str, why: Option<String>| {
        let Some(spec) = keys::find(section, key) else {
            return bad(name, format!("[{section}] {key} is out of range"));
        };
        let value = value_text(rig, spec);
        let given = if loaded.has(spec) {
            format!("{value} given")
        } else {
            format!("{value} (left out: the default) does not fit the file's other values")
        };
        let why = why.map(|w| format!(" ({w})")).unwrap_or_default();
        bad(
            name,
            format!(
                "{} is out of range: {given}{why}; it must be {}",
                loaded.name_of(spec),
                spec.range
            ),
        )
    };
    if let Err(e) = rig.gear_set() {
        let key = match &e {
            RigFileError::Gear {
                source: model::GearError::BadModule,
                ..
            } => "module_mm",
            RigFileError::Gear {
                source: model::GearError::BadPressureAngle,
                ..
            } => "pressure_angle_deg",
            RigFileError::Gear {
                source:
                    model::GearError::BadShift { .. }
                    | model::GearError::UnequalWorkingCentreDistance { .. }
                    | model::GearError::NoWorkingPressureAngle { .. },
                ..
            } => "profile_shift",
            _ => "z",
        };
        let why = match e {
            RigFileError::Gear { source, .. } => source.to_string(),
            other => other.to_string(),
        };
        return Err(out_of_range("gear", key, Some(why)));
    }
    if rig.gear.z.iter().any(|&z| z > u32::from(u16::MAX)) {
        return Err(out_of_range("gear", "z", None));
    }
    let wire = crate::wire::record_unchecked(rig);
    if let Err(rejection) = wire.validate() {
        let field = rejection.field.name();
        let spec = keys::by_wire(field).ok_or_else(|| {
            bad(
                name,
                format!("the device record's `{field}` is out of range"),
            )
        })?;
        let too_big = value_text(rig, spec)
            .parse::<f64>()
            .is_ok_and(|v| v.is_finite() && !(v as f32).is_finite());
        let why = too_big.then(|| "too large for the device's 32-bit record".to_string());
        return Err(out_of_range(spec.section, spec.key, why));
    }
    for (section, key, lo, hi) in BOUNDED {
        if !(lo..=hi).contains(&bounded_value(rig, key)) {
            return Err(out_of_range(section, key, None));
        }
    }
    if let Some(m) = &rig.model {
        let (lo, hi) = model::effects::MU_BOUNDS;
        if !(lo..=hi).contains(&m.mu) {
            return Err(out_of_range("model", "mu", None));
        }
        let (list, p) = rig
            .effects()
            .map_err(|why| bad(name, format!("[model] effects: {why}")))?;
        // An extra viscous loss below -C3 leaves the vibrator negative damping: it would
        // speed itself up (the plant runs away), which no motor does.
        let net = rig.calibration.constants.c3 + p.viscous_loss;
        if list.contains(&model::effects::Effect::VibratorViscousLoss) && net < 0.0 {
            return Err(bad(
                name,
                format!(
                    "[model] effects: vibrator-viscous-loss c_v_n_mm_s_per_rad = {} is out of range: it must be at least -C3 = {} N mm s/rad (C3 + c_v is the vibrator's whole viscous loss, never negative)",
                    p.viscous_loss * 1e3,
                    -rig.calibration.constants.c3 * 1e3
                ),
            ));
        }
    }
    rig.check_user_effects().map_err(|why| bad(name, why))?;
    Ok(())
}
