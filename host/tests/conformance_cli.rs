//! `rig conformance` against a served virtual rig, at real time and faster: every check of
//! the device contract passes, and the JSON lists each one.

use std::time::Duration;

use assert_cmd::Command;
use serde_json::Value;

mod support {
    pub mod emulated;
    pub mod served;
}
use support::served::Server;

/// The checks every run lists (the motion ones run: a served rig is a simulation).
const CHECKS: [&str; 16] = [
    "handshake",
    "version-refusal",
    "out-of-range-refused",
    "malformed-refused",
    "hostile-frames-and-noise",
    "telemetry-rate-exact",
    "capture-values-exact",
    "one-reply-per-request-under-load",
    "busy-beyond-window",
    "safe-state-after-load",
    "release-before-zero",
    "heartbeat-timeout",
    "release-owner",
    "fault-latch-hold-clear",
    "safe-state-after-faults",
    "device-frames-decode",
];

fn conformance(server: &Server) -> Value {
    conformance_with(server, &[], Duration::from_secs(120))
}

fn conformance_with(server: &Server, env: &[(&str, &str)], timeout: Duration) -> Value {
    let out = Command::cargo_bin("rig")
        .unwrap()
        .env_remove("RIG_PORT")
        .env_remove("RIG_ALLOW_MOTION")
        .envs(env.iter().copied())
        .args(["--port", &server.port, "conformance", "--json"])
        .timeout(timeout)
        .output()
        .unwrap();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert_eq!(
        out.status.code(),
        Some(if v["passed"] == true { 0 } else { 1 }),
        "{v:#}"
    );
    v
}

fn check_all_pass(v: &Value, speed: f64) {
    let checks = v["checks"].as_array().unwrap();
    let names: Vec<&str> = checks.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, CHECKS, "{v:#}");
    for c in checks {
        assert_eq!(c["status"], "pass", "{c:#}");
    }
    assert_eq!(v["passed"], true);
    assert_eq!(v["motion"], true);
    // Info carries the scale as f32.
    let scale = v["time_scale"].as_f64().unwrap();
    assert!(
        (scale - speed).abs() < 1e-6,
        "time scale {scale}, want {speed}"
    );
    assert_eq!(v["protocol_version"], protocol::PROTOCOL_VERSION);
}

#[test]
fn a_served_rig_passes_every_check_at_real_time() {
    let server = Server::start_at("1", &[]);
    let v = conformance(&server);
    check_all_pass(&v, 1.0);
    let window = v["checks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "one-reply-per-request-under-load")
        .unwrap();
    assert!(
        window["detail"]
            .as_str()
            .unwrap()
            .starts_with("1000 of 1000 requests answered"),
        "{window:#}"
    );
}

#[test]
fn a_served_rig_passes_every_check_faster_than_real_time() {
    let server = Server::start_at("5", &[]);
    check_all_pass(&conformance(&server), 5.0);
}

#[test]
fn the_release_image_on_the_emulated_board_passes_every_check() {
    if !support::emulated::ready() {
        return;
    }
    // The image itself (processor in the loop), at the pace this machine sustains, which
    // it reports in Info. It is not a simulation to the tool: motion is allowed by hand.
    let server = Server::start_at("1", &["--firmware"]);
    let pace = server.ready["speed"].as_f64().unwrap();
    let v = conformance_with(
        &server,
        &[("RIG_ALLOW_MOTION", "1")],
        Duration::from_secs(900),
    );
    check_all_pass(&v, pace);
    assert_eq!(v["board"], "nucleo-g474re", "{v:#}");
}

#[test]
fn conformance_refuses_sim_and_names_the_fix() {
    let out = Command::cargo_bin("rig")
        .unwrap()
        .env_remove("RIG_PORT")
        .args(["--sim", "conformance"])
        .timeout(Duration::from_secs(60))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("--sim") && e.contains("rig sim serve"), "{e}");
}
