//! The sections of the rig file. C1-C6 are a [`model::Calibration`] (SI) that reads and
//! writes the keys `c1`..`c6` in the paper's units ([`crate::paper_units`]).

use std::collections::BTreeMap;

use serde::de::{self, MapAccess, Visitor};
use serde::ser::SerializeStruct;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::paper_units;

/// `[gear]`: tooth counts, module, pressure angle and profile shifts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GearSection {
    /// Z1, Z2, Z3, Z4.
    pub z: [u32; 4],
    /// Module, mm.
    pub module_mm: f64,
    /// Pressure angle, degrees.
    pub pressure_angle_deg: f64,
    /// Profile shift coefficients x1..x4 (written only when a gear is shifted, so files of
    /// standard gears stay as they were).
    #[serde(skip_serializing_if = "is_standard")]
    pub profile_shift: [f64; 4],
}

fn is_standard(x: &[f64; 4]) -> bool {
    *x == [0.0; 4]
}

impl Default for GearSection {
    fn default() -> Self {
        Self {
            z: [49, 51, 50, 50],
            module_mm: paper_units::tidy(model::GearSet::MODULE_PAPER * 1e3),
            pressure_angle_deg: paper_units::tidy(
                model::GearSet::PRESSURE_ANGLE_STANDARD.to_degrees(),
            ),
            profile_shift: [0.0; 4],
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
            eccentricity_mm: paper_units::tidy(model::ECCENTRICITY_PAPER * 1e3),
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

/// `[calibration]`: the vibrator's C1-C6, the calibration temperature and, when
/// `rig calibrate` measured them, the fit statistics.
///
/// In the file C1-C6 are the keys `c1`..`c6` in the paper's units (Table 2); in memory they
/// are one [`model::Calibration`] in SI.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationSection {
    /// C1-C6 (SI).
    pub constants: model::Calibration,
    /// Motor temperature at calibration, deg C (the thermal drift's reference).
    pub temperature_c: f64,
    /// `[calibration.fit]`: how `rig calibrate` got the constants.
    pub fit: Option<FitSection>,
}

/// Motor temperature the paper's calibration is taken to refer to, deg C (room temperature;
/// the simulated motor's ambient).
pub const CALIBRATION_TEMPERATURE_C: f64 = 25.0;

impl Default for CalibrationSection {
    fn default() -> Self {
        Self {
            constants: model::Calibration::PAPER,
            temperature_c: CALIBRATION_TEMPERATURE_C,
            fit: None,
        }
    }
}

/// The keys of `[calibration]`, in the order written.
const CALIBRATION_KEYS: [&str; 8] = ["c1", "c2", "c3", "c4", "c5", "c6", "temperature_c", "fit"];

/// A key of `[calibration]` (unknown ones are an error naming the key).
#[derive(Deserialize, Clone, Copy)]
#[serde(field_identifier, rename_all = "snake_case")]
enum CalibrationKey {
    C1,
    C2,
    C3,
    C4,
    C5,
    C6,
    TemperatureC,
    Fit,
}

impl Serialize for CalibrationSection {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("CalibrationSection", 8)?;
        for (k, v) in paper_units::KEYS
            .iter()
            .zip(paper_units::to_paper(&self.constants))
        {
            st.serialize_field(k, &v)?;
        }
        st.serialize_field("temperature_c", &self.temperature_c)?;
        match &self.fit {
            Some(fit) => st.serialize_field("fit", fit)?,
            None => st.skip_field("fit")?,
        }
        st.end()
    }
}

impl<'de> Deserialize<'de> for CalibrationSection {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Section;
        impl<'de> Visitor<'de> for Section {
            type Value = CalibrationSection;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("the [calibration] table (c1..c6, temperature_c, fit)")
            }

            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = CalibrationSection::default();
                let mut c = paper_units::to_paper(&out.constants);
                let mut seen = [false; CALIBRATION_KEYS.len()];
                while let Some(key) = map.next_key::<CalibrationKey>()? {
                    let i = key as usize;
                    if std::mem::replace(&mut seen[i], true) {
                        return Err(de::Error::duplicate_field(CALIBRATION_KEYS[i]));
                    }
                    match key {
                        CalibrationKey::TemperatureC => out.temperature_c = map.next_value()?,
                        CalibrationKey::Fit => out.fit = Some(map.next_value()?),
                        _ => c[i] = map.next_value()?,
                    }
                }
                out.constants = paper_units::from_paper(c);
                Ok(out)
            }
        }
        d.deserialize_struct("CalibrationSection", &CALIBRATION_KEYS, Section)
    }
}

/// `[calibration.fit]`: the statistics of `rig calibrate`'s fits, in the paper's units
/// (informational: no reader uses them). Every key is required when the section is there.
#[derive(Debug, Clone, PartialEq)]
pub struct FitSection {
    /// Torque steps in the fit of C1, C2 (`torque_points`).
    pub torque_points: u32,
    /// R^2 of the torque-current fit (`torque_r_squared`).
    pub torque_r_squared: f64,
    /// Residual standard deviation of the torque-current fit, N mm (`torque_residual_sd_nmm`).
    pub torque_residual_sd_nmm: f64,
    /// No-load steps in the fit of C5, C6 (`no_load_points`).
    pub no_load_points: u32,
    /// R^2 of the no-load fit (`no_load_r_squared`).
    pub no_load_r_squared: f64,
    /// Residual standard deviation of the no-load fit, A (`no_load_residual_sd_a`).
    pub no_load_residual_sd_a: f64,
    /// 95 % intervals `[low, high]` of C1..C6 in the paper's units (`c1_ci95`..`c6_ci95`;
    /// those of C3 and C4 propagated from C1 C5 and C1 C6 + C2).
    pub ci95: [[f64; 2]; 6],
    /// The direct fit of the loss torque against cam speed: slope (C3, N mm s/rad) and
    /// intercept (C4, N mm) (`c3_direct`, `c4_direct`).
    pub loss_direct: [f64; 2],
    /// Whether the direct fit agrees with C1 C5 and C1 C6 + C2 (`consistent`).
    pub consistent: bool,
}

/// The keys of `[calibration.fit]`, in the order written (that of the older `[fit]`).
const FIT_KEYS: [&str; 15] = [
    "torque_points",
    "torque_r_squared",
    "torque_residual_sd_nmm",
    "c1_ci95",
    "c2_ci95",
    "no_load_points",
    "no_load_r_squared",
    "no_load_residual_sd_a",
    "c5_ci95",
    "c6_ci95",
    "c3_ci95",
    "c4_ci95",
    "c3_direct",
    "c4_direct",
    "consistent",
];

/// A key of `[calibration.fit]`, in [`FIT_KEYS`] order.
#[derive(Deserialize, Clone, Copy)]
#[serde(field_identifier, rename_all = "snake_case")]
enum FitKey {
    TorquePoints,
    TorqueRSquared,
    TorqueResidualSdNmm,
    C1Ci95,
    C2Ci95,
    NoLoadPoints,
    NoLoadRSquared,
    NoLoadResidualSdA,
    C5Ci95,
    C6Ci95,
    C3Ci95,
    C4Ci95,
    C3Direct,
    C4Direct,
    Consistent,
}

impl FitKey {
    /// Which constant's interval (0-based C index) the key is, if it is one.
    fn interval_of(self) -> Option<usize> {
        match self {
            FitKey::C1Ci95 => Some(0),
            FitKey::C2Ci95 => Some(1),
            FitKey::C3Ci95 => Some(2),
            FitKey::C4Ci95 => Some(3),
            FitKey::C5Ci95 => Some(4),
            FitKey::C6Ci95 => Some(5),
            _ => None,
        }
    }
}

impl Serialize for FitSection {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("FitSection", FIT_KEYS.len())?;
        st.serialize_field("torque_points", &self.torque_points)?;
        st.serialize_field("torque_r_squared", &self.torque_r_squared)?;
        st.serialize_field("torque_residual_sd_nmm", &self.torque_residual_sd_nmm)?;
        st.serialize_field("c1_ci95", &self.ci95[0])?;
        st.serialize_field("c2_ci95", &self.ci95[1])?;
        st.serialize_field("no_load_points", &self.no_load_points)?;
        st.serialize_field("no_load_r_squared", &self.no_load_r_squared)?;
        st.serialize_field("no_load_residual_sd_a", &self.no_load_residual_sd_a)?;
        st.serialize_field("c5_ci95", &self.ci95[4])?;
        st.serialize_field("c6_ci95", &self.ci95[5])?;
        st.serialize_field("c3_ci95", &self.ci95[2])?;
        st.serialize_field("c4_ci95", &self.ci95[3])?;
        st.serialize_field("c3_direct", &self.loss_direct[0])?;
        st.serialize_field("c4_direct", &self.loss_direct[1])?;
        st.serialize_field("consistent", &self.consistent)?;
        st.end()
    }
}

impl<'de> Deserialize<'de> for FitSection {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Section;
        impl<'de> Visitor<'de> for Section {
            type Value = FitSection;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("the [calibration.fit] table")
            }

            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut seen = [false; FIT_KEYS.len()];
                let mut points = [0u32; 2];
                let mut stats = [0.0f64; 4];
                let mut ci95 = [[0.0f64; 2]; 6];
                let mut loss_direct = [0.0f64; 2];
                let mut consistent = false;
                while let Some(key) = map.next_key::<FitKey>()? {
                    let i = key as usize;
                    if std::mem::replace(&mut seen[i], true) {
                        return Err(de::Error::duplicate_field(FIT_KEYS[i]));
                    }
                    if let Some(c) = key.interval_of() {
                        ci95[c] = map.next_value()?;
                        continue;
                    }
                    match key {
                        FitKey::TorquePoints => points[0] = map.next_value()?,
                        FitKey::NoLoadPoints => points[1] = map.next_value()?,
                        FitKey::TorqueRSquared => stats[0] = map.next_value()?,
                        FitKey::TorqueResidualSdNmm => stats[1] = map.next_value()?,
                        FitKey::NoLoadRSquared => stats[2] = map.next_value()?,
                        FitKey::NoLoadResidualSdA => stats[3] = map.next_value()?,
                        FitKey::C3Direct => loss_direct[0] = map.next_value()?,
                        FitKey::C4Direct => loss_direct[1] = map.next_value()?,
                        _ => consistent = map.next_value()?,
                    }
                }
                if let Some(i) = seen.iter().position(|s| !s) {
                    return Err(de::Error::missing_field(FIT_KEYS[i]));
                }
                Ok(FitSection {
                    torque_points: points[0],
                    torque_r_squared: stats[0],
                    torque_residual_sd_nmm: stats[1],
                    no_load_points: points[1],
                    no_load_r_squared: stats[2],
                    no_load_residual_sd_a: stats[3],
                    ci95,
                    loss_direct,
                    consistent,
                })
            }
        }
        d.deserialize_struct("FitSection", &FIT_KEYS, Section)
    }
}

/// `[limits]`: what the firmware enforces.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LimitsSection {
    /// Largest output load the firmware will release, N m.
    pub max_release_load_nm: f64,
    /// Motor current limit, A.
    pub max_current_a: f64,
    /// Highest vibration frequency the firmware will drive, Hz.
    pub max_freq_hz: f64,
}

impl Default for LimitsSection {
    fn default() -> Self {
        // The device's defaults, one source: the wire record's `paper()`.
        let p = protocol::RigParameters::paper();
        let f = |v: f32| reporting::human_f64(f64::from(v));
        Self {
            max_release_load_nm: f(p.max_release_load_nm),
            max_current_a: f(p.max_current_a),
            max_freq_hz: f(p.max_freq_hz),
        }
    }
}

/// `[load]`: the bench around the rig's output, as far as the virtual rig's plant needs it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoadSection {
    /// How far a load hung on the output pulley falls before it rests on the floor, m
    /// (the virtual rig's output then stands still, the rope slack).
    pub drop_m: f64,
}

impl Default for LoadSection {
    fn default() -> Self {
        Self {
            drop_m: model::hardware::bench::LOAD_DROP_M,
        }
    }
}

impl LoadSection {
    /// The output's travel from where a load is hung to where it rests, rad
    /// ([`model::hardware::bench::output_travel_rad`]).
    pub fn output_travel_rad(&self) -> f64 {
        model::hardware::bench::output_travel_rad(self.drop_m)
    }

    /// Whether this is the default bench (the section is then left out of written files).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// `[drive]`: which drive the rig's H-bridge is, the one setting the virtual rig's plant,
/// the firmware's estimator and `rig explain`'s base model read for a rig
/// (`model::hardware::board::DECAY` is the board's default).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveSection {
    /// What the bridge does in the PWM's off-time: `brake` (slow decay, the Pololu G2:
    /// power returns through the gearhead) or `coast` (nothing returns).
    pub decay: DecayMode,
}

impl Default for DriveSection {
    fn default() -> Self {
        Self {
            decay: DecayMode::from(model::hardware::board::DECAY),
        }
    }
}

/// A bridge's decay mode as a rig file names it (`[drive] decay`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DecayMode {
    /// Slow decay (both low sides on in the off-time): the carrier's power returns.
    Brake,
    /// The off-time coasts: nothing returns.
    Coast,
}

impl DecayMode {
    /// Whether the drive takes the carrier's power back (`PlantParams::regeneration`,
    /// the estimator's `carrier_power_returned`).
    pub const fn returns_power(self) -> bool {
        matches!(self, Self::Brake)
    }

    /// `brake` or `coast`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Brake => "brake",
            Self::Coast => "coast",
        }
    }

    /// The mode of a drive that does (`true`) or does not take power back.
    pub const fn from_returns_power(returned: bool) -> Self {
        if returned { Self::Brake } else { Self::Coast }
    }
}

impl From<model::hardware::board::Decay> for DecayMode {
    fn from(d: model::hardware::board::Decay) -> Self {
        Self::from_returns_power(d.returns_power())
    }
}

/// `[model]`: the fitted model of the vibrator current.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    /// mu of Eq. (10) fitted to the current.
    pub mu: f64,
    /// The effects on top of the paper's model, strongest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
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

/// `[[user_effects]]`: an effect of the user's own: a named expression for an extra current
/// (`docs/rig-file.md`, "User-defined effects").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserEffectDef {
    /// Its name (not a library effect's).
    pub name: String,
    /// The extra current in A, an expression over the model's quantities and the parameters
    /// (compiled when the file is read: [`crate::UserLaw`]).
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
