//! `rig explain` through the real binary: the JSON contract, the report folder, the augmented
//! model round trip and the messages for bad input.

use std::path::Path;

use assert_cmd::Command;
use serde_json::Value;

fn rig() -> Command {
    Command::cargo_bin("rig").expect("the rig binary is built")
}

fn json(args: &[&str]) -> Value {
    let out = rig()
        .args(args)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    serde_json::from_slice(&out).expect("stdout is one JSON object")
}

/// A synthetic sweep with `effect` ("none" for none) saved as CSV in `dir`.
fn synthetic_csv(dir: &Path, effect: &str, seed: &str) -> String {
    let path = dir.join(format!("{effect}-{seed}.csv"));
    let p = path.to_str().unwrap().to_string();
    rig()
        .args([
            "explain",
            "--synthetic",
            effect,
            "--seed",
            seed,
            "--no-report",
            "--json",
        ])
        .args(["--write-synthetic", &p])
        .assert()
        .success();
    p
}

#[test]
fn json_contract_on_measured_data() {
    let dir = tempfile::tempdir().unwrap();
    let csv = synthetic_csv(dir.path(), "speed-dependent-axial-friction", "3");
    let v = json(&["explain", "--measured", &csv, "--json"]);
    assert_eq!(v["verdict"], "explained");
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects[0]["name"], "speed-dependent-axial-friction");
    assert!(effects[0]["params"]["omega_c_rad_s"].as_f64().unwrap() > 0.0);
    for key in [
        "rmse_before_a",
        "rmse_after_a",
        "holdout_rmse_before_a",
        "holdout_rmse_after_a",
    ] {
        assert!(v[key].as_f64().is_some(), "missing {key}: {v}");
    }
    assert!(v["holdout_rmse_after_a"].as_f64() < v["holdout_rmse_before_a"].as_f64());
    // Confidence: a block bootstrap of the whole selection.
    let p = effects[0]["inclusion_probability"].as_f64().unwrap();
    assert!(p > 0.8 && p <= 1.0, "{p}");
    assert!(v["confidence"].as_f64().unwrap() > 0.5);
    assert!(v["inclusion_probabilities"]["speed-dependent-axial-friction"].is_number());
    assert!(v["model_weights"][0]["weight"].is_number());
    assert_eq!(v["bootstrap"]["replicates"], 200);
    assert_eq!(v["outliers"], serde_json::json!([]));
    assert!(v["candidates"][0]["bic_weight"].is_number());
    // The default report folder sits beside the data.
    let report = dir.path().join("speed-dependent-axial-friction-3-explain");
    for f in [
        "report.md",
        "candidates.csv",
        "explanation.json",
        "residuals_before.svg",
        "residuals_after.svg",
    ] {
        assert!(report.join(f).is_file(), "missing {f}");
    }
    let svg = std::fs::read_to_string(report.join("residuals_after.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("circle"));
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("Verdict: explained") && md.contains("speed-dependent-axial-friction"));
}

#[test]
fn effect_free_data_and_the_text_output() {
    let v = json(&["explain", "--synthetic", "none", "--seed", "5", "--json"]);
    assert_eq!(v["verdict"], "no-missing-effect");
    assert_eq!(v["effects"], serde_json::json!([]));
    let out = rig()
        .args(["explain", "--synthetic", "none", "--seed", "5"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains("verdict: no-missing-effect") && text.contains("finding:"),
        "{text}"
    );
}

#[test]
fn written_model_is_loaded_back_and_explains_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let csv = synthetic_csv(dir.path(), "thermal-drift", "2");
    let model = dir.path().join("augmented.toml");
    let m = model.to_str().unwrap();
    let report = dir.path().join("report");
    let r = report.to_str().unwrap();
    let first = json(&[
        "explain",
        "--measured",
        &csv,
        "--write-model",
        m,
        "--report",
        r,
        "--json",
    ]);
    assert_eq!(first["verdict"], "explained");
    assert_eq!(first["effects"][0]["name"], "thermal-drift");
    let text = std::fs::read_to_string(&model).unwrap();
    assert!(text.contains("[model]") && text.contains("thermal-drift") && text.contains("k_per_c"));
    assert!(report.join("report.md").is_file());
    let second = json(&[
        "explain",
        "--measured",
        &csv,
        "--model",
        m,
        "--no-report",
        "--json",
    ]);
    assert_eq!(second["verdict"], "no-missing-effect", "{second}");
    // The written model's effect, and at most the drive's own return (the base model's
    // inertia term, which the data's drive puts there), nothing else.
    let known: Vec<&str> = second["known_effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|k| k.as_str())
        .collect();
    assert!(known.contains(&"thermal-drift"), "{known:?}");
    assert!(
        known
            .iter()
            .all(|k| *k == "thermal-drift" || *k == "inertia-rectification"),
        "{known:?}"
    );
}

#[test]
fn a_corrupt_row_is_reported_with_its_row_and_line_and_makes_no_finding() {
    let dir = tempfile::tempdir().unwrap();
    let clean = synthetic_csv(dir.path(), "none", "11");
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // A comment after the header shifts the file lines by one against the data rows.
    lines.insert(1, "# bench session 11".into());
    // Data row 40 (file line 42): the current misread as 100 A.
    let mut fields: Vec<String> = lines[41].split(',').map(str::to_string).collect();
    fields[2] = "100".into();
    lines[41] = fields.join(",");
    // Data row 7: a negative load (a warning, not an outlier).
    let mut fields: Vec<String> = lines[8].split(',').map(str::to_string).collect();
    fields[1] = format!("-{}", fields[1]);
    lines[8] = fields.join(",");
    let path = dir.path().join("corrupt.csv");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let p = path.to_str().unwrap();
    let out = rig()
        .args(["explain", "--measured", p, "--json", "--no-report"])
        .assert()
        .success()
        .get_output()
        .clone();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["verdict"], "no-missing-effect", "{}", v["finding"]);
    let o = &v["outliers"][0];
    assert_eq!(o["row"], 40);
    assert_eq!(o["line"], 42);
    assert_eq!(o["column"], "i_in_a");
    assert!(
        o["reason"]
            .as_str()
            .unwrap()
            .contains("current sensor's range")
    );
    assert_eq!(v["rows"], 149);
    assert!(v["finding"].as_str().unwrap().contains("set aside"));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("warning: tau_rot_nm is negative in 1 of 150 rows (first: row 7, line 9)"),
        "{stderr}"
    );
    // The text output says so too.
    let out = rig()
        .args(["explain", "--measured", p, "--no-report"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains("outliers set aside (1):") && text.contains("row 40 (line 42)"),
        "{text}"
    );
}

#[test]
fn bad_input_fails_with_a_message_naming_the_row_or_column() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let mut good = String::from("omega_n_rad_s,tau_rot_nm,i_in_a\n");
    for k in 0..12 {
        good.push_str(&format!("31.4,{},2.5\n", 0.368 * (k + 1) as f64));
    }
    let cases = [
        (
            write("bad_number.csv", &format!("{good}31.4,1.0,abc\n")),
            "bad_number.csv row 13 (line 14): column i_in_a is not a number ('abc')",
        ),
        (
            write("missing.csv", "omega_n_rad_s,i_in_a\n31.4,2.5\n"),
            "missing.csv: missing required column tau_rot_nm",
        ),
        (
            write("empty.csv", ""),
            "empty.csv is empty: it needs a header and at least 10 rows",
        ),
        (
            write("nan.csv", &format!("{good}31.4,NaN,2.5\n")),
            "nan.csv row 13 (line 14): column tau_rot_nm is not a finite number ('NaN')",
        ),
    ];
    for (path, message) in cases {
        let out = rig()
            .args(["explain", "--measured", &path, "--json", "--no-report"])
            .assert()
            .failure()
            .get_output()
            .clone();
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains(message), "{err}");
        assert!(out.stdout.is_empty(), "nothing on stdout on failure");
    }
    let out = rig()
        .args(["explain", "--measured", "/nonexistent/x.csv", "--no-report"])
        .assert()
        .failure()
        .get_output()
        .clone();
    assert!(
        String::from_utf8(out.stderr)
            .unwrap()
            .contains("cannot read /nonexistent/x.csv")
    );
    let bad_rig = write("rig.toml", "[gear]\nz = [49, 51, 50, 51]\n");
    let out = rig()
        .args(["explain", "--synthetic", "none", "--model", &bad_rig])
        .assert()
        .failure()
        .get_output()
        .clone();
    assert!(
        String::from_utf8(out.stderr)
            .unwrap()
            .contains("unequal centre distances")
    );
    // A calibration constant of the wrong sign: the firmware's rule refuses it, naming it.
    let wrong = write("wrong.toml", "[calibration]\nc2 = 138.0\n");
    let out = rig()
        .args([
            "explain",
            "--synthetic",
            "none",
            "--model",
            &wrong,
            "--no-report",
        ])
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("c2") && err.contains("wrong sign"), "{err}");
    rig()
        .args(["explain", "--synthetic", "gremlins"])
        .assert()
        .failure();
}

/// Issue 19's JSON contract: `lack_of_fit` (statistic, dof, p, against what), per-effect
/// `plausible` with its limits and `extrapolation`; loads in N mm are refused naming the
/// column and the unit.
#[test]
fn json_carries_lack_of_fit_plausibility_and_extrapolation() {
    let dir = tempfile::tempdir().unwrap();
    let csv = synthetic_csv(dir.path(), "vibrator-viscous-loss", "2");
    let v = json(&["explain", "--measured", &csv, "--json", "--no-report"]);
    let l = &v["lack_of_fit"];
    for key in ["statistic", "dof", "p_value", "alpha", "sigma_a"] {
        assert!(l[key].as_f64().is_some(), "lack_of_fit.{key}: {l}");
    }
    assert_eq!(l["against"], "pure-error", "{l}");
    assert_eq!(l["test"], "F");
    assert!(l["against_text"].as_str().unwrap().contains("repeats"));
    assert!(l["locations"].is_array());
    assert_eq!(v["verdict"], "explained", "{}", v["finding"]);
    let f = &v["effects"][0];
    assert_eq!(f["plausible"], true);
    assert!(
        f["limits"]
            .as_array()
            .unwrap()
            .iter()
            .any(|c| c["param"] == "c_v_n_mm_s_per_rad" && c["within"] == true),
        "{f}"
    );
    assert_eq!(f["extrapolation"]["testable"], true, "{f}");
    assert!(f["extrapolation"]["edges"].as_array().unwrap().len() >= 2);
    // The same rows with the loads in N mm.
    let nmm = dir.path().join("nmm.csv");
    scaled_column(&csv, "tau_rot_nm", 1000.0, &nmm);
    let err = refusal(&nmm);
    assert!(err.contains("tau_rot_nm") && err.contains("N mm"), "{err}");
}

/// `path`'s CSV with `column` multiplied by `factor` (comments dropped).
fn scaled_column(path: &str, column: &str, factor: f64, out: &Path) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap();
    let c = header.split(',').position(|f| f == column).unwrap();
    let mut scaled = format!("{header}\n");
    for line in lines {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        f[c] = format!("{}", f[c].parse::<f64>().unwrap() * factor);
        scaled += &f.join(",");
        scaled.push('\n');
    }
    std::fs::write(out, scaled).unwrap();
}

/// `rig explain --measured FILE` refused: its stderr.
fn refusal(file: &Path) -> String {
    let out = rig()
        .args([
            "explain",
            "--measured",
            file.to_str().unwrap(),
            "--no-report",
        ])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    String::from_utf8_lossy(&out).into_owned()
}

/// The unit screen's messages at the command line: cam speeds in Hz or rpm are refused
/// naming the column, the probable unit and the fix; the same rows in rad/s are not.
#[test]
fn cam_speeds_in_hz_or_rpm_are_refused_naming_the_column_and_the_unit() {
    let dir = tempfile::tempdir().unwrap();
    let csv = synthetic_csv(dir.path(), "none", "3");
    let v = json(&["explain", "--measured", &csv, "--json", "--no-report"]);
    assert_eq!(v["verdict"], "no-missing-effect", "{}", v["finding"]);
    let tau = std::f64::consts::TAU;
    for (unit, factor, fix) in [
        ("Hz", 1.0 / tau, "2 pi = 6.283"),
        // Beyond the motor's no-load speed: the range rule's message.
        ("rpm", 60.0 / tau, "not rpm"),
    ] {
        let file = dir.path().join(format!("{unit}.csv"));
        scaled_column(&csv, "omega_n_rad_s", factor, &file);
        let err = refusal(&file);
        assert!(
            err.contains("omega_n_rad_s") && err.contains(unit) && err.contains(fix),
            "{unit}: {err}"
        );
    }
}

#[test]
fn a_sweep_of_the_other_drive_than_the_rig_file_is_refused_never_mixed() {
    // Issue 30: data measured on a braking drive (its `# drive:` line) against a rig file
    // of a coasting one would fit a base model with the wrong inertia term.
    let dir = tempfile::tempdir().unwrap();
    let csv = synthetic_csv(dir.path(), "none", "1");
    let braking = dir.path().join("braking.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(
        &braking,
        format!("# drive: regenerative_decay = true (inertia-rectification kappa = -0.82)\n{text}"),
    )
    .unwrap();
    let coast = dir.path().join("coast.toml");
    std::fs::write(&coast, "[drive]\ndecay = \"coast\"\n").unwrap();
    let out = rig()
        .args(["explain", "--no-report", "--json", "--measured"])
        .arg(&braking)
        .arg("--model")
        .arg(&coast)
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let e = String::from_utf8_lossy(&out);
    assert!(
        e.contains("braking") || e.contains("brake"),
        "names the data's drive: {e}"
    );
    assert!(e.contains("[drive] decay"), "names the setting to fix: {e}");
    assert!(!e.contains("panicked"), "{e}");
    // The same data with a braking rig file (the default) is explained.
    let brake = dir.path().join("brake.toml");
    std::fs::write(&brake, "[drive]\ndecay = \"brake\"\n").unwrap();
    rig()
        .args(["explain", "--no-report", "--json", "--measured"])
        .arg(&braking)
        .arg("--model")
        .arg(&brake)
        .assert()
        .success();
}

/// The README's first example, `rig sim torque-sweep --csv sweep.csv && rig explain
/// --measured sweep.csv`: the sweep states its provenance and the drive the plant ran, so the
/// base model carries the drive's inertia term and the paper's speed-dependent axial friction
/// is named first, with no drive effect (inertia-rectification) named at all; every named
/// effect's inclusion probability is at least the finding's confidence.
#[test]
fn the_readme_first_example_names_the_axial_friction_and_no_drive_effect() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sweep.csv");
    rig()
        .args(["sim", "torque-sweep", "--csv"])
        .arg(&csv)
        .assert()
        .success();
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.starts_with("# rig sim torque-sweep (preset paper"),
        "{text:.300}"
    );
    assert!(
        text.contains("\n# drive: regenerative_decay = "),
        "{text:.400}"
    );
    let e = json(&[
        "explain",
        "--json",
        "--no-report",
        "--measured",
        csv.to_str().unwrap(),
    ]);
    let names: Vec<&str> = e["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names.first(),
        Some(&"speed-dependent-axial-friction"),
        "{e}"
    );
    assert!(!names.contains(&"inertia-rectification"), "{names:?}");
    assert!(
        !e["warnings"].to_string().contains("states no drive"),
        "{}",
        e["warnings"]
    );
    if let Some(c) = e["confidence"].as_f64() {
        for f in e["effects"].as_array().unwrap() {
            let p = f["inclusion_probability"].as_f64().unwrap();
            assert!(p >= c, "{} at {p} below the finding's {c}", f["name"]);
        }
    }
    // Without the drive line the base assumes the board's drive and says so.
    let bare = dir.path().join("bare.csv");
    let rows: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&bare, rows).unwrap();
    let e = json(&[
        "explain",
        "--json",
        "--no-report",
        "--measured",
        bare.to_str().unwrap(),
    ]);
    assert!(
        e["warnings"].to_string().contains("states no drive"),
        "{}",
        e["warnings"]
    );
    assert_eq!(
        e["effects"][0]["name"], "speed-dependent-axial-friction",
        "{e}"
    );
}
