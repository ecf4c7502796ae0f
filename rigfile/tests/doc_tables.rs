//! `docs/rig-file.md` lists exactly the sections, keys, units, ranges and defaults the code
//! accepts, the effect parameters, and the older calibration file's keys: the document
//! cannot go stale.

use std::collections::{BTreeMap, BTreeSet};

use model::effects::Effect;
use rigfile::keys::{self, KEYS};
use rigfile::{EffectEntry, RigFile};

/// The rows of the document's tables, by the table they are in.
#[derive(Default)]
struct Doc {
    /// Section -> rows of cells.
    keys: BTreeMap<String, Vec<Vec<String>>>,
    effects: Vec<Vec<String>>,
    older: Vec<Vec<String>>,
}

enum In {
    Nothing,
    Section(String),
    Effects,
    Older,
}

fn read_doc() -> Doc {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/rig-file.md");
    let text = std::fs::read_to_string(path).expect("docs/rig-file.md exists");
    let mut doc = Doc::default();
    let mut at = In::Nothing;
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("### ") {
            let name = h.trim().trim_matches('`').trim_matches(['[', ']']);
            at = In::Section(name.to_string());
        } else if let Some(h) = line.strip_prefix("## ") {
            at = match h.trim() {
                "Effects" => In::Effects,
                "Older formats" => In::Older,
                _ => In::Nothing,
            };
        } else if line.starts_with("| `") {
            let cells: Vec<String> = line
                .trim()
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect();
            match &at {
                In::Section(s) => doc.keys.entry(s.clone()).or_default().push(cells),
                In::Effects => doc.effects.push(cells),
                In::Older => doc.older.push(cells),
                In::Nothing => {}
            }
        }
    }
    doc
}

/// The names in backticks of a cell, in order.
fn ticked(cell: &str) -> Vec<String> {
    cell.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

#[test]
fn the_document_lists_every_key_with_its_unit_range_and_default() {
    let doc = read_doc();
    let mut documented = BTreeSet::new();
    for (section, rows) in &doc.keys {
        for row in rows {
            assert_eq!(row.len(), 5, "[{section}] row {row:?}");
            let names = ticked(&row[0]);
            let key = &names[0];
            let spec = keys::find(section, key)
                .unwrap_or_else(|| panic!("docs list [{section}] {key}, the code has no such key"));
            assert_eq!(&names[1..], spec.aliases, "aliases of {spec}");
            assert_eq!(row[1], spec.unit, "unit of {spec}");
            assert_eq!(row[2], spec.range, "range of {spec}");
            let default = if spec.default == "-" {
                "-".to_string()
            } else {
                format!("`{}`", spec.default)
            };
            assert_eq!(row[3], default, "default of {spec}");
            assert_eq!(row[4], spec.meaning, "meaning of {spec}");
            assert!(
                documented.insert((section.clone(), key.clone())),
                "{spec} twice"
            );
        }
    }
    let code: BTreeSet<(String, String)> = KEYS
        .iter()
        .map(|k| (k.section.to_string(), k.key.to_string()))
        .collect();
    assert_eq!(
        documented, code,
        "docs/rig-file.md against rigfile::keys::KEYS"
    );
}

#[test]
fn the_document_lists_every_effect_parameter() {
    let doc = read_doc();
    let documented: Vec<(String, String, String, String, String)> = doc
        .effects
        .iter()
        .map(|r| {
            assert_eq!(r.len(), 5, "{r:?}");
            (
                ticked(&r[0])[0].clone(),
                ticked(&r[1])[0].clone(),
                r[2].clone(),
                r[3].clone(),
                r[4].clone(),
            )
        })
        .collect();
    let code: Vec<(String, String, String, String, String)> = keys::effect_params()
        .iter()
        .map(|p| {
            (
                p.effect.name().to_string(),
                p.name.to_string(),
                p.unit.to_string(),
                p.range(),
                p.meaning.to_string(),
            )
        })
        .collect();
    assert_eq!(documented, code);
}

#[test]
fn the_document_maps_every_key_of_the_older_calibration_file() {
    let doc = read_doc();
    let documented: Vec<(String, String)> = doc
        .older
        .iter()
        .map(|r| (ticked(&r[0])[0].clone(), ticked(&r[1])[0].clone()))
        .collect();
    let code: Vec<(String, String)> = keys::wire_keys()
        .map(|k| (k.wire.unwrap_or_default().to_string(), k.path()))
        .collect();
    assert_eq!(documented, code);
    // Each of them loads into that key.
    for k in keys::wire_keys() {
        let flat = k.wire.unwrap_or_default();
        let text = format!("{flat} = {}\n", k.default);
        let loaded = RigFile::parse_detailed(&text, "old.toml").unwrap();
        assert_eq!(loaded.present, [k], "{flat}");
        assert_eq!(loaded.rig, RigFile::paper(), "{flat}");
    }
}

/// The (section, key) pairs of a file as the code writes it.
fn written_keys(table: &toml::Table, section: &str, out: &mut BTreeSet<(String, String)>) {
    for (key, value) in table {
        let nested = if section.is_empty() {
            key.clone()
        } else {
            format!("{section}.{key}")
        };
        match value {
            toml::Value::Table(t) if section.is_empty() || key == "fit" => {
                written_keys(t, &nested, out)
            }
            toml::Value::Array(items) if key == "effects" => {
                out.insert((section.to_string(), key.clone()));
                for item in items {
                    if let toml::Value::Table(t) = item {
                        written_keys(t, &nested, out);
                    }
                }
            }
            _ => {
                out.insert((section.to_string(), key.clone()));
            }
        }
    }
}

#[test]
fn the_code_reads_and_writes_exactly_the_documented_keys() {
    // Every key with a default parses with it, alone in its section, to the paper's rig.
    for k in KEYS
        .iter()
        .filter(|k| k.default != "-" && !k.section.starts_with("model"))
    {
        for name in std::iter::once(k.key).chain(k.aliases.iter().copied()) {
            let text = format!("[{}]\n{name} = {}\n", k.section, k.default);
            let loaded = RigFile::parse_detailed(&text, "one.toml")
                .unwrap_or_else(|e| panic!("{text}: {e}"));
            assert_eq!(loaded.rig, RigFile::paper(), "{text}");
            assert_eq!(loaded.present, [k], "{text}");
        }
    }
    // A file with every section written has exactly the documented keys.
    let mut rig = RigFile::paper().with_model(
        0.25,
        vec![EffectEntry {
            name: Effect::CurrentSensorOffset.name().into(),
            params: BTreeMap::from([("offset_a".to_string(), 0.01)]),
        }],
    );
    // Shifted gears write profile_shift (files of standard gears leave it out).
    rig.gear.profile_shift = [0.1, -0.1, 0.2, -0.2];
    // So do benches other than the default 2 m drop.
    rig.load.drop_m = 1.5;
    rig.calibration.fit = Some(rigfile::FitSection {
        torque_points: 9,
        torque_r_squared: 1.0,
        torque_residual_sd_nmm: 0.0,
        no_load_points: 10,
        no_load_r_squared: 1.0,
        no_load_residual_sd_a: 0.0,
        ci95: [
            [62.0, 62.2],
            [-139.0, -137.0],
            [0.23, 0.24],
            [1.6, 1.8],
            [0.0037, 0.0038],
            [2.2, 2.3],
        ],
        loss_direct: [0.235, 1.7],
        consistent: true,
    });
    let text = rig.to_toml().unwrap();
    let table: toml::Table = text.parse().unwrap();
    let mut written = BTreeSet::new();
    written_keys(&table, "", &mut written);
    let code: BTreeSet<(String, String)> = KEYS
        .iter()
        .map(|k| (k.section.to_string(), k.key.to_string()))
        .collect();
    assert_eq!(written, code, "{text}");
    let loaded = RigFile::parse_detailed(&text, "all.toml").unwrap();
    assert_eq!(
        loaded.present.len(),
        KEYS.len() - 2,
        "all but name and params"
    );
    assert_eq!(loaded.rig, rig);
}

#[test]
fn every_effect_takes_exactly_its_documented_parameters() {
    for effect in Effect::ALL {
        let names = keys::effect_param_names(effect);
        assert!(!names.is_empty(), "{}", effect.name());
        for name in names {
            let v = if name == "tau_ref_nm" { 1.0 } else { 0.5 };
            let params = BTreeMap::from([(name.to_string(), v)]);
            let mut p = model::effects::EffectParams::default();
            rigfile::apply_params(effect, &params, &mut p)
                .unwrap_or_else(|e| panic!("{} {name}: {e}", effect.name()));
        }
        let bogus = BTreeMap::from([("bogus".to_string(), 1.0)]);
        let mut p = model::effects::EffectParams::default();
        let e = rigfile::apply_params(effect, &bogus, &mut p).unwrap_err();
        assert!(e.contains("bogus") && e.contains(effect.name()), "{e}");
    }
}
