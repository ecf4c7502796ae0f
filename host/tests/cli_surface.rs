//! The command line's surface, through the real binary: device options only where a device
//! is used, numbers as a person writes them, values the device cannot honour refused with
//! their range (or reported), and files written whole or not at all.

use std::time::Duration;

use assert_cmd::Command;
use serde_json::Value;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

/// Runs `args`, requires failure, and returns stderr.
fn fails(args: &[&str]) -> String {
    let out = rig().args(args).assert().failure().get_output().clone();
    let e = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!e.contains("panicked"), "panic:\n{e}");
    e
}

/// Runs `args`, requires success, and returns stdout.
fn succeeds(args: &[&str]) -> String {
    let out = rig().args(args).assert().success().get_output().clone();
    String::from_utf8(out.stdout).expect("stdout is UTF-8")
}

fn says(text: &str, wants: &[&str]) {
    for w in wants {
        assert!(text.contains(w), "expected {w:?} in:\n{text}");
    }
}

/// Every number literal in `json` (a JSON text), as written.
fn number_literals(json: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut in_string, mut escaped, mut start) = (false, false, None);
    for (i, ch) in json.char_indices() {
        if in_string {
            match (escaped, ch) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            continue;
        }
        let part_of_number = ch.is_ascii_digit() || matches!(ch, '-' | '+' | '.' | 'e' | 'E');
        match (start, part_of_number) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                out.push(&json[s..i]);
                start = None;
            }
            _ => {}
        }
        if ch == '"' {
            in_string = true;
        }
    }
    if let Some(s) = start {
        out.push(&json[s..]);
    }
    out
}

/// Significant digits of a number literal (`0.00378` has 3, `62.099998474121094` 17).
fn significant_digits(literal: &str) -> usize {
    let mantissa = literal.split(['e', 'E']).next().unwrap_or("");
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    let digits = digits.trim_start_matches('0');
    let digits = if mantissa.contains('.') {
        digits
    } else {
        digits.trim_end_matches('0')
    };
    digits.len().max(1)
}

#[test]
fn literals_are_found_and_counted() {
    let v = number_literals(r#"{"a":62.1,"b":"x1.5","c":[-0.00378,2e-5],"d":10}"#);
    assert_eq!(v, ["62.1", "-0.00378", "2e-5", "10"]);
    assert_eq!(significant_digits("62.099998474121094"), 17);
    assert_eq!(significant_digits("-0.00378"), 3);
}

#[test]
fn device_options_are_refused_by_verbs_without_a_device() {
    // After the verb clap itself refuses them.
    let e = fails(&["design", "--port", "/dev/x"]);
    says(&e, &["--port"]);
    // Before the verb: refused by name, with where they go.
    let e = fails(&["--port", "/dev/x", "design"]);
    says(&e, &["--port", "rig design", "uses no device", "info"]);
    let e = fails(&["--sim", "sim", "fig5"]);
    says(&e, &["--sim", "rig sim"]);
    let e = fails(&["--baud", "9600", "ports"]);
    says(&e, &["--baud", "rig ports"]);
    let e = fails(&["--speed", "2", "explain", "--synthetic", "none"]);
    says(&e, &["--speed", "rig explain"]);
    // $RIG_PORT is read only when a device is opened.
    let out = rig()
        .env("RIG_PORT", "/dev/does-not-exist")
        .args(["design", "--json"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let v: Value = serde_json::from_slice(&out).unwrap();
    assert_eq!(v["holds_load"], true);
    // The simulated demo runs in virtual time and has no serial line.
    says(&fails(&["--speed", "5", "demo"]), &["--speed", "rig demo"]);
    says(&fails(&["demo", "--baud", "9600"]), &["--baud", "--port"]);
}

#[test]
fn device_options_go_before_or_after_a_device_verb() {
    let before: Value = serde_json::from_str(&succeeds(&["--sim", "info", "--json"])).unwrap();
    let after: Value = serde_json::from_str(&succeeds(&["info", "--sim", "--json"])).unwrap();
    assert_eq!(before["sim"], true);
    assert_eq!(after["sim"], true);
    assert_eq!(before["firmware_version"], after["firmware_version"]);
    // Below a verb's own subcommand too.
    let v: Value = serde_json::from_str(&succeeds(&[
        "calibration",
        "get",
        "--json",
        "--sim",
        "--speed",
        "10",
    ]))
    .unwrap();
    assert!(v.is_object(), "{v}");
    let e = fails(&["--sim", "info", "--port", "/dev/ttyACM0"]);
    says(&e, &["--port", "cannot be used with --sim"]);
    let help = succeeds(&["info", "--help"]);
    says(&help, &["--port", "--sim", "Device options"]);
    let help = succeeds(&["design", "--help"]);
    assert!(!help.contains("--port"), "{help}");
}

#[test]
fn numbers_print_as_a_person_writes_them() {
    // Telemetry is f32 on the wire: widened to f64 it would print 17 digits.
    let text = succeeds(&[
        "--sim",
        "monitor",
        "--json",
        "--seconds",
        "0.3",
        "--rate",
        "20",
    ]);
    assert!(text.lines().count() >= 5, "{text}");
    for line in text.lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        assert!(v["current_a"].is_number(), "{line}");
        for n in number_literals(line) {
            assert!(significant_digits(n) <= 9, "{n} in {line}");
        }
        // Device time in microseconds, printed in seconds: 0.054, not 0.054000000000000006.
        let t = v["device_time_s"].to_string();
        assert!(t.len() <= 10, "{t}");
    }
    // Virtual time counted in 1 ms steps reads as such: 0.304, not 0.3040000000000002.
    let text = succeeds(&["sim", "fig5", "--json", "--hold", "1"]);
    let v: Value = serde_json::from_str(&text).unwrap();
    let t = v["release_to_motion_s"].to_string();
    assert!(
        significant_digits(&t) <= 4,
        "release_to_motion_s = {t}:\n{text}"
    );
    let text = succeeds(&[
        "--sim",
        "--speed",
        "10",
        "capture",
        "--seconds",
        "0.05",
        "--json",
    ]);
    let v: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["duration_s"].to_string(), "0.05");
}

#[test]
fn values_the_device_would_change_are_refused_with_their_range() {
    let e = fails(&[
        "--sim", "--speed", "10", "release", "on", "--freq", "18", "--for", "1",
    ]);
    says(
        &e,
        &[
            "--freq 18",
            "1 to 15 Hz",
            "max_freq_hz",
            "rig calibration set",
        ],
    );
    let e = fails(&["--sim", "capture", "--rate", "3000"]);
    says(
        &e,
        &[
            "--rate 3000",
            "10000 Hz divided by a whole number",
            "2500 and 5000 Hz",
        ],
    );
    let e = fails(&["--sim", "capture", "--seconds", "0.00001"]);
    says(&e, &["--seconds", "at least 0.0001 s"]);
    let e = fails(&[
        "--sim",
        "--speed",
        "10",
        "capture",
        "--seconds",
        "0.1",
        "--release",
        "16",
    ]);
    says(&e, &["--release 16", "1 to 15 Hz"]);
    let e = fails(&["--sim", "monitor", "--rate", "300", "--seconds", "0.1"]);
    says(&e, &["--rate 300", "250 and 500 Hz"]);
    let e = fails(&[
        "--sim",
        "--speed",
        "10",
        "monitor",
        "--release",
        "20",
        "--seconds",
        "0.1",
    ]);
    says(&e, &["--release 20", "1 to 15 Hz"]);
    let e = fails(&["sim", "fig5", "--freq", "16"]);
    says(&e, &["--freq 16", "simulated rig drives 1 to 15 Hz"]);
    let e = fails(&["sim", "table1", "--freq", "0.5"]);
    says(&e, &["--freq 0.5", "1 to 15 Hz"]);
    // A burst longer than the buffer is refused with the longest the device records (the
    // device itself refuses rather than capping it).
    let e = fails(&["--sim", "--speed", "10", "capture", "--seconds", "1.5"]);
    says(&e, &["--seconds 1.5", "10000 samples (1 s at 10000 Hz)"]);
}

#[test]
fn a_failed_run_leaves_existing_files_alone() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap.csv");
    std::fs::write(&cap, "old capture\n").unwrap();
    // Refused after the device was opened (the frequency is checked against its calibration).
    let e = fails(&[
        "--sim",
        "--speed",
        "10",
        "capture",
        "--seconds",
        "0.1",
        "--release",
        "18",
        "--csv",
        cap.to_str().unwrap(),
    ]);
    says(&e, &["--release 18"]);
    assert_eq!(std::fs::read_to_string(&cap).unwrap(), "old capture\n");
    let mon = dir.path().join("mon.csv");
    std::fs::write(&mon, "old log\n").unwrap();
    fails(&[
        "--sim",
        "--speed",
        "10",
        "monitor",
        "--plain",
        "--seconds",
        "0.2",
        "--release",
        "18",
        "--csv",
        mon.to_str().unwrap(),
    ]);
    assert_eq!(std::fs::read_to_string(&mon).unwrap(), "old log\n");
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "temporary files left: {names:?}");
    // A run that succeeds replaces the file whole.
    succeeds(&[
        "--sim",
        "--speed",
        "10",
        "capture",
        "--seconds",
        "0.05",
        "--csv",
        cap.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&cap).unwrap();
    assert!(text.starts_with("index,t_s,"), "{text}");
    assert_eq!(text.lines().count(), 501);
}
