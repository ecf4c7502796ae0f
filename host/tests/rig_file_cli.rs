//! One rig file for every verb, through the real binary and the virtual device: what
//! `rig calibrate`, `rig calibration get` and `rig explain --write-model` write, every other
//! verb reads; the two older formats still load; a failed `--write-model` run leaves the
//! file it was asked to replace as it was.

use std::path::{Path, PathBuf};
use std::time::Duration;

use assert_cmd::Command;
use serde_json::Value;

/// Virtual seconds per wall-clock second.
const SPEED: &str = "20";

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

fn sim(args: &[&str]) -> Command {
    let mut c = rig();
    c.args(["--sim", "--speed", SPEED]).args(args);
    c
}

mod support {
    pub mod cli;
}
use support::cli::{json_of as json, stdout_of as ok};

fn fails(mut c: Command) -> String {
    let out = c.assert().failure().get_output().clone();
    assert!(out.stdout.is_empty(), "nothing on stdout on failure");
    String::from_utf8(out.stderr).expect("stderr is UTF-8")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// Fixtures written by the `rig` binary of d1c5970 (`rigfile/tests/fixtures/README.md`).
fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../rigfile/tests/fixtures")
        .join(name)
}

#[test]
fn calibrate_writes_a_rig_file_explain_and_calibration_set_accept() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let v = json(sim(&["calibrate", "--yes", "--json", "--out", s(&out)]));
    let file = out.join("calibration.toml");
    assert_eq!(v["files"]["calibration"], s(&file));
    let text = std::fs::read_to_string(&file).unwrap();
    for section in ["[gear]", "[calibration]", "[calibration.fit]", "[limits]"] {
        assert!(text.contains(section), "{section} missing:\n{text}");
    }
    // The file's C1 is what the device stored, as a person writes it.
    let c1 = v["c1"].as_f64().unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("c1 = "))
        .expect("a c1 line");
    let in_file: f64 = line["c1 = ".len()..].parse().unwrap();
    assert!((in_file - c1).abs() < 1e-4 * c1, "{line} vs {c1}");
    assert!(line.len() < "c1 = 62.09020".len() + 4, "{line}");

    let e = json({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "none",
            "--model",
            s(&file),
            "--no-report",
            "--json",
        ]);
        c
    });
    assert_eq!(e["verdict"], "no-missing-effect", "{e}");

    // A fresh virtual device has Table 2: the measured constants are news to it.
    let set = json(sim(&["calibration", "set", s(&file), "--yes", "--json"]));
    assert_eq!(set["written"], true, "{set}");
    assert_eq!(set["defaulted"], serde_json::json!([]), "{set}");
    let stored = set["calibration"]["c1_nmm_per_a"].as_f64().unwrap();
    assert!((stored - c1).abs() < 1e-4, "{stored} vs {c1}");
}

#[test]
fn explains_model_file_is_accepted_by_calibration_set_and_keeps_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    // A rig file with limits of its own, a section no tool knows, and a fit.
    let start = dir.path().join("start.toml");
    std::fs::write(
        &start,
        "[limits]\nmax_freq_hz = 12.0\n\n[bench]\noperator = \"A. N. Other\"\nserial = 7\n",
    )
    .unwrap();
    let model = dir.path().join("model.toml");
    ok({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "thermal-drift",
            "--seed",
            "2",
            "--model",
            s(&start),
            "--write-model",
            s(&model),
            "--no-report",
        ]);
        c
    });
    let text = std::fs::read_to_string(&model).unwrap();
    assert!(
        text.contains("[model]") && text.contains("thermal-drift"),
        "{text}"
    );
    assert!(text.contains("max_freq_hz = 12.0"), "{text}");
    assert!(
        text.contains("[bench]") && text.contains("operator = \"A. N. Other\""),
        "the unknown section is kept:\n{text}"
    );
    let set = json(sim(&["calibration", "set", s(&model), "--yes", "--json"]));
    assert_eq!(set["written"], true, "{set}");
    assert_eq!(set["changed"].as_array().unwrap().len(), 1, "{set}");
    assert_eq!(set["calibration"]["max_freq_hz"], 12.0, "{set}");

    // The paper's rig with a model: the device already has it.
    let paper_model = dir.path().join("paper-model.toml");
    ok({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "none",
            "--write-model",
            s(&paper_model),
            "--no-report",
        ]);
        c
    });
    let text = ok(sim(&["calibration", "set", s(&paper_model), "--yes"]));
    assert!(text.contains("already has this calibration"), "{text}");
}

#[test]
fn calibration_get_updates_a_rig_file_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("rig.toml");
    std::fs::write(
        &file,
        "[calibration]\nc1 = 60.0\ntemperature_c = 31.5\n\n[model]\nmu = 0.25\n\n[notes]\ntext = \"kept\"\n",
    )
    .unwrap();
    let said = ok(sim(&["calibration", "get", s(&file)]));
    assert!(said.contains("wrote") && said.contains("updated"), "{said}");
    let text = std::fs::read_to_string(&file).unwrap();
    // The device's record replaces what it carries; the rest stays.
    assert!(text.contains("c1 = 62.1\n"), "{text}");
    assert!(text.contains("temperature_c = 31.5"), "{text}");
    assert!(text.contains("[model]\nmu = 0.25"), "{text}");
    assert!(text.contains("[notes]\ntext = \"kept\""), "{text}");
    assert!(text.contains("[limits]"), "{text}");
}

#[test]
fn calibration_set_says_which_keys_took_the_papers_values() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("part.toml");
    std::fs::write(&file, "[calibration]\nc1 = 62.0\n").unwrap();
    let text = ok(sim(&["calibration", "set", s(&file), "--yes"]));
    assert!(
        text.contains("not in")
            && text.contains("[cam] eccentricity_mm = 1.0, carrier_mass_kg = 3.82\n")
            && text.contains(
                "[limits] max_release_load_nm = 3.68, max_current_a = 4.5, max_freq_hz = 15.0\n"
            )
            && !text.contains("c1 = "),
        "{text}"
    );
    assert!(text.contains("c1_nmm_per_a: 62.1 -> 62"), "{text}");
    let v = json(sim(&["calibration", "set", s(&file), "--yes", "--json"]));
    let defaulted = v["defaulted"].as_array().unwrap();
    assert_eq!(defaulted.len(), 15, "{v}");
    assert!(defaulted.contains(&Value::from("max_freq_hz")), "{v}");
    assert!(!defaulted.contains(&Value::from("c1_nmm_per_a")), "{v}");

    // A typo in a known section names the key and the section; nothing is sent.
    std::fs::write(&file, "[limits]\nmax_freq = 12.0\n").unwrap();
    let e = fails(sim(&["calibration", "set", s(&file), "--yes"]));
    assert!(
        e.contains("`max_freq`") && e.contains("[limits]") && e.contains("nothing was written"),
        "{e}"
    );
    // A file with no key the device carries is refused.
    std::fs::write(&file, "[model]\nmu = 0.25\n").unwrap();
    let e = fails(sim(&["calibration", "set", s(&file), "--yes"]));
    assert!(e.contains("sets no calibration field"), "{e}");
}

#[test]
fn files_in_the_two_older_formats_load_everywhere() {
    for name in [
        "legacy-calibration-get.toml",
        "legacy-calibrate.toml",
        "legacy-rig-model.toml",
        "legacy-rig-doc.toml",
    ] {
        let path = fixture(name);
        let e = json({
            let mut c = rig();
            c.args([
                "explain",
                "--synthetic",
                "none",
                "--model",
                s(&path),
                "--no-report",
                "--json",
            ]);
            c
        });
        assert!(e["verdict"].is_string(), "{name}: {e}");
        let set = json(sim(&["calibration", "set", s(&path), "--yes", "--json"]));
        assert!(set["written"].is_boolean(), "{name}: {set}");
        match name {
            // Every field of the device, Table 2: nothing to write.
            "legacy-calibration-get.toml" => {
                assert_eq!(set["written"], false, "{set}");
                assert_eq!(set["defaulted"], serde_json::json!([]), "{set}");
            }
            // The constants rig calibrate measured.
            "legacy-calibrate.toml" => {
                assert_eq!(set["written"], true, "{set}");
                let c1 = set["calibration"]["c1_nmm_per_a"].as_f64().unwrap();
                assert!((c1 - 62.090202).abs() < 1e-4, "{set}");
            }
            // The rig file of `rig explain --help` has no [limits]: the defaults.
            _ => {
                assert_eq!(set["written"], false, "{set}");
                assert_eq!(set["defaulted"].as_array().unwrap().len(), 3, "{set}");
            }
        }
    }
}

#[test]
fn a_failed_write_model_run_leaves_the_file_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.toml");
    let before = "# the model from last week\n[model]\nmu = 0.25\n";
    std::fs::write(&model, before).unwrap();
    let untouched = || {
        assert_eq!(std::fs::read_to_string(&model).unwrap(), before);
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(names.is_empty(), "temporary files left: {names:?}");
    };
    // The report folder cannot be written (a file is in the way).
    let blocker = dir.path().join("blocker");
    std::fs::write(&blocker, "").unwrap();
    let e = fails({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "none",
            "--write-model",
            s(&model),
            "--report",
            s(&blocker.join("report")),
        ]);
        c
    });
    assert!(e.contains("blocker"), "{e}");
    untouched();
    // The data cannot be fitted.
    let csv = dir.path().join("few.csv");
    std::fs::write(&csv, "omega_n_rad_s,tau_rot_nm,i_in_a\n31.4,1.0,2.5\n").unwrap();
    fails({
        let mut c = rig();
        c.args([
            "explain",
            "--measured",
            s(&csv),
            "--write-model",
            s(&model),
            "--no-report",
        ]);
        c
    });
    untouched();
    // The rig file it starts from is bad.
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[cam]\neccentricty_mm = 1.0\n").unwrap();
    let e = fails({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "none",
            "--model",
            s(&bad),
            "--write-model",
            s(&model),
        ]);
        c
    });
    assert!(e.contains("eccentricty_mm") && e.contains("[cam]"), "{e}");
    untouched();
    // A run that works replaces it.
    ok({
        let mut c = rig();
        c.args([
            "explain",
            "--synthetic",
            "none",
            "--write-model",
            s(&model),
            "--no-report",
        ]);
        c
    });
    let after = std::fs::read_to_string(&model).unwrap();
    assert!(
        after.contains("[calibration]") && after.contains("[model]"),
        "{after}"
    );
}
