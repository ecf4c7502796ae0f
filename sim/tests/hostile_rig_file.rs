//! Hostile rig files (issue 33): extreme floats and integers (NaN, infinities, 1e308, -0,
//! subnormals, values past `f32` and `u32`) in every number a rig file gives, one or several
//! at a time. Nothing panics: the file is refused with a message naming the file and a key
//! it set, or it gives a usable rig: its conversions succeed, the virtual rig builds from
//! it, boots and runs with finite state, and it writes back to a file that reads the same.

use proptest::prelude::*;
use rigfile::RigFile;
use sim::{SimConfig, SimRig};

/// Floats as a careless or hostile user types them (TOML spellings).
fn extreme_float() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e308".to_string()),
        Just("-1e308".to_string()),
        Just("3.4e38".to_string()),
        Just("1e30".to_string()),
        Just("-1e30".to_string()),
        Just("0.0".to_string()),
        Just("-0.0".to_string()),
        Just("5e-324".to_string()),
        Just("1e-45".to_string()),
        Just("1e-30".to_string()),
        Just("-1.0".to_string()),
        Just("1e6".to_string()),
        Just("9223372036854775807".to_string()),
        Just("-9223372036854775808".to_string()),
        (-1e3f64..1e3).prop_map(|x| format!("{x:?}")),
        any::<f64>()
            .prop_filter("TOML has no spelling for these", |x| x.is_finite())
            .prop_map(|x| format!("{x:?}")),
    ]
}

/// Integers as a careless or hostile user types them (some outside `u32` and `u16`).
fn extreme_int() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("3".to_string()),
        Just("65535".to_string()),
        Just("65536".to_string()),
        Just("4294967295".to_string()),
        Just("4294967296".to_string()),
        Just("9223372036854775807".to_string()),
        Just("1e300".to_string()),
        Just("nan".to_string()),
        (0u32..200).prop_map(|x| x.to_string()),
    ]
}

/// The numeric keys of the rig file: (section, key, the paper's value).
const FLOAT_KEYS: [(&str, &str, &str); 16] = [
    ("gear", "module_mm", "1.0"),
    ("gear", "pressure_angle_deg", "20.0"),
    ("cam", "eccentricity_mm", "1.0"),
    ("cam", "carrier_mass_kg", "3.82"),
    ("friction", "mu_s", "0.271"),
    ("friction", "mu_d", "0.174"),
    ("calibration", "c1", "62.1"),
    ("calibration", "c2", "-138.0"),
    ("calibration", "c3", "0.235"),
    ("calibration", "c4", "1.69"),
    ("calibration", "c5", "0.00378"),
    ("calibration", "c6", "2.25"),
    ("calibration", "temperature_c", "25.0"),
    ("limits", "max_release_load_nm", "3.68"),
    ("limits", "max_current_a", "4.5"),
    ("limits", "max_freq_hz", "15.0"),
];

/// What one case changes: float keys (by index) with their text, one tooth count, one
/// profile shift, the fitted mu, and an effect's parameter.
#[derive(Debug, Clone)]
struct Case {
    floats: Vec<(usize, String)>,
    tooth: Option<(usize, String)>,
    shift: Option<(usize, String)>,
    mu: Option<String>,
    effect: Option<(usize, usize, String)>,
}

fn case() -> impl Strategy<Value = Case> {
    (
        proptest::collection::vec((0..FLOAT_KEYS.len(), extreme_float()), 0..4),
        proptest::option::weighted(0.2, (0usize..4, extreme_int())),
        proptest::option::weighted(0.15, (0usize..4, extreme_float())),
        proptest::option::weighted(0.3, extreme_float()),
        proptest::option::weighted(0.5, (0usize..64, 0usize..8, extreme_float())),
    )
        .prop_map(|(floats, tooth, shift, mu, effect)| Case {
            floats,
            tooth,
            shift,
            mu,
            effect,
        })
}

/// The rig file of `case`, and the names a refusal may give (the keys it set).
fn file(case: &Case) -> (String, Vec<String>) {
    let mut names = Vec::new();
    let mut value = |section: &str, key: &str, paper: &str| -> String {
        match case
            .floats
            .iter()
            .rev()
            .find(|(k, _)| FLOAT_KEYS[*k].0 == section && FLOAT_KEYS[*k].1 == key)
        {
            Some((_, v)) => {
                names.push(key.to_string());
                v.clone()
            }
            None => paper.to_string(),
        }
    };
    let mut text = String::new();
    let mut section = "";
    let mut z = ["49", "51", "50", "50"].map(String::from);
    if let Some((k, v)) = &case.tooth {
        z[*k] = v.clone();
    }
    for (s, key, paper) in FLOAT_KEYS {
        if s != section {
            text += &format!("[{s}]\n");
            if s == "gear" {
                text += &format!("z = [{}]\n", z.join(", "));
                let mut x = ["0.0", "0.0", "0.0", "0.0"].map(String::from);
                if let Some((k, v)) = &case.shift {
                    x[*k] = v.clone();
                }
                text += &format!("profile_shift = [{}]\n", x.join(", "));
            }
            section = s;
        }
        let v = value(s, key, paper);
        text += &format!("{key} = {v}\n");
    }
    if case.tooth.is_some() {
        names.push("z".into());
    }
    if case.shift.is_some() {
        names.push("profile_shift".into());
    }
    if case.mu.is_some() || case.effect.is_some() {
        let mu = case.mu.clone().unwrap_or_else(|| "0.2".into());
        text += &format!("[model]\nmu = {mu}\n");
        if case.mu.is_some() {
            names.push("mu".into());
        }
        if let Some((e, p, v)) = &case.effect {
            let info = &model::effects::EFFECTS[e % model::effects::EFFECTS.len()];
            let keys: Vec<&str> = info.keys().collect();
            text += &format!("[[model.effects]]\nname = \"{}\"\n", info.name);
            names.push(info.name.to_string());
            if !keys.is_empty() {
                let key = keys[p % keys.len()];
                text += &format!("params = {{ {key} = {v} }}\n");
                names.push(key.to_string());
            }
        }
    }
    (text, names)
}

/// A rig file that loaded is usable: every conversion, the virtual rig (booted and run
/// released for a moment), and its own file read back the same.
fn use_rig(rig: &RigFile) -> Result<(), String> {
    rig.gear_set().map_err(|e| format!("gear_set: {e}"))?;
    rig.drive().map_err(|e| format!("drive: {e}"))?;
    let wire = rig.to_wire().map_err(|e| format!("to_wire: {e}"))?;
    wire.validate()
        .map_err(|e| format!("the device would refuse it: {e:?}"))?;
    let _ = rig.calibration();
    let text = rig.to_toml().map_err(|e| format!("to_toml: {e}"))?;
    let again = RigFile::parse(&text, "again.toml").map_err(|e| format!("read back: {e}"))?;
    if again.to_wire().ok() != Some(wire) {
        return Err("its own file reads back differently".into());
    }
    if rig.model.is_some() {
        rig.plant_effects()
            .map_err(|e| format!("plant_effects: {e}"))?;
        rig.current_model()
            .map_err(|e| format!("current_model: {e}"))?;
    }
    let mut config = SimConfig::from_rig_file(rig).map_err(|e| format!("virtual rig: {e}"))?;
    sim::preset::apply_model(rig, &mut config).or_else(|e| {
        // A fitted effect the plant cannot run is named, not a failure of the file.
        if e.to_string().contains("cannot run") {
            Ok(())
        } else {
            Err(format!("apply_model: {e}"))
        }
    })?;
    // Booted, then released by its button (the firmware drives the motor at the file's
    // limits and calibration).
    let mut sim = SimRig::new(config);
    sim.advance(0.15);
    sim.set_button(true);
    sim.advance(0.25);
    let s = sim.plant().state();
    if !(s.current.is_finite() && s.cam_speed.is_finite() && s.temperature.is_finite()) {
        return Err(format!("the virtual rig's state is not finite: {s:?}"));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn extreme_numbers_in_a_rig_file_are_refused_by_name_or_give_a_usable_rig(case in case()) {
        let (text, names) = file(&case);
        match RigFile::parse(&text, "hostile.toml") {
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.contains("hostile.toml"), "{msg}\n{text}");
                prop_assert!(
                    names.iter().any(|n| msg.contains(n.as_str())),
                    "names none of {names:?}: {msg}\n{text}"
                );
            }
            Ok(rig) => {
                let used = use_rig(&rig);
                prop_assert!(used.is_ok(), "{}\n{text}", used.unwrap_err());
            }
        }
    }
}
