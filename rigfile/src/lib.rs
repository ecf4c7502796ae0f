//! The rig file: a TOML description of the rig (gear set, cam, friction, vibrator
//! calibration) and, once `rig explain --write-model` has written it, the fitted model with the
//! effects it found. `rig explain --model FILE` reads it back; the simulator can build its
//! current model from it ([`RigFile::current_model`]).
//!
//! Every section and key is optional: what is left out is the paper's (49, 51, 50, 50) rig.
//! Lengths are in mm and C1-C6 in the paper's units (Table 2), as the paper prints them;
//! unknown keys are an error, so a typo does not silently fall back to the paper's value.
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
//! `explain::library`); an effect listed without a parameter starts at zero. An entry with
//! `form = "..."` is a library effect in one of its family forms, and an entry named after a
//! `[[user_effects]]` definition is that user effect (both are `rig explain`'s terms,
//! `explain::terms`; [`RigFile::term_entries`]).
//!
//! ```toml
//! # A user-defined effect: an expression over w, tau, t, temp, i, i_f, i_m and f_ax (see
//! # `rig explain --help`) giving an extra current in A, with its parameters.
//! [[user_effects]]
//! name = "brush-drag"
//! expression = "c * (w / 100)^2"
//! params = { c = { unit = "A", bounds = [-0.5, 0.5] } }   # null (the value without the
//!                                                         # effect) 0, start = null
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use model::effects::{CurrentModel, Effect, EffectParams, ParamValue};
use model::{Calibration, CamDrive, GearSet};
use serde::{Deserialize, Serialize};

mod error;

pub use error::RigFileError;

/// A rig file (see the module docs for the format).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct RigFile {
    /// The gear set.
    pub gear: GearSection,
    /// The cam and carrier.
    pub cam: CamSection,
    /// Tooth friction.
    pub friction: FrictionSection,
    /// Vibrator calibration (Table 2).
    pub calibration: CalibrationSection,
    /// The fitted model, when `rig explain` wrote one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelSection>,
    /// User-defined effects (`[[user_effects]]`), candidates of `rig explain`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub user_effects: Vec<UserEffectDef>,
}

/// `[[user_effects]]`: an effect of the user's own: a named expression for an extra current.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserEffectDef {
    /// Its name (not a library effect's).
    pub name: String,
    /// The extra current in A, an expression over the model's quantities and the parameters
    /// (checked by `rig explain`).
    pub expression: String,
    /// Its parameters by name.
    #[serde(default)]
    pub params: BTreeMap<String, UserParamDef>,
}

/// One parameter of a user effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserParamDef {
    /// Its unit (for reports).
    #[serde(default)]
    pub unit: String,
    /// The range the fit keeps it in, [low, high].
    pub bounds: [f64; 2],
    /// The value at which the effect vanishes (default 0).
    #[serde(default)]
    pub null: f64,
    /// The fit's start (default: `null`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<f64>,
    /// Fit the parameter in ln (a positive scale; bounds must be positive).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub log: bool,
}

/// `[gear]`: tooth counts, module and pressure angle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GearSection {
    /// Z1, Z2, Z3, Z4.
    pub z: [u32; 4],
    /// Module, mm.
    pub module_mm: f64,
    /// Pressure angle, degrees.
    pub pressure_angle_deg: f64,
}

impl Default for GearSection {
    fn default() -> Self {
        Self {
            z: model::paper::RIG_Z,
            module_mm: 1.0,
            pressure_angle_deg: 20.0,
        }
    }
}

/// `[cam]`: eccentricity and carrier mass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CamSection {
    /// Cam eccentricity e, mm.
    #[serde(alias = "e_mm")]
    pub eccentricity_mm: f64,
    /// Carrier mass M_hat, kg.
    pub carrier_mass_kg: f64,
}

impl Default for CamSection {
    fn default() -> Self {
        Self {
            eccentricity_mm: model::ECCENTRICITY_PAPER * 1e3,
            carrier_mass_kg: model::CARRIER_MASS_PAPER,
        }
    }
}

/// `[friction]`: static and dynamic friction coefficients of the teeth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrictionSection {
    /// Static friction coefficient (also the start value of the fitted mu).
    pub mu_s: f64,
    /// Dynamic friction coefficient.
    pub mu_d: f64,
}

impl Default for FrictionSection {
    fn default() -> Self {
        Self {
            mu_s: model::MU_S_PAPER,
            mu_d: model::MU_D_PAPER,
        }
    }
}

/// `[calibration]`: C1-C6 in the paper's units and the calibration temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationSection {
    /// C1, N mm/A.
    pub c1: f64,
    /// C2, N mm.
    pub c2: f64,
    /// C3, N mm s/rad.
    pub c3: f64,
    /// C4, N mm.
    pub c4: f64,
    /// C5, A s/rad.
    pub c5: f64,
    /// C6, A.
    pub c6: f64,
    /// Motor temperature at calibration, deg C (the thermal drift's reference).
    pub temperature_c: f64,
}

impl Default for CalibrationSection {
    fn default() -> Self {
        let [c1, c2, c3, c4, c5, c6] = Calibration::PAPER.to_paper_units();
        Self {
            c1,
            c2,
            c3,
            c4,
            c5,
            c6,
            temperature_c: 25.0,
        }
    }
}

/// How the plant (`model::plant`) runs a rig file's model: see [`RigFile::plant_effects`].
#[derive(Debug, Clone, PartialEq)]
pub struct PlantSetup {
    /// The plant's switchable effects.
    pub effects: model::plant::PlantEffects,
    /// Whether the drive regenerates (`PlantParams::regeneration`).
    pub regeneration: bool,
    /// Effects of the model the plant cannot represent.
    pub not_in_plant: Vec<Effect>,
}

/// `[model]`: the fitted model of the vibrator current.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    /// mu of Eq. (10) fitted to the current.
    pub mu: f64,
    /// The effects on top of the paper's model, strongest first.
    #[serde(default)]
    pub effects: Vec<EffectEntry>,
    /// Effects in a family form or of the user's own (`rig explain`'s terms).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub terms: Vec<TermEntry>,
}

/// `[[model.effects]]`: one effect with its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectEntry {
    /// The effect's name (e.g. `speed-dependent-axial-friction`).
    pub name: String,
    /// Its parameters by name (e.g. `omega_c_rad_s`).
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
}

/// `[[model.terms]]`: an effect of `rig explain`'s terms (`explain::terms`): a library effect
/// in one of its family forms, or a user effect of `[[user_effects]]`, with its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermEntry {
    /// The effect's name (a library effect's with `form`, else a user effect's).
    pub name: String,
    /// The family form of a library effect (e.g. `warm-up-in-time`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub form: Option<String>,
    /// Its parameters by name.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
}

impl RigFile {
    /// The paper's rig, no fitted model.
    pub fn paper() -> Self {
        Self::default()
    }

    /// Reads and checks a rig file.
    pub fn load(path: &Path) -> Result<Self, RigFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| RigFileError::File {
            action: "read",
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses and checks rig-file text; `name` names it in messages.
    pub fn parse(text: &str, name: &str) -> Result<Self, RigFileError> {
        let rig: RigFile = toml::from_str(text).map_err(|e| RigFileError::RigFile {
            file: name.to_string(),
            why: e.to_string().trim_end().to_string(),
        })?;
        rig.check(name)?;
        Ok(rig)
    }

    /// The file as TOML text.
    pub fn to_toml(&self) -> Result<String, RigFileError> {
        toml::to_string(self).map_err(|e| RigFileError::BadValue {
            what: "rig file".into(),
            why: format!("cannot be written as TOML: {e}"),
        })
    }

    /// Writes the file atomically: a failed write leaves an existing file untouched.
    pub fn save(&self, path: &Path) -> Result<(), RigFileError> {
        let text = format!(
            "# Rig file of the vibration-switched planetary gear (format: `rig explain --help`).\n{}",
            self.to_toml()?
        );
        reporting::write_atomic(path, text.as_bytes())?;
        Ok(())
    }

    fn check(&self, name: &str) -> Result<(), RigFileError> {
        let bad = |why: String| RigFileError::RigFile {
            file: name.to_string(),
            why,
        };
        self.drive().map_err(|e| match e {
            RigFileError::Gear { z, source } => bad(format!("[gear] z = {z:?}: {source}")),
            other => other,
        })?;
        let positive = [
            ("[cam] eccentricity_mm", self.cam.eccentricity_mm),
            ("[cam] carrier_mass_kg", self.cam.carrier_mass_kg),
            ("[calibration] c1", self.calibration.c1),
        ];
        for (what, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!("{what} = {v} must be a positive number")));
            }
        }
        let c = &self.calibration;
        for (what, v) in [
            ("[friction] mu_s", self.friction.mu_s),
            ("[friction] mu_d", self.friction.mu_d),
            ("[calibration] c2", c.c2),
            ("[calibration] c3", c.c3),
            ("[calibration] c4", c.c4),
            ("[calibration] c5", c.c5),
            ("[calibration] c6", c.c6),
            ("[calibration] temperature_c", c.temperature_c),
        ] {
            if !v.is_finite() {
                return Err(bad(format!("{what} = {v} is not a finite number")));
            }
        }
        if self.friction.mu_s < 0.0 || self.friction.mu_d < 0.0 {
            return Err(bad("friction coefficients must not be negative".into()));
        }
        let mut names: Vec<&str> = Vec::new();
        for u in &self.user_effects {
            let what = format!("[[user_effects]] {}", u.name);
            if u.name.is_empty()
                || Effect::from_name(&u.name).is_some()
                || names.contains(&u.name.as_str())
            {
                return Err(bad(format!(
                    "{what}: give each user effect a name of its own, not empty and not a library effect's"
                )));
            }
            names.push(&u.name);
            for (k, p) in &u.params {
                let [lo, hi] = p.bounds;
                let start = p.start.unwrap_or(p.null);
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(bad(format!(
                        "{what}: parameter {k} bounds = [{lo}, {hi}]: give finite bounds, low < high"
                    )));
                }
                if !(lo..=hi).contains(&p.null) || !(lo..=hi).contains(&start) {
                    return Err(bad(format!(
                        "{what}: parameter {k}: null {} and start {start} must lie within [{lo}, {hi}]",
                        p.null
                    )));
                }
                if p.log && lo <= 0.0 {
                    return Err(bad(format!(
                        "{what}: parameter {k} is fitted in ln (log = true): its bounds must be positive"
                    )));
                }
            }
        }
        for t in self.term_entries() {
            let known = match &t.form {
                Some(_) => Effect::from_name(&t.name).is_some(),
                None => names.contains(&t.name.as_str()),
            };
            if !known {
                return Err(bad(format!(
                    "[[model.terms]] {}: give a library effect's name with a form, or the name of a [[user_effects]] definition",
                    t.name
                )));
            }
        }
        if let Some(m) = &self.model {
            if !(m.mu.is_finite() && m.mu >= 0.0) {
                return Err(bad(format!("[model] mu = {} must be a number >= 0", m.mu)));
            }
            self.effects().map_err(|why| bad(why.to_string()))?;
        }
        Ok(())
    }

    /// The gear set, module and pressure angle in SI.
    pub fn gear_set(&self) -> Result<GearSet, RigFileError> {
        let g = &self.gear;
        GearSet::new(g.z, g.module_mm * 1e-3, g.pressure_angle_deg.to_radians())
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
        let c = &self.calibration;
        Calibration::from_paper_units([c.c1, c.c2, c.c3, c.c4, c.c5, c.c6])
    }

    /// The `[[model.terms]]` entries (`rig explain` checks their forms and parameters).
    pub fn term_entries(&self) -> &[TermEntry] {
        self.model.as_ref().map_or(&[], |m| m.terms.as_slice())
    }

    /// The library effects of `[model]` in their own laws with their parameters, in file
    /// order (the terms, [`RigFile::term_entries`], aside).
    pub fn effects(&self) -> Result<(Vec<Effect>, EffectParams), String> {
        let mut list = Vec::new();
        let mut params = EffectParams::default();
        let terms = self.term_entries();
        for entry in self.model.iter().flat_map(|m| &m.effects) {
            if terms.iter().any(|t| t.name == entry.name) {
                return Err(format!(
                    "effect {} is listed twice (once under [[model.terms]])",
                    entry.name
                ));
            }
            let effect = Effect::from_name(&entry.name).ok_or_else(|| {
                format!(
                    "unknown effect '{}' (known: {})",
                    entry.name,
                    Effect::ALL.map(|e| e.name()).join(", ")
                )
            })?;
            if list.contains(&effect) {
                return Err(format!("effect {} is listed twice", entry.name));
            }
            apply_params(effect, &entry.params, &mut params)?;
            list.push(effect);
        }
        Ok((list, params))
    }

    /// The current model this file describes: the fitted mu and effects of `[model]`, or the
    /// paper's model with mu = mu_s when there is none.
    pub fn current_model(&self) -> Result<CurrentModel, RigFileError> {
        let mut m = CurrentModel::paper(
            self.drive()?,
            self.calibration(),
            self.model.as_ref().map_or(self.friction.mu_s, |m| m.mu),
        );
        m.effects = self
            .effects()
            .map_err(|why| RigFileError::RigFile {
                file: "(in memory)".into(),
                why,
            })?
            .1;
        Ok(m)
    }

    /// The plant's switchable effects (`model::plant`) for the effects of `[model]`, so the
    /// simulator can run the augmented model, with the names of the effects the plant cannot
    /// represent. Exact: load-dependent friction, current offset, thermal drift (per K),
    /// viscous loss, linear bush (lever arm = hold / force); inertia rectification maps to the
    /// drive's regeneration (kappa < -0.75: regenerating). Not in the plant: the
    /// speed-dependent axial friction of Eq. (40) with a fixed corner speed (the plant's
    /// `friction_split` applies Eq. 40 with the simulated output speed instead), tooth
    /// compliance, the mesh ripple and a thermal drift against time.
    pub fn plant_effects(&self) -> Result<PlantSetup, RigFileError> {
        let (list, p) = self.effects().map_err(|why| RigFileError::RigFile {
            file: "(in memory)".into(),
            why,
        })?;
        let mut out = model::plant::PlantEffects::default();
        let mut regeneration = true;
        let mut missing = Vec::new();
        let time_driven = self
            .model
            .iter()
            .flat_map(|m| &m.effects)
            .any(|e| e.params.contains_key("k_per_s"));
        for e in list {
            match e {
                Effect::LoadDependentFriction => {
                    out.load_friction =
                        Some((p.load_exponent, model::effects::LOAD_FRICTION_REFERENCE_NM));
                }
                Effect::CurrentSensorOffset => out.current_offset = p.current_offset,
                Effect::ThermalDrift if !time_driven => out.thermal_drift = Some(p.thermal_coeff),
                Effect::VibratorViscousLoss => out.extra_viscous = p.viscous_loss,
                Effect::LinearBushFriction if p.bush_force > 0.0 => {
                    out.bush_friction = p.bush_force;
                    out.bush_hold_arm = p.bush_hold_torque / p.bush_force;
                    out.bush_omega = p.bush_corner_speed;
                }
                Effect::InertiaRectification => regeneration = p.rectification < -0.75,
                other => missing.push(other),
            }
        }
        Ok(PlantSetup {
            effects: out,
            regeneration,
            not_in_plant: missing,
        })
    }

    /// This rig with `[model]` set to `mu` and `effects` (name and parameters each).
    pub fn with_model(&self, mu: f64, effects: Vec<EffectEntry>) -> Self {
        self.with_model_terms(mu, effects, Vec::new())
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

/// Sets the effect's parameters in `p` from reported (rig-file) names, as the model's effect
/// table ([`model::effects::EFFECTS`]) names them with their units; unknown names are an
/// error naming the expected ones, a fixed parameter must keep its value. Missing names keep
/// their value in `p`.
pub fn apply_params(
    effect: Effect,
    params: &BTreeMap<String, f64>,
    p: &mut EffectParams,
) -> Result<(), String> {
    let info = effect.info();
    for (k, &v) in params {
        let Some(param) = info.param(k) else {
            return Err(format!(
                "effect {} has no parameter {k} (it takes {})",
                effect.name(),
                info.keys().collect::<Vec<_>>().join(", ")
            ));
        };
        if !v.is_finite() {
            return Err(format!("{} {k} = {v} is not finite", effect.name()));
        }
        if let ParamValue::Fixed(fixed) = param.value
            && (v - fixed).abs() > 1e-12
        {
            return Err(format!(
                "{} {k} is fixed at {fixed} {}",
                effect.name(),
                param.unit
            ));
        }
        param.apply(p, v);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_is_the_paper_rig() {
        let r = RigFile::parse("", "rig.toml").unwrap();
        assert_eq!(r, RigFile::paper());
        let d = r.drive().unwrap();
        assert_eq!(d.gear.z(), [49, 51, 50, 50]);
        assert!((d.eccentricity - 1e-3).abs() < 1e-15);
        assert!((r.calibration().c1 - Calibration::PAPER.c1).abs() < 1e-15);
        let m = r.current_model().unwrap();
        assert_eq!(m.mu, model::MU_S_PAPER);
    }

    #[test]
    fn other_gear_set_and_aliases() {
        let text = "[gear]\nz = [52, 48, 50, 50]\n[cam]\ne_mm = 0.5\n";
        let r = RigFile::parse(text, "rig.toml").unwrap();
        assert_eq!(r.gear_set().unwrap().z(), [52, 48, 50, 50]);
        assert_eq!(r.cam.eccentricity_mm, 0.5);
    }

    #[test]
    fn mistakes_are_named() {
        let e = RigFile::parse("[cam]\neccentricty_mm = 1.0\n", "rig.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("rig.toml") && e.contains("eccentricty_mm"),
            "{e}"
        );
        let e = RigFile::parse("[gear]\nz = [49, 51, 50, 51]\n", "rig.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unequal centre distances"), "{e}");
        let e = RigFile::parse(
            "[model]\nmu = 0.2\n[[model.effects]]\nname = \"gremlins\"\n",
            "rig.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("unknown effect 'gremlins'"), "{e}");
    }

    #[test]
    fn plant_runs_the_augmented_model() {
        let text = "[model]\nmu = 0.25\n[[model.effects]]\nname = \"current-sensor-offset\"\nparams = { offset_a = 0.04 }\n[[model.effects]]\nname = \"linear-bush-friction\"\nparams = { force_n = 4.0, hold_nm = 0.8, omega_b_rad_s = 40.0 }\n[[model.effects]]\nname = \"tooth-compliance\"\nparams = { compliance_um_per_n = 1.0 }\n";
        let r = RigFile::parse(text, "rig.toml").unwrap();
        let setup = r.plant_effects().unwrap();
        let plant = setup.effects;
        assert_eq!(plant.current_offset, 0.04);
        assert!((plant.bush_hold_torque(0.0) - 0.8).abs() < 1e-12);
        assert!((plant.bush_hold_torque(40.0) - 0.4).abs() < 1e-12);
        assert!(setup.regeneration);
        assert_eq!(setup.not_in_plant, [Effect::ToothCompliance]);
    }

    #[test]
    fn model_round_trips() {
        let mut params = BTreeMap::new();
        params.insert("omega_c_rad_s".to_string(), 21.0);
        let r = RigFile::paper().with_model(
            0.25,
            vec![EffectEntry {
                name: "speed-dependent-axial-friction".into(),
                params,
            }],
        );
        let back = RigFile::parse(&r.to_toml().unwrap(), "rig.toml").unwrap();
        assert_eq!(back, r);
        let m = back.current_model().unwrap();
        assert_eq!(m.mu, 0.25);
        assert_eq!(m.effects.axial_corner_speed, 21.0);
    }

    #[test]
    fn user_effects_and_terms_round_trip() {
        let text = "[[user_effects]]\nname = \"brush-drag\"\nexpression = \"c * (w / 100)^2\"\nparams = { c = { unit = \"A\", bounds = [-0.5, 0.5] } }\n[model]\nmu = 0.27\n[[model.effects]]\nname = \"current-sensor-offset\"\nparams = { offset_a = 0.01 }\n[[model.terms]]\nname = \"brush-drag\"\nparams = { c = 0.1 }\n[[model.terms]]\nname = \"thermal-drift\"\nform = \"warm-up-in-time\"\nparams = { k_per_s = 1e-6, tau_s = 900.0 }\n";
        let r = RigFile::parse(text, "rig.toml").unwrap();
        assert_eq!(r.user_effects[0].params["c"].bounds, [-0.5, 0.5]);
        assert_eq!(r.term_entries().len(), 2);
        let (effects, p) = r.effects().unwrap();
        assert_eq!(effects, [Effect::CurrentSensorOffset]);
        assert_eq!(p.current_offset, 0.01);
        let back = RigFile::parse(&r.to_toml().unwrap(), "back.toml").unwrap();
        assert_eq!(back, r);
        // A term that names nothing known, a library name used twice, bad bounds.
        let e = RigFile::parse(
            "[model]\nmu = 0.27\n[[model.terms]]\nname = \"gremlin\"\n",
            "r.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("gremlin") && e.contains("[[user_effects]]"),
            "{e}"
        );
        let e = RigFile::parse("[model]\nmu = 0.27\n[[model.effects]]\nname = \"thermal-drift\"\n[[model.terms]]\nname = \"thermal-drift\"\nform = \"warm-up-in-time\"\n", "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("listed twice"), "{e}");
        let e = RigFile::parse("[[user_effects]]\nname = \"x\"\nexpression = \"c\"\nparams = { c = { bounds = [1.0, -1.0] } }\n", "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("low < high"), "{e}");
    }
}
