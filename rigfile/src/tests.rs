use std::collections::BTreeMap;

use model::effects::Effect;

use super::*;

/// A plausible `[calibration.fit]`.
pub(crate) fn a_fit() -> FitSection {
    FitSection {
        torque_points: 9,
        torque_r_squared: 0.9999,
        torque_residual_sd_nmm: 0.02,
        no_load_points: 10,
        no_load_r_squared: 0.999,
        no_load_residual_sd_a: 0.0004,
        ci95: [
            [62.0, 62.2],
            [-138.2, -137.9],
            [0.23, 0.24],
            [1.63, 1.73],
            [0.0037, 0.0039],
            [2.249, 2.251],
        ],
        loss_direct: [0.2346, 1.68],
        consistent: true,
    }
}

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
    let loaded = RigFile::parse_detailed("", "rig.toml").unwrap();
    assert!(loaded.present.is_empty());
    assert_eq!(loaded.defaulted().len(), 16);
}

#[test]
fn other_gear_set_and_aliases() {
    let text = "[gear]\nz = [52, 48, 50, 50]\n[cam]\ne_mm = 0.5\n";
    let r = RigFile::parse(text, "rig.toml").unwrap();
    assert_eq!(r.gear_set().unwrap().z(), [52, 48, 50, 50]);
    assert_eq!(r.cam.eccentricity_mm, 0.5);
    let loaded = RigFile::parse_detailed(text, "rig.toml").unwrap();
    let set: Vec<String> = loaded.present.iter().map(|k| k.path()).collect();
    assert_eq!(set, ["[gear] z", "[cam] eccentricity_mm"]);
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
    // The key and its section, and the line.
    assert!(e.contains("[cam]") && e.contains("line 2"), "{e}");
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
fn unknown_keys_in_every_known_section_name_key_and_section() {
    for section in ["gear", "cam", "friction", "calibration", "limits"] {
        let text = format!("[{section}]\nbogus_key = 1.0\n");
        let e = RigFile::parse(&text, "rig.toml").unwrap_err().to_string();
        assert!(
            e.contains("bogus_key") && e.contains(&format!("[{section}]")),
            "{e}"
        );
    }
    let e = RigFile::parse("[calibration.fit]\nr2 = 1.0\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("r2") && e.contains("[calibration.fit]"), "{e}");
    // The fit is written whole: a missing key is named.
    let mut r = RigFile::paper();
    r.calibration.fit = Some(a_fit());
    let text = r.to_toml().unwrap().replace("c4_direct = 1.68\n", "");
    let e = RigFile::parse(&text, "rig.toml").unwrap_err().to_string();
    assert!(e.contains("missing field `c4_direct`"), "{e}");
    let e = RigFile::parse("[model]\nmu = 0.2\nnu = 0.1\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("nu") && e.contains("[model]"), "{e}");
    // A C1 typed at the top level is not silently the paper's.
    let e = RigFile::parse("c1 = 60.0\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown field `c1`") && e.contains("[calibration]"),
        "{e}"
    );
}

#[test]
fn unknown_sections_are_kept_when_the_file_is_rewritten() {
    let text = "[calibration]\nc1 = 61.0\n\n[notes]\nwho = \"bench 2\"\nwhen = 2024-05-01T10:00:00Z\nlist = [1, 2]\n\n[[runs]]\nid = 1\n[[runs]]\nid = 2\n";
    let r = RigFile::parse(text, "rig.toml").unwrap();
    assert_eq!(r.extra.len(), 2);
    let rewritten = r.with_model(0.25, Vec::new()).to_toml().unwrap();
    let back = RigFile::parse(&rewritten, "rig.toml").unwrap();
    assert_eq!(back.extra, r.extra);
    assert!(rewritten.contains("who = \"bench 2\""), "{rewritten}");
    assert!(
        rewritten.contains("when = 2024-05-01T10:00:00Z"),
        "{rewritten}"
    );
    assert!(rewritten.contains("[[runs]]"), "{rewritten}");
    assert_eq!(back.calibration.constants.c1, 61.0e-3);
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
    // No inertia-rectification fitted: the plant keeps its own drive.
    assert_eq!(setup.regeneration, None);
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
fn calibration_is_written_in_the_papers_units_and_read_into_si() {
    let mut r = RigFile::paper();
    r.calibration.fit = Some(a_fit());
    let text = r.to_toml().unwrap();
    for line in [
        "[calibration]\nc1 = 62.1\nc2 = -138.0\nc3 = 0.235\nc4 = 1.69\nc5 = 0.00378\nc6 = 2.25\ntemperature_c = 25.0\n",
        "[calibration.fit]\ntorque_points = 9\n",
        "[limits]\nmax_release_load_nm = 3.68\nmax_current_a = 4.5\nmax_freq_hz = 15.0\n",
    ] {
        assert!(text.contains(line), "{text}");
    }
    let back = RigFile::parse(&text, "rig.toml").unwrap();
    assert_eq!(back, r);
    assert_eq!(back.calibration(), Calibration::PAPER);
    // 62.1 N mm/A is 0.0621 N m/A inside.
    assert!((back.calibration().c1 - 0.0621).abs() < 1e-15);
}

#[test]
fn out_of_range_values_name_the_key_the_value_and_the_range() {
    let e = RigFile::parse("[friction]\nmu_s = 0.2\nmu_d = 0.5\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("[friction] `mu_d` is out of range: 0.5 given") && e.contains("not above mu_s"),
        "{e}"
    );
    // A default that does not fit the file's other values says so.
    let e = RigFile::parse("[friction]\nmu_s = 0.1\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`mu_d`") && e.contains("left out"), "{e}");
    let e = RigFile::parse("[calibration]\nc1 = -62.1\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("[calibration] `c1` is out of range"), "{e}");
    let e = RigFile::parse("[limits]\nmax_freq_hz = 1e40\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("32-bit"), "{e}");
    let e = RigFile::parse("[gear]\npressure_angle_deg = 50.0\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`pressure_angle_deg`"), "{e}");
    let e = RigFile::parse("[gear]\nz = [49, 51, 70000, -69950]\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("[gear]") && e.contains("line 2"), "{e}");
}

/// Fixtures written by the `rig` binary of d1c5970 (see `tests/fixtures/README.md`).
fn fixture(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_older_calibration_file_loads() {
    let loaded =
        RigFile::parse_detailed(&fixture("legacy-calibration-get.toml"), "old.toml").unwrap();
    assert_eq!(loaded.format, FileFormat::CalibrationFile);
    assert_eq!(loaded.rig, RigFile::paper());
    assert_eq!(loaded.set_on_device().len(), 16);
    assert!(loaded.defaulted().is_empty());
    assert_eq!(
        loaded.rig.to_wire().unwrap(),
        protocol::RigParameters::paper()
    );

    let loaded = RigFile::parse_detailed(&fixture("legacy-calibrate.toml"), "old.toml").unwrap();
    assert_eq!(loaded.format, FileFormat::CalibrationFile);
    let c = paper_units::to_paper(&loaded.rig.calibration());
    assert_eq!(c[0], 62.090202);
    assert_eq!(c[5], 2.250479);
    let fit = loaded
        .rig
        .calibration
        .fit
        .as_ref()
        .expect("[fit] became [calibration.fit]");
    assert_eq!(fit.torque_points, 9);
    assert_eq!(fit.ci95[0], [62.058329, 62.122075]);
    assert_eq!(fit.ci95[4], [0.003688, 0.003867]);
    assert_eq!(fit.ci95[2], [0.229849, 0.239296]);
    assert_eq!(fit.loss_direct, [0.234573, 1.681421]);
    assert!(fit.consistent);
    assert!(loaded.rig.extra.is_empty());
    // Rewritten, it is a rig file that reads back the same.
    let text = loaded.rig.to_toml().unwrap();
    let again = RigFile::parse_detailed(&text, "new.toml").unwrap();
    assert_eq!(again.format, FileFormat::RigFile);
    assert_eq!(again.rig, loaded.rig);
}

#[test]
fn the_older_calibration_file_partial_and_malformed() {
    let loaded = RigFile::parse_detailed("c1_nmm_per_a = 60\n", "t.toml").unwrap();
    assert_eq!(loaded.rig.to_wire().unwrap().c1_nmm_per_a, 60.0);
    assert_eq!(loaded.rig.to_wire().unwrap().c2_nmm, -138.0);
    let set: Vec<_> = loaded.set_on_device().iter().map(|k| k.wire).collect();
    assert_eq!(set, [Some("c1_nmm_per_a")]);
    assert_eq!(loaded.name_of(keys::by_wire("mu_d").unwrap()), "`mu_d`");

    let err = |text: &str| RigFile::parse(text, "bad.toml").unwrap_err().to_string();
    let e = err("c1_nmm_per_a = \"lots\"\n");
    assert!(
        e.contains("bad.toml") && e.contains("line 1") && e.contains("invalid type"),
        "{e}"
    );
    let e = err("c1_nmm_per_a = 62.1\nc7 = 1.0\n");
    assert!(
        e.contains("unknown field `c7`") && e.contains("line 2"),
        "{e}"
    );
    let e = err("c1_nmm_per_a = -62.1\n");
    assert!(e.contains("`c1_nmm_per_a` is out of range"), "{e}");
    let e = err("c1_nmm_per_a = [1\n");
    assert!(e.contains("bad.toml") && e.contains("line"), "{e}");
    let e = err("z = [50, 50, 50, 50]\n");
    assert!(e.contains("`z` is out of range"), "{e}");
    let e = err("c1_nmm_per_a = 62.1\nmu_d = 0.5\n");
    assert!(
        e.contains("`mu_d` is out of range") && e.contains("not above mu_s"),
        "{e}"
    );
    let e = err("c1_nmm_per_a = 62.1\n[calibration]\nc2 = 1.0\n");
    assert!(e.contains("mixes"), "{e}");
    // An odd [fit] is kept as it is, not refused.
    let r = RigFile::parse("c6_a = 2.0\n[fit]\nr2 = 0.9\n", "t.toml").unwrap();
    assert!(r.calibration.fit.is_none());
    assert_eq!(r.extra["fit"]["r2"].as_float(), Some(0.9));
}

#[test]
fn the_older_rig_files_load() {
    let r = RigFile::parse(&fixture("legacy-rig-doc.toml"), "doc.toml").unwrap();
    assert_eq!(r.calibration(), Calibration::PAPER);
    assert_eq!(r.model.as_ref().unwrap().mu, 0.262);
    assert_eq!(r.current_model().unwrap().effects.axial_corner_speed, 21.0);
    let loaded = RigFile::parse_detailed(&fixture("legacy-rig-model.toml"), "m.toml").unwrap();
    assert_eq!(loaded.format, FileFormat::RigFile);
    let r = &loaded.rig;
    assert_eq!(r.model.as_ref().unwrap().effects[0].name, "thermal-drift");
    // The limits it did not have are the paper's.
    assert_eq!(r.to_wire().unwrap(), protocol::RigParameters::paper());
    assert_eq!(loaded.defaulted().len(), 3);
}

#[test]
fn user_effects_and_terms_round_trip() {
    let text = "[[user_effects]]\nname = \"brush-drag\"\nexpression = \"c * (w / 100)^2\"\nparams = { c = { unit = \"A\", bounds = [-0.5, 0.5] } }\n[model]\nmu = 0.27\n[[model.effects]]\nname = \"current-sensor-offset\"\nparams = { offset_a = 0.01 }\n[[model.terms]]\nname = \"brush-drag\"\nparams = { c = 0.1 }\n[[model.terms]]\nname = \"thermal-drift\"\nform = \"warm-up-in-time\"\nparams = { k_per_s = 1e-6, tau_s = 900.0 }\n";
    let r = RigFile::parse(text, "rig.toml").unwrap();
    assert_eq!(r.user_effects[0].params["c"].bounds, [-0.5, 0.5]);
    assert_eq!(r.term_entries().len(), 2);
    assert!(r.extra.is_empty());
    let (effects, p) = r.effects().unwrap();
    assert_eq!(effects, [model::effects::Effect::CurrentSensorOffset]);
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
    assert!(
        e.contains("low < high") && e.contains("[[user_effects]] x"),
        "{e}"
    );
}

#[test]
fn the_drive_decay_is_a_known_inertia_term_unless_the_model_fits_it() {
    use model::effects::{KAPPA_BRAKING_DRIVE, KAPPA_POWER_NOT_RETURNED};
    let paper = RigFile::paper();
    let eq10 = paper.current_model().unwrap().effects.rectification;
    assert_eq!(eq10, 0.0, "the paper's rig alone is Eq. (10)");
    for (regenerative, kappa) in [
        (false, KAPPA_POWER_NOT_RETURNED),
        (true, KAPPA_BRAKING_DRIVE),
    ] {
        let rig = paper.with_drive_decay(regenerative);
        let m = rig.current_model().unwrap();
        assert_eq!(m.effects.rectification, kappa);
        assert_eq!(m.mu, paper.friction.mu_s, "mu stays the rig's mu_s");
        // Applied twice, or over a model that fits kappa itself: unchanged.
        assert_eq!(rig.with_drive_decay(!regenerative), rig);
    }
}

#[test]
fn profile_shift_round_trips_and_a_mismatch_names_the_key_and_the_fix() {
    let mut rig = RigFile::paper();
    rig.gear.profile_shift = [0.1, -0.1, 0.2, -0.2];
    let text = rig.to_toml().unwrap();
    assert!(text.contains("profile_shift"), "{text}");
    let back = RigFile::parse_detailed(&text, "shifted.toml").unwrap().rig;
    assert_eq!(back.gear.profile_shift, rig.gear.profile_shift);
    assert_eq!(back.gear_set().unwrap().shift(), rig.gear.profile_shift);
    // Standard gears do not write the key: existing files stay as they were.
    assert!(
        !RigFile::paper()
            .to_toml()
            .unwrap()
            .contains("profile_shift")
    );
    let bad = text.replace("0.2, -0.2", "0.3, 0.0");
    let err = RigFile::parse_detailed(&bad, "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("profile_shift") && err.contains("x3 + x4"),
        "{err}"
    );
}

#[test]
fn the_drive_decay_round_trips_and_defaults_to_the_boards_braking_drive() {
    // The README's board brakes (the Pololu G2): the default, written out explicitly.
    let paper = RigFile::paper();
    assert_eq!(paper.drive.decay, crate::DecayMode::Brake);
    assert!(paper.drive.decay.returns_power());
    let text = paper.to_toml().unwrap();
    assert!(text.contains("[drive]\ndecay = \"brake\""), "{text}");
    assert_eq!(RigFile::parse(&text, "paper.toml").unwrap(), paper);
    // A coasting rig round-trips as coast.
    let mut coast = RigFile::paper();
    coast.drive.decay = crate::DecayMode::Coast;
    let text = coast.to_toml().unwrap();
    assert!(text.contains("decay = \"coast\""), "{text}");
    let back = RigFile::parse(&text, "coast.toml").unwrap();
    assert_eq!(back, coast);
    assert!(!back.drive.decay.returns_power());
    // A wrong value names the section and the allowed ones.
    let e = RigFile::parse("[drive]\ndecay = \"fast\"\n", "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("[drive]") && e.contains("brake") && e.contains("coast"),
        "{e}"
    );
}

/// Issue 33: the numbers the hostile rig-file property test found: a tooth count past
/// `u32` (named, with its range), 3.4e38 N mm/A (fits the device's 32-bit record, ran the
/// simulated motor to NaN), an effect parameter far outside any fit and an extra viscous
/// loss that leaves the vibrator negative damping.
#[test]
fn extreme_numbers_are_refused_naming_the_key_and_its_range() {
    let refused = |text: &str| RigFile::parse(text, "h.toml").unwrap_err().to_string();
    let e = refused("[gear]\nz = [4294967296, 51, 50, 50]\n");
    assert!(e.contains("`z`") && e.contains("4 to 65535"), "{e}");
    let e = refused("[gear]\nz = [4294967295, 51, 50, 50]\n");
    assert!(e.contains("z"), "{e}");
    let e = refused("[calibration]\nc1 = 3.4e38\n");
    assert!(e.contains("c1") && e.contains("at most 1000"), "{e}");
    let e = refused("[calibration]\ntemperature_c = -300.0\n");
    assert!(
        e.contains("temperature_c") && e.contains("absolute zero"),
        "{e}"
    );
    let e = refused(
        "[model]\nmu = 0.2\n[[model.effects]]\nname = \"inertia-rectification\"\nparams = { kappa = 1e300 }\n",
    );
    assert!(e.contains("kappa") && e.contains("from -1 to 20"), "{e}");
    let e = refused(
        "[model]\nmu = 0.2\n[[model.effects]]\nname = \"vibrator-viscous-loss\"\nparams = { c_v_n_mm_s_per_rad = -1.0 }\n",
    );
    assert!(e.contains("c_v_n_mm_s_per_rad") && e.contains("-C3"), "{e}");
    // Inside every range: a usable rig.
    RigFile::parse(
        "[calibration]\nc1 = 1000.0\n[model]\nmu = 3.0\n[[model.effects]]\nname = \"vibrator-viscous-loss\"\nparams = { c_v_n_mm_s_per_rad = -0.2 }\n",
        "ok.toml",
    )
    .unwrap();
}

/// Each of the rig file's own ranges is the one its key states (docs/rig-file.md).
#[test]
fn the_bounded_keys_state_their_ranges() {
    for (section, key, lo, hi) in crate::parse::BOUNDED {
        let spec = crate::keys::find(section, key).unwrap();
        assert!(
            spec.range.contains(&format!("{hi}")),
            "{spec}: {}",
            spec.range
        );
        // Zero as a lower end reads "zero or positive".
        if lo > f64::MIN && lo != 0.0 {
            assert!(
                spec.range.contains(&format!("{lo}")),
                "{spec}: {}",
                spec.range
            );
        }
        let mut rig = RigFile::paper();
        assert!(crate::parse::check_all(&rig, "x").is_ok());
        // Just past the top: refused naming the key.
        let past = hi * 1.01 + 1.0;
        match key {
            "module_mm" => rig.gear.module_mm = past,
            "eccentricity_mm" => rig.cam.eccentricity_mm = past,
            "carrier_mass_kg" => rig.cam.carrier_mass_kg = past,
            "temperature_c" => rig.calibration.temperature_c = past,
            "max_release_load_nm" => rig.limits.max_release_load_nm = past,
            "max_current_a" => rig.limits.max_current_a = past,
            "max_freq_hz" => rig.limits.max_freq_hz = past,
            _ => {
                let mut c = crate::paper_units::to_paper(&rig.calibration.constants);
                let k: usize = key[1..].parse().unwrap();
                c[k - 1] = past;
                rig.calibration.constants = crate::paper_units::from_paper(c);
            }
        }
        let e = crate::parse::check_all(&rig, "x").unwrap_err().to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
}
