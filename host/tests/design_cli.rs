//! `rig design` and `rig demo` contracts, run through the real binary.

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
    serde_json::from_slice(&out).expect("stdout is JSON")
}

#[test]
fn single_gear_set_json_has_the_contract_keys() {
    let v = json(&["design", "--z", "49,51,50,50", "--json"]);
    for key in [
        "z",
        "rho",
        "big_lambda",
        "mu_s_lambda",
        "mu_d_lambda",
        "holds_load",
        "contact_ratios",
    ] {
        assert!(v.get(key).is_some(), "missing {key}: {v}");
    }
    assert_eq!(v["z"], serde_json::json!([49, 51, 50, 50]));
    assert!((v["rho"].as_f64().unwrap() - 25.5).abs() < 0.01);
    assert!((v["mu_s_lambda"].as_f64().unwrap() - 1.336).abs() < 0.001);
    assert_eq!(v["holds_load"], Value::Bool(true));
    assert_eq!(v["contact_ratios"].as_array().unwrap().len(), 4);
    // mu_d Lambda = 0.858 < 1: the designer is warned.
    assert!(
        v["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("mu_d*Lambda"))
    );
}

#[test]
fn table1_json_reproduces_the_paper_in_order() {
    let v = json(&["design", "--table1", "--json"]);
    let rows = v.as_array().expect("an array");
    let expected = [
        ([49, 51, 50, 50], 25.5, 1.336, true),
        ([50, 50, 51, 49], -24.5, 1.336, true),
        ([50, 50, 48, 52], 13.0, 0.668, false),
        ([52, 48, 50, 50], -12.0, 0.668, false),
        ([49, 51, 48, 52], 8.84, 0.445, false),
        ([52, 48, 51, 49], -7.84, 0.445, false),
    ];
    assert_eq!(rows.len(), 6);
    for (row, (z, rho, ml, holds)) in rows.iter().zip(expected) {
        assert_eq!(row["z"], serde_json::json!(z));
        assert!((row["rho"].as_f64().unwrap() - rho).abs() < 0.01, "{row}");
        assert!(
            (row["mu_s_lambda"].as_f64().unwrap() - ml).abs() < 0.001,
            "{row}"
        );
        assert_eq!(row["holds_load"], Value::Bool(holds));
    }
}

#[test]
fn eta_gross_gives_mu_from_eta() {
    let v = json(&[
        "design",
        "--z",
        "50,50,51,49",
        "--eta-gross",
        "0.423",
        "--json",
    ]);
    assert!(
        (v["mu_from_eta"].as_f64().unwrap() - 0.271).abs() < 0.001,
        "{v}"
    );
    let v = json(&[
        "design",
        "--z",
        "50,50,51,49",
        "--eta-gross",
        "0.533",
        "--json",
    ]);
    assert!(
        (v["mu_from_eta"].as_f64().unwrap() - 0.174).abs() < 0.001,
        "{v}"
    );
}

#[test]
fn required_cam_torque_follows_load_and_frequency() {
    let low = json(&["design", "--tau-rot", "0.368", "--freq", "5", "--json"]);
    let high = json(&["design", "--tau-rot", "3.68", "--freq", "15", "--json"]);
    assert!(high["tau_cam_hat_nm"].as_f64().unwrap() > low["tau_cam_hat_nm"].as_f64().unwrap());
}

#[test]
fn masses_give_the_equivalent_inertia() {
    let v = json(&[
        "design", "--i1", "0", "--m23", "0", "--i23", "0", "--i4", "0.25", "--json",
    ]);
    assert!((v["i_hat_kg_m2"].as_f64().unwrap() - 0.25).abs() < 1e-12);
}

#[test]
fn bad_input_exits_non_zero_with_a_reason() {
    let cases: [(&[&str], &str); 8] = [
        (&["design", "--z", "0,51,50,50"], "positive"),
        (&["design", "--z", "-1,51,50,50"], "positive"),
        (&["design", "--z", "49,51,50"], "four"),
        (&["design", "--z", "a,51,50,50"], "not a whole number"),
        (
            &["design", "--z", "49,51,50,51"],
            "unequal centre distances",
        ),
        (&["design", "--z", "50,50,50,50"], "tooth difference"),
        (&["design", "--mu-s", "abc"], "not a number"),
        (&["design", "--freq", "-5"], "greater than zero"),
    ];
    for (args, needle) in cases {
        let out = rig().args(args).assert().failure().get_output().clone();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn demo_runs_the_simulated_rig_and_writes_its_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let assert = rig()
        .args(["demo", "--quick", "--out", out.to_str().unwrap()])
        .assert()
        .success();
    let text = String::from_utf8_lossy(&assert.get_output().stdout).into_owned();
    assert!(
        text.contains("every verdict agrees with the paper"),
        "{text}"
    );
    assert!(text.contains("everything agrees with the paper"), "{text}");
    for file in [
        "design.json",
        "fig5.json",
        "table1.json",
        "torque_sweep.csv",
        "torque_sweep.svg",
        "faults.json",
        "summary.json",
        "calibration/calibration.toml",
    ] {
        assert!(out.join(file).exists(), "{file} missing");
    }
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["all_ok"], Value::Bool(true));
    let c = summary["calibration"]["measured"].as_array().unwrap();
    assert!((c[0].as_f64().unwrap() / 62.1 - 1.0).abs() < 0.05);
}
