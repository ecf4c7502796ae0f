//! `rig design --x`, `rig design search` and a designed gear on the virtual rig, run
//! through the real binary; the search's designs re-checked by formulas written out here
//! (ISO 21771 / KHK geometry, Willis' equation with the paper's Eq. 19), not the model's.

use std::f64::consts::PI;

use assert_cmd::Command;
use serde_json::Value;

fn rig() -> Command {
    Command::cargo_bin("rig").expect("the rig binary is built")
}

mod support {
    pub mod cli;
}
use support::cli::json_of;

fn json(args: &[&str]) -> Value {
    json_of(rig().args(args))
}

/// A small search around the paper's gear that still finds designs that stop.
const SEARCH: &[&str] = &[
    "design",
    "search",
    "--teeth",
    "47,53",
    "--max-n",
    "1",
    "--max-sum-difference",
    "1",
    "--stop-margin",
    "0.1",
    "--limit",
    "5",
];

#[test]
fn zero_shift_gives_today_s_numbers() {
    let plain = json(&["design", "--z", "49,51,50,50", "--json"]);
    let shifted = json(&["design", "--z", "49,51,50,50", "--x", "0,0,0,0", "--json"]);
    assert_eq!(plain, shifted);
    for key in [
        "z",
        "n",
        "rho",
        "contact_ratios",
        "big_lambda",
        "small_lambda",
        "mu_s_lambda",
        "mu_d_lambda",
        "holds_load",
        "keeps_moving_after_stop",
        "omega_n_rad_s",
        "tau_rot_nm",
        "tau_cam_hat_nm",
        "warnings",
    ] {
        assert!(plain.get(key).is_some(), "missing {key}");
    }
    assert!((plain["mu_s_lambda"].as_f64().unwrap() - 1.336).abs() < 1e-3);
    assert!((plain["mu_d_lambda"].as_f64().unwrap() - 0.858).abs() < 1e-3);
    assert_eq!(plain["warnings"].as_array().unwrap().len(), 1);
}

#[test]
fn undercut_and_an_impossible_cam_torque_are_warned() {
    let v = json(&["design", "--z", "10,12,11,11", "--json"]);
    let warnings = v["warnings"].to_string();
    assert!(warnings.contains("G1 undercut"), "{warnings}");
    let v = json(&["design", "--freq", "100", "--json"]);
    let warnings = v["warnings"].to_string();
    assert!(warnings.contains("cam torque"), "{warnings}");
    // Unequal working centre distances are an error naming the fix.
    let out = rig()
        .args(["design", "--z", "49,51,51,50", "--x", "0.2,0.3,0,0"])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let err = String::from_utf8_lossy(&out);
    assert!(err.contains("x3 + x4"), "{err}");
    // A shift range the gear set would refuse is refused up front.
    let out = rig()
        .args(["design", "search", "--shift", "-2,1"])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    assert!(String::from_utf8_lossy(&out).contains("--shift"));
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("a number")
}

fn inv(a: f64) -> f64 {
    a.tan() - a
}

/// Working pressure angle by bisection on inv alpha_w = 2 tan a (x1 + x2)/(z1 + z2) + inv a.
fn alpha_w(z: [f64; 2], x: [f64; 2], a: f64) -> f64 {
    let target = 2.0 * a.tan() * (x[0] + x[1]) / (z[0] + z[1]) + inv(a);
    let (mut lo, mut hi) = (1e-6, 1.4);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if inv(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

#[test]
fn search_designs_pass_every_check_and_hold_under_independent_formulas() {
    let v = json(&[SEARCH, &["--json"]].concat());
    assert!(f(&v["candidates"]) > 10_000.0, "{}", v["candidates"]);
    let designs = v["designs"].as_array().expect("designs");
    assert!(!designs.is_empty(), "no design found: {v}");
    let (m, a) = (1.0, 20f64.to_radians());
    for d in designs {
        for key in [
            "contact_ratios",
            "mesh_contact_ratios",
            "working_pressure_angles_deg",
            "centre_distance_mm",
            "big_lambda",
            "tau_cam_hat_nm",
            "strength_margin",
        ] {
            assert!(d.get(key).is_some(), "missing {key}");
        }
        assert!(f(&d["mu_d_lambda"]) >= 1.1 - 1e-9, "{d}");
        for c in d["checks"].as_array().unwrap() {
            assert_eq!(c["passed"], Value::Bool(true), "{c}");
        }
        let z: Vec<f64> = d["z"].as_array().unwrap().iter().map(f).collect();
        let x: Vec<f64> = d["x"].as_array().unwrap().iter().map(f).collect();
        // Both meshes at the reported centre distance (KHK Table 4.5).
        let mut eps = [0.0; 2];
        for (k, (i, j)) in [(0, 1), (2, 3)].into_iter().enumerate() {
            let aw = alpha_w([z[i], z[j]], [x[i], x[j]], a);
            assert!(
                (aw.to_degrees() - f(&d["working_pressure_angles_deg"][k])).abs() < 1e-6,
                "{d}"
            );
            let a0 = m * (z[i] + z[j]) / 2.0;
            let aw_dist = a0 * a.cos() / aw.cos();
            assert!((aw_dist - f(&d["centre_distance_mm"])).abs() < 1e-3, "{d}");
            // Tip heights (1 + y - x_other) m keep the 0.25 m clearance (KHK).
            let y = (aw_dist - a0) / m;
            let ra = [
                m * (z[i] / 2.0 + 1.0 + y - x[j]).min(z[i] / 2.0 + 1.0 + x[i]),
                m * (z[j] / 2.0 + 1.0 + y - x[i]).min(z[j] / 2.0 + 1.0 + x[j]),
            ];
            let rb = [m * z[i] * a.cos() / 2.0, m * z[j] * a.cos() / 2.0];
            // ISO 21771: path of contact over the base pitch.
            eps[k] = ((ra[0].powi(2) - rb[0].powi(2)).sqrt()
                + (ra[1].powi(2) - rb[1].powi(2)).sqrt()
                - aw_dist * aw.sin())
                / (PI * m * a.cos());
            assert!(eps[k] >= 1.1, "{d}");
            assert!(
                (eps[k] - f(&d["mesh_contact_ratios"][k])).abs() < 1e-9,
                "{d}"
            );
        }
        // Willis' equation with Eq. (19): backdriven from G4 the gear locks when
        // eta12 eta34 <= min(u, 1/u). At mu_d the design must lock (it stops).
        let e: Vec<f64> = d["contact_ratios"]
            .as_array()
            .unwrap()
            .iter()
            .map(f)
            .collect();
        let h12 = 1.0 - e[0] - e[1] + e[0] * e[0] + e[1] * e[1];
        let h34 = 1.0 - e[2] - e[3] + e[2] * e[2] + e[3] * e[3];
        let mu_d = 0.174;
        let eta = (1.0 - mu_d * PI * h12 * (1.0 / z[0] + 1.0 / z[1]))
            * (1.0 - mu_d * PI * h34 * (1.0 / z[2] + 1.0 / z[3]));
        let u = z[0] * z[2] / (z[1] * z[3]);
        assert!(
            eta <= u.min(1.0 / u),
            "{d}: eta0 {eta} vs {}",
            u.min(1.0 / u)
        );
        assert!(f(&d["strength_margin"]) >= 1.0);
        assert!(f(&d["tau_cam_hat_nm"]) <= f(&d["tau_cam_available_nm"]));
    }
}

#[test]
fn a_designed_gear_stops_on_the_virtual_rig_and_the_paper_s_keeps_falling() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("designs");
    let svg = dir.path().join("front.svg");
    rig()
        .args(
            [
                SEARCH,
                &[
                    "--write",
                    out.to_str().unwrap(),
                    "--svg",
                    svg.to_str().unwrap(),
                ],
            ]
            .concat(),
        )
        .assert()
        .success();
    let drawn = std::fs::read_to_string(&svg).unwrap();
    assert!(
        drawn.starts_with("<svg")
            && reporting::check::figure_texts(&drawn)
                .iter()
                .any(|t| t == "μ_d Λ"),
        "{drawn:.200}"
    );
    let file = out.join("design-01.toml");
    let designed = json(&["sim", "fig5", "--model", file.to_str().unwrap(), "--json"]);
    assert!(f(&designed["mu_d_lambda"]) > 1.0, "{designed}");
    assert_eq!(
        designed["held_without_vibration"],
        Value::Bool(true),
        "{designed}"
    );
    assert!(designed["release_to_motion_s"].is_number(), "{designed}");
    assert_eq!(
        designed["stops_after_vibration"],
        Value::Bool(true),
        "{designed}"
    );
    let paper = json(&["sim", "fig5", "--json", "--after-stop", "10"]);
    assert_eq!(
        paper["stops_after_vibration"],
        Value::Bool(false),
        "{paper}"
    );
    assert!(
        f(&paper["after_stop_travel_rad"]) > 5.0 * f(&designed["after_stop_travel_rad"]),
        "paper {paper} vs designed {designed}"
    );
    // The table1 scenario runs the design as its one row: held, then released.
    let rows = json(&["sim", "table1", "--model", file.to_str().unwrap(), "--json"]);
    let row = &rows.as_array().unwrap()[0];
    assert_eq!(
        row["backdriven_without_vibration"],
        Value::Bool(false),
        "{row}"
    );
    assert_eq!(row["backdriven_with_vibration"], Value::Bool(true), "{row}");
}

#[test]
fn a_shifted_design_with_unequal_tooth_sums_runs_on_the_virtual_rig() {
    // Z1 + Z2 = 100, Z3 + Z4 = 101: one working centre distance through the shifts, which
    // the stored record carries (protocol v7), so the firmware accepts it and releases.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("unequal.toml");
    std::fs::write(
        &file,
        "[gear]\nz = [49, 51, 51, 50]\nprofile_shift = [0.2, 0.3, 0.0, -0.017]\n",
    )
    .unwrap();
    let run = json(&["sim", "fig5", "--model", file.to_str().unwrap(), "--json"]);
    assert_eq!(run["z"], serde_json::json!([49, 51, 51, 50]), "{run}");
    assert_eq!(
        run["x"],
        serde_json::json!([0.2, 0.3, 0.0, -0.017]),
        "{run}"
    );
    assert!(run["release_to_motion_s"].is_number(), "{run}");
}

#[test]
fn every_design_the_default_search_writes_runs_on_the_virtual_rig() {
    // `rig design search --write` with its default options, then `rig sim fig5 --model`
    // on each file: every one is stored by the virtual rig's firmware (unequal tooth sums
    // included), held without vibration, released by it, and drawn with the file's gear.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("designs");
    rig()
        .args(["design", "search", "--json", "--write"])
        .arg(&out)
        .assert()
        .success();
    let mut files: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 10, "{files:?}");
    let mut unequal_sums = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let gear: toml::Table = toml::from_str::<toml::Table>(&text).unwrap()["gear"]
            .as_table()
            .unwrap()
            .clone();
        let z: Vec<i64> = gear["z"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_integer().unwrap())
            .collect();
        unequal_sums += usize::from(z[0] + z[1] != z[2] + z[3]);
        let run = json(&["sim", "fig5", "--model", file.to_str().unwrap(), "--json"]);
        let name = file.display();
        assert_eq!(run["z"], serde_json::json!(z), "{name}: {run}");
        if let Some(x) = gear.get("profile_shift") {
            let want: Vec<f64> = x
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_float().unwrap())
                .collect();
            assert_eq!(run["x"], serde_json::json!(want), "{name}: {run}");
        }
        assert_eq!(
            run["held_without_vibration"],
            Value::Bool(true),
            "{name}: {run}"
        );
        assert!(run["release_to_motion_s"].is_number(), "{name}: {run}");
        assert!(f(&run["mu_d_lambda"]) > 1.0, "{name}: {run}");
    }
    // The search closes tooth-sum differences by shift: some designs need the shifts on
    // the wire (the ones the virtual rig refused before protocol v7).
    assert!(unequal_sums >= 1, "{files:?}");
}
