//! The rig file: one TOML description of a rig, read and written by every rig tool.
//! `rig calibrate` writes it, `rig calibration get` writes and `rig calibration set` sends
//! it, `rig explain --model/--write-model` reads and writes it (with the fitted model), and
//! the simulator can be built from it (`sim::SimConfig::from_rig_file`).
//!
//! Every section and key, with unit, allowed range and default: `docs/rig-file.md` (the
//! table behind it is [`keys::KEYS`]; a test keeps the two equal). In short:
//!
//! ```toml
//! [gear]
//! z = [49, 51, 50, 50]        # Z1, Z2, Z3, Z4 (G1 fixed, G2-G3 planet, G4 output)
//! module_mm = 1.0
//! pressure_angle_deg = 20.0
//!
//! [cam]
//! eccentricity_mm = 1.0       # e (alias: e_mm)
//! carrier_mass_kg = 3.82      # M_hat = M1 + M23
//!
//! [friction]
//! mu_s = 0.271
//! mu_d = 0.174
//!
//! [calibration]               # Table 2, the paper's units
//! c1 = 62.1                   # N mm/A
//! c2 = -138.0                 # N mm
//! c3 = 0.235                  # N mm s/rad
//! c4 = 1.69                   # N mm
//! c5 = 0.00378                # A s/rad
//! c6 = 2.25                   # A
//! temperature_c = 25.0        # motor temperature at calibration (thermal-drift reference)
//!
//! [limits]                    # what the firmware enforces
//! max_release_load_nm = 3.68
//! max_current_a = 4.5
//! max_freq_hz = 15.0
//!
//! # Written by `rig explain --write-model`: the fitted model of the vibrator current.
//! [model]
//! mu = 0.262                  # mu of Eq. (10), fitted to the current
//!
//! [[model.effects]]
//! name = "speed-dependent-axial-friction"
//! params = { omega_c_rad_s = 21.0 }
//! ```
//!
//! The effect names and their parameters are those of `rig explain` (see
//! `explain::library`); an effect listed without a parameter starts at zero. An entry of
//! `[[model.terms]]` with `form = "..."` is a library effect in one of its family forms, and
//! one named after a `[[user_effects]]` definition is that user effect (both are `rig
//! explain`'s terms, `explain::terms`; [`RigFile::term_entries`]).
//!
//! ```toml
//! # A user-defined effect: an expression over w, tau, t, temp, i, i_f, i_m and f_ax (see
//! # docs/rig-file.md) giving an extra current in A, with its parameters.
//! [[user_effects]]
//! name = "brush-drag"
//! expression = "c * (w / 100)^2"
//! params = { c = { unit = "A", bounds = [-0.5, 0.5] } }   # null (the value without the
//!                                                         # effect) 0, start = null
//! ```
//!
//! Every section and key is optional: what is left out is the paper's (49, 51, 50, 50) rig
//! ([`Loaded::defaulted`] says which keys a file left out). Unknown keys inside a known
//! section are an error naming the key and the section, so a typo does not silently fall
//! back to the paper's value; unknown sections are ignored and kept as they are when a tool
//! rewrites the file ([`RigFile::extra`]). The older flat calibration file (`c1_nmm_per_a =
//! ...`, written by `rig calibrate` and `rig calibration get` before this format) still
//! loads ([`FileFormat::CalibrationFile`]).
//!
//! Conversions between the rig file, [`model::Calibration`] and the device's record
//! (`protocol::RigParameters`) live in one place: [`wire`] and [`paper_units`].

use std::path::Path;

use model::{Calibration, CamDrive, GearSet};
use serde::{Deserialize, Serialize};

mod effects;
mod error;
pub mod keys;
pub mod paper_units;
mod parse;
pub mod plan;
pub mod row;
mod sections;
pub mod text_input;
pub mod user_law;
pub mod wire;

pub use effects::{MAX_USER_EFFECTS, PlantSetup, apply_params};
pub use error::RigFileError;
pub use keys::KeySpec;
pub use parse::{FileFormat, Loaded};
pub use sections::{
    CALIBRATION_TEMPERATURE_C, CalibrationSection, CamSection, DecayMode, DriveSection,
    EffectEntry, FitSection, FrictionSection, GearSection, LimitsSection, LoadSection,
    ModelSection, TermEntry, UserEffectDef, UserParamDef,
};
pub use user_law::{USER_VARIABLES, UserLaw, UserTerm};

/// The first line of every rig file the tools write.
pub const HEADER: &str =
    "# Rig file of the vibration-switched planetary gear; sections and keys: docs/rig-file.md";

/// A rig file (see the module docs for the format).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct RigFile {
    /// The gear set.
    pub gear: GearSection,
    /// The cam and carrier.
    pub cam: CamSection,
    /// Tooth friction.
    pub friction: FrictionSection,
    /// Vibrator calibration (Table 2) and, from `rig calibrate`, its fit.
    pub calibration: CalibrationSection,
    /// The limits the firmware enforces.
    pub limits: LimitsSection,
    /// The drive: the bridge's decay mode (braking by default, the README's board).
    pub drive: DriveSection,
    /// The bench around the output: how far a hung load falls before it rests on the
    /// floor (left out of written files while it is the default).
    #[serde(skip_serializing_if = "LoadSection::is_default")]
    pub load: LoadSection,
    /// The fitted model, when `rig explain` wrote one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelSection>,
    /// User-defined effects (`[[user_effects]]`), candidates of `rig explain`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub user_effects: Vec<UserEffectDef>,
    /// Sections this version does not read (tables or arrays of tables, by name), kept as
    /// they were when the file is rewritten.
    #[serde(skip)]
    pub extra: toml::Table,
}

/// Largest rig file read, bytes (a rig file with every section is about 2 KiB).
pub const MAX_RIG_FILE_BYTES: u64 = 1024 * 1024;

impl RigFile {
    /// The paper's rig, no fitted model.
    pub fn paper() -> Self {
        Self::default()
    }

    /// Reads and checks a rig file (either format, see [`RigFile::load_detailed`]).
    pub fn load(path: &Path) -> Result<Self, RigFileError> {
        Ok(Self::load_detailed(path)?.rig)
    }

    /// Reads and checks a rig file, saying which format it had and which keys it set.
    pub fn load_detailed(path: &Path) -> Result<Loaded, RigFileError> {
        // A rig file is a few KiB: a pipe, a device or a huge file is refused before reading.
        if let Ok(meta) = std::fs::metadata(path)
            && (!meta.is_file() || meta.len() > MAX_RIG_FILE_BYTES)
        {
            return Err(RigFileError::BadValue {
                what: format!("rig file {}", path.display()),
                why: if meta.is_file() {
                    format!(
                        "is {} bytes, more than the {} KiB a rig file can need: give the rig file (TOML), not a data file",
                        meta.len(),
                        MAX_RIG_FILE_BYTES / 1024
                    )
                } else {
                    "is not a regular file (a folder, pipe or device): give a rig file (TOML)"
                        .into()
                },
            });
        }
        // The read itself stays bounded too (a file can grow, or its size be unknown).
        let read_err = |source| RigFileError::File {
            action: "read",
            path: path.display().to_string(),
            source,
        };
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(
            &mut std::io::Read::take(
                std::fs::File::open(path).map_err(read_err)?,
                MAX_RIG_FILE_BYTES + 1,
            ),
            &mut bytes,
        )
        .map_err(read_err)?;
        // Not text (a binary file): said as the bounded reader says it ([`text_input`]).
        let text = String::from_utf8(bytes).map_err(|e| RigFileError::BadValue {
            what: format!("rig file {}", path.display()),
            why: format!(
                "is not UTF-8 text (byte {}): give a rig file (TOML)",
                e.utf8_error().valid_up_to()
            ),
        })?;
        if text.len() as u64 > MAX_RIG_FILE_BYTES {
            return Err(RigFileError::BadValue {
                what: format!("rig file {}", path.display()),
                why: format!(
                    "is more than the {} KiB a rig file can need: give the rig file (TOML), not a data file",
                    MAX_RIG_FILE_BYTES / 1024
                ),
            });
        }
        Self::parse_detailed(&text, &path.display().to_string())
    }

    /// Parses and checks rig-file text; `name` names it in messages.
    pub fn parse(text: &str, name: &str) -> Result<Self, RigFileError> {
        Ok(Self::parse_detailed(text, name)?.rig)
    }

    /// Parses and checks rig-file text in either format (the rig file, or the older flat
    /// calibration file), saying which keys it set; `name` names it in messages.
    pub fn parse_detailed(text: &str, name: &str) -> Result<Loaded, RigFileError> {
        parse::parse(text, name)
    }

    /// Checks every value against its allowed range (`docs/rig-file.md`); the error names
    /// the key as `[section] key`.
    pub fn check(&self) -> Result<(), RigFileError> {
        parse::check_all(self, "(in memory)")
    }

    /// The file as TOML text (no header comment): the known sections, then the kept ones.
    pub fn to_toml(&self) -> Result<String, RigFileError> {
        let cannot = |e: toml::ser::Error| RigFileError::BadValue {
            what: "rig file".into(),
            why: format!("cannot be written as TOML: {e}"),
        };
        let mut text = toml::to_string(self).map_err(cannot)?;
        if let Some((name, _)) = self.extra.iter().find(|(_, v)| !parse::is_section(v)) {
            return Err(RigFileError::BadValue {
                what: format!("kept section `{name}`"),
                why: "is not a table: only whole sections are kept".into(),
            });
        }
        if !self.extra.is_empty() {
            text.push('\n');
            text.push_str(&toml::to_string(&self.extra).map_err(cannot)?);
        }
        if !text.ends_with('\n') {
            text.push('\n');
        }
        Ok(text)
    }

    /// The file as TOML text behind [`HEADER`] and `comment` (one `#` line per line).
    pub fn to_toml_with_comment(&self, comment: &str) -> Result<String, RigFileError> {
        let mut text = format!("{HEADER}\n");
        for line in comment.lines() {
            text.push_str(&format!("# {line}\n").replace("# \n", "#\n"));
        }
        text.push_str(&self.to_toml()?);
        Ok(text)
    }

    /// Writes the file atomically: a failed write leaves an existing file untouched.
    pub fn save(&self, path: &Path) -> Result<(), RigFileError> {
        self.save_with_comment(path, "")
    }

    /// Writes the file atomically with `comment` below the header line.
    pub fn save_with_comment(&self, path: &Path, comment: &str) -> Result<(), RigFileError> {
        let text = self.to_toml_with_comment(comment)?;
        reporting::write_atomic(path, text.as_bytes())?;
        Ok(())
    }

    /// The gear set, module, pressure angle and profile shifts in SI.
    pub fn gear_set(&self) -> Result<GearSet, RigFileError> {
        let g = &self.gear;
        GearSet::shifted(
            g.z,
            g.profile_shift,
            g.module_mm * 1e-3,
            g.pressure_angle_deg.to_radians(),
        )
        .map_err(|source| RigFileError::Gear { z: g.z, source })
    }

    /// The cam drive (gear set, e and M_hat in SI).
    pub fn drive(&self) -> Result<CamDrive, RigFileError> {
        Ok(CamDrive {
            gear: self.gear_set()?,
            eccentricity: self.cam.eccentricity_mm * 1e-3,
            carrier_mass: self.cam.carrier_mass_kg,
        })
    }

    /// The vibrator calibration in SI.
    pub fn calibration(&self) -> Calibration {
        self.calibration.constants
    }

    /// This rig with `[model]` set to `mu` and `effects` (name and parameters each).
    pub fn with_model(&self, mu: f64, effects: Vec<EffectEntry>) -> Self {
        self.with_model_terms(mu, effects, Vec::new())
    }

    /// This rig with its drive's inertia term known: `inertia-rectification` at the kappa
    /// of a drive that does (`regenerative`) or does not take the carrier's power back
    /// ([`model::effects::drive_kappa`]), added to `[model]` (created with mu = mu_s when
    /// absent) unless the model already fits it. The virtual rig and the firmware's
    /// estimator follow the board's decay mode (`model::hardware::board::REGENERATIVE_DECAY`);
    /// Eq. (10) alone is neither drive, so data measured through the board always carries it.
    pub fn with_drive_decay(&self, regenerative: bool) -> Self {
        let listed = self
            .model
            .iter()
            .flat_map(|m| &m.effects)
            .any(|e| e.name == "inertia-rectification");
        if listed {
            return self.clone();
        }
        let mut r = self.clone();
        let model = r.model.get_or_insert_with(|| ModelSection {
            mu: self.friction.mu_s,
            effects: Vec::new(),
            terms: Vec::new(),
        });
        let mut params = std::collections::BTreeMap::new();
        params.insert(
            "kappa".to_string(),
            model::effects::drive_kappa(regenerative),
        );
        model.effects.push(EffectEntry {
            name: "inertia-rectification".into(),
            params,
        });
        r
    }

    /// This rig with `[model]` set to `mu`, `effects` and `terms`.
    pub fn with_model_terms(
        &self,
        mu: f64,
        effects: Vec<EffectEntry>,
        terms: Vec<TermEntry>,
    ) -> Self {
        let mut r = self.clone();
        r.model = Some(ModelSection { mu, effects, terms });
        r
    }
}

#[cfg(test)]
mod tests;
