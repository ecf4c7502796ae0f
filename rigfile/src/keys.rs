//! Every section and key of the rig file with its unit, allowed range and default: the one
//! table `docs/rig-file.md` documents (a test checks that the document lists exactly these),
//! the loader uses to say which keys a file left at their defaults, and the range checks
//! quote in their messages.

use std::fmt;

use model::effects::Effect;

/// One key of the rig file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeySpec {
    /// The section, as written in the header (`gear`, `calibration.fit`, `model.effects`).
    pub section: &'static str,
    /// The key.
    pub key: &'static str,
    /// Other names the reader accepts for the key.
    pub aliases: &'static [&'static str],
    /// Unit ("-" for a pure number).
    pub unit: &'static str,
    /// What values are allowed, in words (quoted by the range checks: "it must be ...").
    pub range: &'static str,
    /// The default as TOML text, "-" when the key has none (required in its section).
    pub default: &'static str,
    /// The field of the device's calibration record (`protocol::RigParameters`) that carries
    /// the key, which is also the key's name in the older flat calibration file.
    pub wire: Option<&'static str>,
    /// What the key means.
    pub meaning: &'static str,
}

impl KeySpec {
    /// The key as a reader finds it: `[section] key`.
    pub fn path(&self) -> String {
        format!("[{}] {}", self.section, self.key)
    }
}

impl fmt::Display for KeySpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}] {}", self.section, self.key)
    }
}

/// The sections a rig file may have; any other section is kept as it is but not read.
pub const SECTIONS: [&str; 9] = [
    "gear",
    "cam",
    "friction",
    "calibration",
    "limits",
    "drive",
    "load",
    "model",
    "user_effects",
];

const fn key(
    section: &'static str,
    key: &'static str,
    unit: &'static str,
    range: &'static str,
    default: &'static str,
    wire: Option<&'static str>,
    meaning: &'static str,
) -> KeySpec {
    KeySpec {
        section,
        key,
        aliases: &[],
        unit,
        range,
        default,
        wire,
        meaning,
    }
}

const FIT_RANGE: &str = "as fitted (not checked)";

/// Every key of the rig file, section by section.
pub const KEYS: &[KeySpec] = &[
    key(
        "gear",
        "z",
        "-",
        "four tooth counts from 4 to 65535 with Z1 + Z2 = Z3 + Z4 (unless profile_shift gives both meshes one working centre distance), Z1 != Z4 and Z1 Z3 != Z2 Z4",
        "[49, 51, 50, 50]",
        Some("z"),
        "tooth counts Z1 (fixed), Z2, Z3 (the compound planet), Z4 (output)",
    ),
    key(
        "gear",
        "module_mm",
        "mm",
        "positive, at most 100",
        "1.0",
        Some("module_mm"),
        "gear module",
    ),
    key(
        "gear",
        "pressure_angle_deg",
        "deg",
        "between 0 and 45, both excluded",
        "20.0",
        Some("pressure_angle_deg"),
        "pressure angle",
    ),
    key(
        "gear",
        "profile_shift",
        "-",
        "four coefficients from -1 to 2 giving both meshes one working centre distance (within 0.001 module)",
        "[0.0, 0.0, 0.0, 0.0]",
        // On the record (`profile_shift`, protocol v7) but not a wire key: the older flat
        // file never had it, and a file of standard gears leaves it out without being told
        // it took a default.
        None,
        "profile shift coefficients x1..x4 (ISO 21771; `rig design --x`, `rig design search --write`)",
    ),
    KeySpec {
        aliases: &["e_mm"],
        ..key(
            "cam",
            "eccentricity_mm",
            "mm",
            "positive, at most 100",
            "1.0",
            Some("eccentricity_mm"),
            "cam eccentricity e, the vibration amplitude",
        )
    },
    key(
        "cam",
        "carrier_mass_kg",
        "kg",
        "positive, at most 1000",
        "3.82",
        Some("carrier_mass_kg"),
        "vibrating mass M_hat = M1 + M23",
    ),
    key(
        "friction",
        "mu_s",
        "-",
        "between 0 and 1, both excluded",
        "0.271",
        Some("mu_s"),
        "static tooth friction coefficient (also the start value of the fitted mu)",
    ),
    key(
        "friction",
        "mu_d",
        "-",
        "positive and not above mu_s",
        "0.174",
        Some("mu_d"),
        "dynamic tooth friction coefficient",
    ),
    key(
        "calibration",
        "c1",
        "N mm/A",
        "positive, at most 1000",
        "62.1",
        Some("c1_nmm_per_a"),
        "C1 of Eq. (15): cam torque = C1 i_in + C2",
    ),
    key(
        "calibration",
        "c2",
        "N mm",
        "from -10000 to 10000",
        "-138.0",
        Some("c2_nmm"),
        "C2 of Eq. (15)",
    ),
    key(
        "calibration",
        "c3",
        "N mm s/rad",
        "zero or positive, at most 100",
        "0.235",
        Some("c3_nmm_s_per_rad"),
        "C3 of Eq. (16): vibrator loss torque = C3 w_n + C4",
    ),
    key(
        "calibration",
        "c4",
        "N mm",
        "from -10000 to 10000",
        "1.69",
        Some("c4_nmm"),
        "C4 of Eq. (16)",
    ),
    key(
        "calibration",
        "c5",
        "A s/rad",
        "zero or positive, at most 1",
        "0.00378",
        Some("c5_a_s_per_rad"),
        "C5 of Eq. (17): no-load current = C5 w_n + C6",
    ),
    key(
        "calibration",
        "c6",
        "A",
        "zero or positive, at most 100",
        "2.25",
        Some("c6_a"),
        "C6 of Eq. (17)",
    ),
    key(
        "calibration",
        "temperature_c",
        "deg C",
        "from -273.15 (absolute zero) to 1000",
        "25.0",
        None,
        "motor temperature at calibration (the thermal drift's reference)",
    ),
    key(
        "calibration.fit",
        "torque_points",
        "-",
        FIT_RANGE,
        "-",
        None,
        "torque steps in the fit of C1, C2",
    ),
    key(
        "calibration.fit",
        "torque_r_squared",
        "-",
        FIT_RANGE,
        "-",
        None,
        "R^2 of the torque-current fit",
    ),
    key(
        "calibration.fit",
        "torque_residual_sd_nmm",
        "N mm",
        FIT_RANGE,
        "-",
        None,
        "residual standard deviation of the torque-current fit",
    ),
    key(
        "calibration.fit",
        "c1_ci95",
        "N mm/A",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C1, [low, high]",
    ),
    key(
        "calibration.fit",
        "c2_ci95",
        "N mm",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C2",
    ),
    key(
        "calibration.fit",
        "no_load_points",
        "-",
        FIT_RANGE,
        "-",
        None,
        "no-load steps in the fit of C5, C6 (stalled ones left out)",
    ),
    key(
        "calibration.fit",
        "no_load_r_squared",
        "-",
        FIT_RANGE,
        "-",
        None,
        "R^2 of the no-load fit",
    ),
    key(
        "calibration.fit",
        "no_load_residual_sd_a",
        "A",
        FIT_RANGE,
        "-",
        None,
        "residual standard deviation of the no-load fit",
    ),
    key(
        "calibration.fit",
        "c5_ci95",
        "A s/rad",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C5",
    ),
    key(
        "calibration.fit",
        "c6_ci95",
        "A",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C6",
    ),
    key(
        "calibration.fit",
        "c3_ci95",
        "N mm s/rad",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C3 = C1 C5 (propagated from both fits, Student's t at the Welch-Satterthwaite degrees of freedom)",
    ),
    key(
        "calibration.fit",
        "c4_ci95",
        "N mm",
        FIT_RANGE,
        "-",
        None,
        "95 % interval of C4 = C1 C6 + C2 (propagated from both fits, Student's t at the Welch-Satterthwaite degrees of freedom)",
    ),
    key(
        "calibration.fit",
        "c3_direct",
        "N mm s/rad",
        FIT_RANGE,
        "-",
        None,
        "slope of the direct fit of the loss torque against cam speed",
    ),
    key(
        "calibration.fit",
        "c4_direct",
        "N mm",
        FIT_RANGE,
        "-",
        None,
        "intercept of that fit",
    ),
    key(
        "calibration.fit",
        "consistent",
        "-",
        "true or false",
        "-",
        None,
        "whether the direct fit agrees with C1 C5 and C1 C6 + C2 within their intervals",
    ),
    key(
        "limits",
        "max_release_load_nm",
        "N m",
        "positive, at most 1000",
        "3.68",
        Some("max_release_load_nm"),
        "largest output load the firmware will release",
    ),
    key(
        "limits",
        "max_current_a",
        "A",
        "positive, at most 100",
        "4.5",
        Some("max_current_a"),
        "motor current limit",
    ),
    key(
        "limits",
        "max_freq_hz",
        "Hz",
        "positive, at most 100",
        "15.0",
        Some("max_freq_hz"),
        "highest vibration frequency the firmware will drive",
    ),
    key(
        "drive",
        "decay",
        "-",
        "`brake` or `coast`",
        "\"brake\"",
        None,
        "what the H-bridge does in the PWM's off-time: `brake` (slow decay, the Pololu G2: the carrier's power returns through the gearhead, kappa -0.82) or `coast` (nothing returns, kappa -1/2); the virtual rig, the estimator and `rig explain`'s base model follow it",
    ),
    key(
        "load",
        "drop_m",
        "m",
        "from 0.05 to 20",
        "2.0",
        None,
        "how far a load hung on the output pulley falls before it rests on the floor (the virtual rig's output then stands still, its rope slack); the drop unwound from the 75 mm pulley is the output's travel (2 m: 26.7 rad)",
    ),
    key(
        "model",
        "mu",
        "-",
        "from 0 to 3 (the fit's bounds)",
        "-",
        None,
        "mu of Eq. (10) fitted to the vibrator current",
    ),
    key(
        "model",
        "effects",
        "-",
        "an array of `[[model.effects]]` tables",
        "[]",
        None,
        "the effects on top of the paper's model, strongest first",
    ),
    key(
        "model.effects",
        "name",
        "-",
        "an effect name (see Effects)",
        "-",
        None,
        "the effect",
    ),
    key(
        "model.effects",
        "params",
        "-",
        "a table of the effect's parameters (see Effects)",
        "{}",
        None,
        "its parameters; one left out starts at zero",
    ),
];

/// The key `key` (or an alias of it) of `section`.
pub fn find(section: &str, key: &str) -> Option<&'static KeySpec> {
    KEYS.iter()
        .find(|k| k.section == section && (k.key == key || k.aliases.contains(&key)))
}

/// The key carried by field `field` of the device's calibration record (the older flat
/// calibration file's key of the same name).
pub fn by_wire(field: &str) -> Option<&'static KeySpec> {
    KEYS.iter().find(|k| k.wire == Some(field))
}

/// The keys the device's calibration record carries, in the record's order.
pub fn wire_keys() -> impl Iterator<Item = &'static KeySpec> {
    KEYS.iter().filter(|k| k.wire.is_some())
}

/// One parameter of an effect in `[[model.effects]] params`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectParamSpec {
    /// The effect.
    pub effect: Effect,
    /// The parameter's name.
    pub name: &'static str,
    /// Its unit.
    pub unit: &'static str,
    /// The range a rig file's value must lie in, [low, high] (the range the fit keeps it
    /// in; a fixed parameter's value twice).
    pub bounds: (f64, f64),
    /// What it means and what the reader does with it.
    pub meaning: &'static str,
}

impl EffectParamSpec {
    /// [`EffectParamSpec::bounds`] in words, as the range check quotes it.
    pub fn range(&self) -> String {
        range_text(self.bounds)
    }
}

/// A parameter's range `[lo, hi]` in words: `from lo to hi`, `at least lo`, `exactly v`.
pub fn range_text((lo, hi): (f64, f64)) -> String {
    if lo == hi {
        format!("exactly {lo}")
    } else if hi.is_finite() {
        format!("from {lo} to {hi}")
    } else {
        format!("at least {lo}")
    }
}

/// The parameters each effect takes (names as `rig explain` reports them), read from the
/// model's effects table ([`model::effects::EFFECTS`]): the one place they are defined.
pub fn effect_params() -> Vec<EffectParamSpec> {
    model::effects::EFFECTS
        .iter()
        .flat_map(|info| {
            info.params.iter().map(move |p| EffectParamSpec {
                effect: info.effect,
                name: p.key,
                unit: p.unit,
                bounds: match p.value {
                    model::effects::ParamValue::Fixed(v) => (v, v),
                    _ => p.bounds,
                },
                meaning: p.meaning,
            })
        })
        .collect()
}

/// The parameter names effect `effect` takes.
pub fn effect_param_names(effect: Effect) -> Vec<&'static str> {
    effect.info().keys().collect()
}
