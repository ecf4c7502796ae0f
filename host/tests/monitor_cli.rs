//! `rig monitor` from the operator's side: flags explained, stale estimates cleared.

use std::time::Duration;

use assert_cmd::Command;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

fn stdout(c: &mut Command) -> String {
    String::from_utf8(c.assert().success().get_output().stdout.clone()).unwrap()
}

#[test]
fn explain_names_every_status_flag_and_the_stale_rule() {
    let text = stdout(rig().args(["monitor", "--explain"]));
    for flag in [
        "COASTS_AFTER_STOP",
        "NOT_SELF_LOCKING",
        "HOST_RELEASE",
        "BUTTON_RELEASE",
        "CAPTURE_RUNNING",
        "CALIBRATION_DEFAULTS",
        "OUTPUT_MOVING",
        "OPEN_LOOP",
    ] {
        assert!(text.contains(flag), "{flag} missing:\n{text}");
    }
    assert!(text.contains("stale") && text.contains("`-`"), "{text}");
    assert!(text.lines().all(|l| l.chars().count() <= 160), "{text}");
}

#[test]
fn estimates_show_a_dash_while_locked_and_values_while_vibrating() {
    let text = stdout(rig().args([
        "--sim",
        "--speed",
        "5",
        "monitor",
        "--plain",
        "--seconds",
        "3",
        "--rate",
        "20",
        "--release",
        "10",
    ]));
    // Columns under the header: time_s state cam_hz current_a tau_cam_nm bus_v output_rad faults.
    let head = text.lines().next().unwrap();
    assert!(head.contains("current_a tau_cam_nm bus_v"), "{head}");
    let cols = |l: &str| l.split_whitespace().map(str::to_owned).collect::<Vec<_>>();
    let locked: Vec<&str> = text.lines().filter(|l| l.contains(" locked ")).collect();
    assert!(!locked.is_empty(), "{text}");
    assert!(
        locked
            .iter()
            .all(|l| cols(l)[4] == "-" && cols(l)[5].parse::<f64>().is_ok()),
        "{text}"
    );
    let vibrating: Vec<&str> = text.lines().filter(|l| l.contains("vibrating")).collect();
    let last = vibrating.last().expect("it vibrated");
    assert!(
        cols(last)[4] != "-" && cols(last)[4].parse::<f64>().is_ok(),
        "a current estimate while vibrating: {last}"
    );
    assert!(text.lines().all(|l| l.len() <= 80), "{text}");
}
