//! Every device verb of `rig`, run through the real binary against the virtual device
//! (`--sim`: the firmware core and the simulated plant on a pseudo-terminal), faster than
//! real time.

use std::path::Path;
use std::time::Duration;

use assert_cmd::Command;
use serde_json::Value;

/// Virtual seconds per wall-clock second in these tests.
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
use support::cli::{json_of, stdout_of};

#[test]
fn help_lists_every_verb() {
    let text = stdout_of(rig().arg("--help"));
    for verb in [
        "ports",
        "info",
        "faults",
        "clear",
        "release",
        "monitor",
        "capture",
        "calibrate",
        "calibration",
        "design",
        "sim",
        "explain",
        "demo",
    ] {
        assert!(
            text.lines().any(|l| l.trim_start().starts_with(verb)),
            "--help lacks {verb}:\n{text}"
        );
    }
    for opt in ["--port", "--baud", "--sim", "--speed"] {
        assert!(text.contains(opt), "--help lacks {opt}");
    }
    for verb in [
        "ports",
        "info",
        "release",
        "monitor",
        "capture",
        "calibrate",
        "calibration",
    ] {
        rig().args([verb, "--help"]).assert().success();
    }
}

#[test]
fn ports_lists_as_json() {
    let v = json_of(rig().args(["ports", "--json"]));
    let list = v.as_array().expect("an array");
    for p in list {
        assert!(p.get("port").is_some() && p.get("stlink").is_some(), "{p}");
    }
    rig().arg("ports").assert().success();
}

#[test]
fn info_json_has_the_contract_keys() {
    let v = json_of(rig().args(["--sim", "info", "--json"]));
    assert_eq!(v["protocol_version"], protocol::PROTOCOL_VERSION);
    assert_eq!(v["host_protocol_version"], protocol::PROTOCOL_VERSION);
    assert!(
        v["firmware_version"].as_str().unwrap().split('.').count() == 3,
        "{v}"
    );
    assert_eq!(v["board"], "virtual");
    assert_eq!(v["sim"], true);
    // Identity (issue 13): the build, why it last reset, and how long ago.
    assert_eq!(v["firmware_build"], "virtual", "{v}");
    assert_eq!(v["reset_cause"], "power-on", "{v}");
    assert!(v["uptime_s"].as_u64().is_some(), "{v}");
    // The virtual rig has the optional output-shaft encoder fitted and measures its bus;
    // its bridge brakes by default (the README's Pololu G2).
    assert_eq!(
        v["capabilities"],
        serde_json::json!([
            "OUTPUT_ENCODER",
            "BUS_VOLTAGE",
            "SIMULATION",
            "BRAKING_DECAY"
        ]),
        "{v}"
    );
    assert_eq!(v["decay"], "brake", "{v}");
    assert_eq!(v["time_scale"], 1.0, "{v}");
    let v = json_of(rig().args(["--sim", "--speed", "4", "info", "--json"]));
    assert_eq!(v["time_scale"], 4.0, "{v}");
    let text = stdout_of(sim(&["info"]));
    assert!(text.contains("bridge     brake decay"), "{text}");
    assert!(
        text.contains("firmware")
            && text.contains(&format!("protocol   v{}", protocol::PROTOCOL_VERSION)),
        "{text}"
    );
}

#[test]
fn faults_and_clear() {
    let v = json_of(sim(&["faults", "--json"]));
    assert_eq!(v["active"], serde_json::json!([]));
    assert_eq!(v["latched"], serde_json::json!([]));
    assert!(stdout_of(sim(&["faults"])).contains("no faults"));
    let v = json_of(sim(&["clear", "--json"]));
    assert_eq!(v["latched"], serde_json::json!([]));
    let v = json_of(sim(&["clear", "--json"]));
    assert_eq!(v["cleared"], serde_json::json!([]));
    // Nothing was latched, and the message says so rather than claiming a clear.
    let text = stdout_of(sim(&["clear"]));
    assert!(text.contains("no faults were latched"), "{text}");
}

#[test]
fn release_off_reports_what_the_output_does() {
    let v = json_of(sim(&["release", "off", "--json"]));
    assert_eq!(v["released"], false, "{v}");
    assert_eq!(v["state"], "locked", "{v}");
    // The virtual rig has an output encoder: measured at rest, nothing hanging.
    assert_eq!(v["output_moving"], false, "{v}");
    // The paper's gear coasts once moving (mu_d Lambda = 0.858 < 1): said, not hidden.
    assert_eq!(v["coasts_after_stop"], true, "{v}");
    let text = stdout_of(sim(&["release", "off"]));
    assert!(
        text.contains("the gear holds its load (output at rest)"),
        "{text}"
    );
}

#[test]
fn release_vibrates_for_a_bounded_time_then_locks() {
    let v = json_of(sim(&[
        "release", "on", "--freq", "10", "--for", "2", "--json",
    ]));
    let states: Vec<&str> = v["states"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert!(states.contains(&"vibrating"), "{v}");
    assert_eq!(v["final_state"], "locked", "{v}");
    assert_eq!(v["ended_by"], "for");
    let hz = v["mean_vibrating_hz"].as_f64().unwrap();
    assert!((hz - 10.0).abs() < 0.5, "{hz}");
    let text = stdout_of(sim(&["release", "on", "--freq", "5", "--for", "1.5"]));
    assert!(
        text.contains("vibrating") && text.contains("locked after"),
        "{text}"
    );
    assert!(stdout_of(sim(&["release", "off"])).contains("vibration off"));
}

#[test]
fn monitor_prints_lines_and_logs_csv() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mon.csv");
    let text = stdout_of(sim(&[
        "monitor",
        "--plain",
        "--seconds",
        "0.5",
        "--rate",
        "100",
        "--csv",
        csv.to_str().unwrap(),
    ]));
    // A header of the CSV's column names, then one line per sample in 80 columns.
    let (head, lines) = text.split_once('\n').unwrap();
    assert!(
        head.contains("current_a") && head.ends_with("faults"),
        "{head}"
    );
    let lines: Vec<&str> = lines.lines().collect();
    assert!(lines.len() >= 45, "{} lines", lines.len());
    assert!(
        lines
            .iter()
            .all(|l| l.contains("locked") && l.ends_with(" none") && l.len() <= 80),
        "{text}"
    );
    let log = std::fs::read_to_string(&csv).unwrap();
    assert!(
        log.starts_with("device_time_s,state,cam_speed_rad_s"),
        "{log}"
    );
    assert_eq!(log.lines().count(), lines.len() + 1);
    // JSON lines, one object per sample.
    let text = stdout_of(sim(&[
        "monitor",
        "--json",
        "--seconds",
        "0.2",
        "--rate",
        "50",
    ]));
    for line in text.lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        assert_eq!(v["state"], "locked");
    }
    assert!(text.lines().count() >= 9);
    // Released while monitoring: the supervisor spins the cam up to the target.
    let text = stdout_of(sim(&[
        "monitor",
        "--plain",
        "--seconds",
        "2",
        "--rate",
        "20",
        "--release",
        "10",
    ]));
    assert!(
        text.contains("spin_up") && text.contains("vibrating"),
        "{text}"
    );
}

#[test]
fn capture_burst_is_complete_and_converted() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("cap.csv");
    let v = json_of(sim(&[
        "capture",
        "--seconds",
        "0.3",
        "--csv",
        csv.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["sample_rate_hz"], 10_000);
    assert_eq!(v["total_samples"], 3000);
    assert_eq!(v["received"], 3000);
    assert_eq!(v["dropped"], 0);
    assert_eq!(v["completed"], true);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(
            "index,t_s,current_adc,current_a,encoder_count,cam_angle_rad,output_count,output_angle_rad"
        )
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3000);
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r[0], k.to_string());
        // Motor off: the current reads near zero.
        assert!(r[3].parse::<f64>().unwrap().abs() < 0.2, "{r:?}");
        // The virtual rig has an output encoder; the locked gear holds it still.
        assert_eq!((r[6], r[7]), ("0", "0.000000"), "{r:?}");
    }
    assert_eq!(v["mean_output_speed_rad_s"], 0.0);
    // During vibration at 10 Hz: the encoder turns 10 revolutions a second.
    let v = json_of(sim(&[
        "capture",
        "--seconds",
        "0.5",
        "--release",
        "10",
        "--json",
    ]));
    let w = v["mean_cam_speed_rad_s"].as_f64().unwrap();
    assert!((w / std::f64::consts::TAU - 10.0).abs() < 0.5, "{w}");
    assert!(v["mean_current_a"].as_f64().unwrap() > 1.0, "{v}");
    assert_eq!(v["dropped"], 0);
    // Longer than the buffer: refused before the device records, naming the longest.
    let out = sim(&["capture", "--seconds", "1.5"]).assert().failure();
    let e = String::from_utf8_lossy(&out.get_output().stderr).into_owned();
    assert!(
        e.contains("--seconds 1.5") && e.contains("10000 samples (1 s at 10000 Hz)"),
        "{e}"
    );
}

#[test]
fn calibrate_reproduces_table2() {
    let dir = tempfile::tempdir().unwrap();
    let v = json_of(sim(&["calibrate", "--yes", "--json"]).current_dir(dir.path()));
    let table2 = [62.1, -138.0, 0.235, 1.69, 0.00378, 2.25];
    for (k, want) in table2.iter().enumerate() {
        let key = format!("c{}", k + 1);
        let got = v[&key].as_f64().unwrap_or_else(|| panic!("no {key}: {v}"));
        let tol = if k == 3 { 0.5 } else { 0.05 };
        assert!(
            ((got - want) / want).abs() < tol,
            "{key} = {got}, Table 2 {want}"
        );
    }
    assert_eq!(v["written_to_device"], true);
    assert_eq!(v["consistency"]["agree"], true);
    assert!(v["torque_fit"]["r_squared"].as_f64().unwrap() > 0.999);
    assert!(v["no_load_fit"]["r_squared"].as_f64().unwrap() > 0.99);
    // The default folder is under report/, named by the time.
    let folders: Vec<_> = std::fs::read_dir(dir.path().join("report"))
        .expect("rig calibrate wrote under report/")
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(folders.len(), 1, "{folders:?}");
    let out = folders[0].clone();
    let name = out.file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("calibrate-") && name.ends_with('Z'),
        "{name}"
    );
    assert!(!dir.path().join("calibration").exists());
    assert_eq!(
        v["files"]["calibration"].as_str().unwrap(),
        Path::new("report")
            .join(&name)
            .join("calibration.toml")
            .to_str()
            .unwrap()
    );
    for f in [
        "calibration.toml",
        "torque_current.svg",
        "no_load.svg",
        "points.csv",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let svg = std::fs::read_to_string(out.join("torque_current.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("Torque-current"));
    // The file it wrote is a valid calibration file for `calibration set`.
    let cal = out.join("calibration.toml");
    let set = json_of(sim(&[
        "calibration",
        "set",
        cal.to_str().unwrap(),
        "--yes",
        "--json",
    ]));
    assert_eq!(set["written"], true, "{set}");
}

#[test]
fn calibrate_dry_run_writes_nothing_and_takes_gauge_readings_from_csv() {
    let dir = tempfile::tempdir().unwrap();
    // The paper's torque line at the currents a blocked RS-735 draws (V / 0.44 ohm).
    let mut gauge = String::from("volts,gauge_nmm\n");
    let [c1, c2, ..] = model::paper::TABLE2;
    let ohm = model::hardware::rs735::RESISTANCE_OHM;
    for k in 0..9 {
        let volts = 1.05 + 0.1 * f64::from(k);
        gauge.push_str(&format!("{volts:.2},{:.3}\n", c1 * volts / ohm + c2));
    }
    let path = dir.path().join("gauge.csv");
    std::fs::write(&path, gauge).unwrap();
    let v = json_of(
        sim(&[
            "calibrate",
            "--dry-run",
            "--json",
            "--gauge-csv",
            path.to_str().unwrap(),
        ])
        .current_dir(dir.path()),
    );
    assert_eq!(v["dry_run"], true);
    assert_eq!(v["written_to_device"], false);
    assert!(v["files"].is_null());
    assert!(!dir.path().join("calibration").exists());
    assert!(!dir.path().join("report").exists());
    let c1 = v["c1"].as_f64().unwrap();
    assert!((c1 / 62.1 - 1.0).abs() < 0.05, "{c1}");
    let text = stdout_of(sim(&["calibrate", "--dry-run"]).current_dir(dir.path()));
    assert!(text.contains("C1") && text.contains("dry run"), "{text}");
}

#[test]
fn calibration_get_and_set_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cal.toml");
    let text = stdout_of(sim(&["calibration", "get", file.to_str().unwrap()]));
    assert!(text.contains("wrote"), "{text}");
    // A rig file: C1 in [calibration] in the paper's units.
    let toml = std::fs::read_to_string(&file).unwrap();
    assert!(toml.contains("[calibration]\nc1 = 62.1\n"), "{toml}");
    let printed = stdout_of(sim(&["calibration", "get"]));
    assert!(printed.contains("c6 = 2.25"), "{printed}");
    let v = json_of(sim(&["calibration", "get", "--json"]));
    assert!((v["c1_nmm_per_a"].as_f64().unwrap() - 62.1).abs() < 1e-4);
    // Unchanged: nothing to write.
    let same = stdout_of(sim(&[
        "calibration",
        "set",
        file.to_str().unwrap(),
        "--yes",
    ]));
    assert!(same.contains("already has this calibration"), "{same}");
    // A partial file changes only its keys.
    // C1 alone moved within C4 = C1 C6 + C2's tolerance (the firmware's rule).
    std::fs::write(&file, "c1_nmm_per_a = 62.0\nmax_freq_hz = 12.0\n").unwrap();
    let v = json_of(sim(&[
        "calibration",
        "set",
        file.to_str().unwrap(),
        "--yes",
        "--json",
    ]));
    assert_eq!(v["written"], true);
    assert_eq!(v["changed"].as_array().unwrap().len(), 2, "{v}");
    assert!((v["calibration"]["c1_nmm_per_a"].as_f64().unwrap() - 62.0).abs() < 1e-4);
    assert!((v["calibration"]["c2_nmm"].as_f64().unwrap() + 138.0).abs() < 1e-4);
    // Without --yes and without a terminal it refuses.
    let out = sim(&["calibration", "set", file.to_str().unwrap()])
        .assert()
        .failure();
    let e = String::from_utf8_lossy(&out.get_output().stderr).into_owned();
    assert!(e.contains("--yes"), "{e}");
}
