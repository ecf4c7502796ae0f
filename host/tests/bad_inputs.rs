//! Bad inputs to the `rig` device verbs, each with the message it must produce: a missing
//! port, a wrong baud rate, a silent device, a version mismatch (fake peers on a
//! pseudo-terminal), malformed calibration and gauge files, and bad option values.

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use assert_cmd::Command;
use protocol::{
    Capabilities, DeviceInfo, DeviceMessage, FirmwareVersion, Frame, LegacyV1Nack,
    PROTOCOL_VERSION, ParametersStatus, Reply, Request, RequestDeframer, ResetCause, SCHEMA_HASH,
};
use serialport::{SerialPort, TTYPort};

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(60));
    c
}

/// Runs `args`, requires failure, and returns stderr.
fn fails(args: &[&str]) -> String {
    let out = rig().args(args).assert().failure().get_output().clone();
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn assert_says(text: &str, wants: &[&str]) {
    for w in wants {
        assert!(text.contains(w), "expected {w:?} in:\n{text}");
    }
    assert!(!text.contains("panicked"), "panic:\n{text}");
}

/// What a fake device does with the bytes it receives.
#[derive(Clone, Copy)]
enum Peer {
    /// Never answers.
    Silent,
    /// Answers every byte with line noise, as a device at another baud rate would look.
    Garbage,
    /// Answers `Hello` with `Info` of this protocol version (and schema hash).
    Version(u16, u32),
    /// Protocol v1 firmware: answers `Hello` with v1's own refusal layout.
    V1,
}

/// A fake device on a pseudo-terminal; the `rig` binary opens `port`.
struct FakeDevice {
    port: String,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl FakeDevice {
    fn start(peer: Peer) -> Self {
        let (mut master, slave) = TTYPort::pair().expect("pseudo-terminals are available");
        let port = slave.name().expect("the slave has a name");
        // The binary opens the slave exclusively: this process must not hold it.
        drop(slave);
        master.set_timeout(Duration::from_millis(5)).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let mut deframer = RequestDeframer::new();
            let mut buf = [0u8; 256];
            let mut seq = 0u16;
            while !flag.load(Ordering::SeqCst) {
                let n = match master.read(&mut buf) {
                    Ok(n) => n,
                    Err(_) => {
                        // Timed out, or no one has the slave open yet.
                        std::thread::sleep(Duration::from_millis(2));
                        continue;
                    }
                };
                match peer {
                    Peer::Silent => {}
                    Peer::Garbage => {
                        let _ = master.write_all(&[0x55, 0xF3, 0x19, 0x00, 0xA7, 0x00]);
                    }
                    Peer::V1 => {
                        let mut requests = Vec::new();
                        deframer.push(&buf[..n], |f| requests.push(f));
                        for Frame {
                            seq: hello_seq,
                            msg,
                        } in requests.into_iter().flatten()
                        {
                            if let Request::Hello { .. } = msg {
                                seq = seq.wrapping_add(1);
                                let nack = LegacyV1Nack { hello_seq };
                                let frame = protocol::encode_frame_vec(seq, &nack).unwrap();
                                let _ = master.write_all(&frame);
                            }
                        }
                    }
                    Peer::Version(version, hash) => {
                        let mut requests = Vec::new();
                        deframer.push(&buf[..n], |f| requests.push(f));
                        for Frame {
                            seq: request_seq,
                            msg,
                        } in requests.into_iter().flatten()
                        {
                            if let Request::Hello { .. } | Request::GetInfo = msg {
                                let info = DeviceInfo {
                                    firmware_version: FirmwareVersion {
                                        major: 9,
                                        minor: 0,
                                        patch: 0,
                                    },
                                    protocol_version: version,
                                    schema_hash: hash,
                                    firmware_build: "0123abcd".try_into().unwrap(),
                                    board: "fake".try_into().unwrap(),
                                    parameters_status: ParametersStatus::Defaults,
                                    reset_cause: ResetCause::PowerOn,
                                    uptime_s: 1,
                                    capabilities: Capabilities::empty(),
                                    time_scale: 1.0,
                                    max_baud: protocol::DEFAULT_BAUD_RATE,
                                };
                                seq = seq.wrapping_add(1);
                                let reply = DeviceMessage::reply(request_seq, Reply::Info(info));
                                let frame = protocol::encode_frame_vec(seq, &reply).unwrap();
                                let _ = master.write_all(&frame);
                            }
                        }
                    }
                }
            }
        });
        Self {
            port,
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for FakeDevice {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[test]
fn missing_port_names_it_and_how_to_list_ports() {
    let e = fails(&["--port", "/dev/does-not-exist", "info"]);
    assert_says(&e, &["/dev/does-not-exist", "rig ports"]);
}

#[test]
fn no_device_at_all_says_how_to_name_one() {
    // A machine with exactly one ST-LINK plugged in would use it: CI has none.
    let e = fails(&["faults"]);
    assert_says(&e, &["--port", "--sim"]);
}

#[test]
fn unusable_baud_values_are_refused_by_the_parser() {
    let e = fails(&["--sim", "--baud", "0", "info"]);
    assert_says(&e, &["0 baud is not a usable rate", "921600"]);
    let e = fails(&["--sim", "--baud", "fast", "info"]);
    assert_says(&e, &["'fast' is not a baud rate"]);
}

#[test]
fn wrong_baud_rate_line_noise_suggests_the_baud() {
    let dev = FakeDevice::start(Peer::Garbage);
    let e = fails(&["--port", &dev.port, "--baud", "115200", "info"]);
    assert_says(&e, &["no reply", &dev.port, "garbled", "--baud", "921600"]);
}

#[test]
fn silent_device_times_out_with_what_to_check() {
    let dev = FakeDevice::start(Peer::Silent);
    let e = fails(&["--port", &dev.port, "info"]);
    assert_says(
        &e,
        &[
            "no reply from the device on",
            &dev.port,
            "Hello",
            "nothing came back",
            "powered",
        ],
    );
}

#[test]
fn newer_firmware_asks_to_update_the_host_tool() {
    let dev = FakeDevice::start(Peer::Version(PROTOCOL_VERSION + 1, 0x1234_5678));
    let e = fails(&["--port", &dev.port, "info", "--json"]);
    let want = format!(
        "the firmware speaks protocol {}, this rig tool speaks {}: update the rig tool",
        PROTOCOL_VERSION + 1,
        PROTOCOL_VERSION
    );
    assert_says(&e, &[&want, "cargo install"]);
}

#[test]
fn older_firmware_asks_to_flash_the_firmware() {
    let dev = FakeDevice::start(Peer::Version(PROTOCOL_VERSION - 1, 0x1234_5678));
    let e = fails(&["--port", &dev.port, "faults"]);
    assert_says(&e, &["run `rig flash` to update the firmware"]);
}

#[test]
fn v1_firmware_asks_to_flash_the_firmware() {
    // A v1 device can only refuse in v1's layout; the tool recognises it.
    let dev = FakeDevice::start(Peer::V1);
    let e = fails(&["--port", &dev.port, "info"]);
    let want = format!(
        "the firmware speaks protocol 1, this rig tool speaks {PROTOCOL_VERSION}: run `rig flash` to update the firmware"
    );
    assert_says(&e, &[&want]);
}

#[test]
fn same_version_other_schema_asks_for_one_checkout() {
    let dev = FakeDevice::start(Peer::Version(PROTOCOL_VERSION, SCHEMA_HASH ^ 0xFF));
    let e = fails(&["--port", &dev.port, "info"]);
    assert_says(&e, &["message layouts differ", "same source"]);
}

#[test]
fn malformed_calibration_files_change_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, &[&str]); 6] = [
        (
            "type.toml",
            "c1_nmm_per_a = \"high\"\n",
            &["type.toml", "line 1", "invalid type"],
        ),
        (
            "typo.toml",
            "c1 = 62.1\n",
            &["typo.toml", "unknown field `c1`"],
        ),
        (
            "range.toml",
            "c1_nmm_per_a = 62.1\nmu_d = 0.5\n",
            &["range.toml", "`mu_d` is out of range", "not above mu_s"],
        ),
        (
            "syntax.toml",
            "c1_nmm_per_a = [62.1\n",
            &["syntax.toml", "line"],
        ),
        (
            "empty.toml",
            "# nothing here\n",
            &["sets no calibration field"],
        ),
        ("z.toml", "z = [50, 50, 50, 50]\n", &["`z` is out of range"]),
    ];
    for (name, text, wants) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let e = fails(&[
            "--sim",
            "calibration",
            "set",
            path.to_str().unwrap(),
            "--yes",
        ]);
        assert_says(&e, wants);
        assert_says(&e, &["nothing was written to the device"]);
    }
    let e = fails(&["--sim", "calibration", "set", "/no/such/cal.toml", "--yes"]);
    assert_says(&e, &["/no/such/cal.toml", "cannot read it"]);
}

#[test]
fn limits_and_constants_beyond_the_board_are_refused() {
    // The firmware's rule (model::BoardLimits and model::Calibration::check), run before
    // sending: a load cap of 100 N m would switch OVERLOAD off, C1 = 900 is 14 times
    // Table 2. Past the rig file's own ranges (issue 33: 1e30, 2258), the file is refused
    // as it is read, naming the key and its range.
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &[&str])] = &[
        (
            "load.toml",
            "[limits]\nmax_release_load_nm = 100.0\n",
            &["max_release_load_nm", "3.68 N m"],
        ),
        (
            "c1.toml",
            "[calibration]\nc1 = 900.0\n",
            &["c1", "plausible range"],
        ),
        (
            "load-far.toml",
            "[limits]\nmax_release_load_nm = 1e30\n",
            &["max_release_load_nm", "at most 1000"],
        ),
        (
            "c1-far.toml",
            "[calibration]\nc1 = 2258.0\n",
            &["c1", "at most 1000"],
        ),
    ];
    for (name, text, wants) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let e = fails(&[
            "--sim",
            "calibration",
            "set",
            path.to_str().unwrap(),
            "--yes",
        ]);
        assert_says(&e, wants);
        assert_says(&e, &["nothing was written to the device"]);
    }
}

#[test]
fn bad_gauge_file_is_refused_before_the_rig_moves() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gauge.csv");
    std::fs::write(&path, "gauge_nmm\n10\n20\n").unwrap();
    let e = fails(&[
        "--sim",
        "calibrate",
        "--dry-run",
        "--gauge-csv",
        path.to_str().unwrap(),
    ]);
    assert_says(&e, &["gauge.csv", "2 gauge readings for 9 torque steps"]);
}

#[test]
fn option_values_and_combinations() {
    let e = fails(&["--speed", "10", "info"]);
    assert_says(&e, &["add --sim"]);
    let e = fails(&["--sim", "--speed", "0", "info"]);
    assert_says(&e, &["not a speed the simulation can keep"]);
    let e = fails(&["--sim", "--port", "/dev/ttyACM0", "info"]);
    assert_says(&e, &["cannot be used with"]);
    let e = fails(&["--sim", "release", "sideways"]);
    assert_says(&e, &["invalid value 'sideways'", "on, off"]);
    let e = fails(&["--sim", "monitor", "--rate", "5000"]);
    assert_says(&e, &["5000"]);
}

#[test]
fn device_refusal_is_explained() {
    // The firmware drives at most the calibration's max_freq_hz (15 Hz): the tool refuses
    // beyond it before asking, naming the option, the range and the calibration field (the
    // device's own refusal reads "refused Release(on) (argument out of range)", see
    // host's error tests; no Rust `Debug` name such as `BadArgument` reaches the user).
    let e = fails(&[
        "--sim", "--speed", "10", "release", "on", "--freq", "40", "--for", "1",
    ]);
    assert_says(&e, &["--freq 40", "1 to 15 Hz", "max_freq_hz"]);
    assert!(!e.contains("BadArgument"), "{e}");
}

#[test]
fn unwritable_output_is_a_clear_error() {
    let e = fails(&[
        "--sim",
        "capture",
        "--seconds",
        "0.1",
        "--csv",
        "/no/such/dir/c.csv",
    ]);
    assert_says(&e, &["cannot create /no/such/dir/c.csv"]);
}
