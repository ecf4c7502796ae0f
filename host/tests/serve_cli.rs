//! `rig sim serve`: the virtual rig served on a pseudo-terminal to separate client
//! processes, with state lasting between them; and the `paper` preset's sweep.

use std::process::Stdio;
use std::time::{Duration, Instant};

use assert_cmd::Command;
use serde_json::Value;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

mod support {
    pub mod served;
}
use support::served::Server;

impl Server {
    fn start(extra: &[&str]) -> Self {
        Self::start_at("5", extra)
    }

    fn client(&self, args: &[&str]) -> Command {
        let mut c = rig();
        c.args(["--port", &self.port]).args(args);
        c
    }

    fn json(&self, args: &[&str]) -> Value {
        let out = self
            .client(args)
            .assert()
            .success()
            .get_output()
            .stdout
            .clone();
        let text = String::from_utf8(out).unwrap();
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("not JSON ({e}):\n{text}"))
    }

    /// `rig faults --json`: exit 0 with nothing latched, 3 while a fault is latched.
    fn faults(&self) -> Value {
        let out = self.client(&["faults", "--json"]).output().unwrap();
        let v: Value = serde_json::from_slice(&out.stdout).unwrap();
        let latched = !v["latched"].as_array().unwrap().is_empty();
        assert_eq!(out.status.code(), Some(if latched { 3 } else { 0 }), "{v}");
        v
    }

    /// SIGINT, then the exit status.
    fn interrupt(mut self) -> std::process::ExitStatus {
        let sent = std::process::Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .expect("kill(1) runs");
        assert!(sent.success());
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "serve did not stop");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// `rig calibration set` with C1 = `c1` (N mm/A) through `server`, read back by `rig
/// calibration get`; the file goes in `dir`.
fn calibration_round_trip(server: &Server, dir: &std::path::Path, c1: f64) {
    let file = dir.join("cal.toml");
    std::fs::write(&file, format!("c1_nmm_per_a = {c1}\n")).unwrap();
    let v = server.json(&[
        "calibration",
        "set",
        file.to_str().unwrap(),
        "--yes",
        "--json",
    ]);
    assert_eq!(v["written"], true, "{v}");
    let v = server.json(&["calibration", "get", "--json"]);
    assert!(
        (v["c1_nmm_per_a"].as_f64().unwrap() - c1).abs() < 1e-4,
        "{v}"
    );
}

#[test]

fn served_rig_keeps_calibration_and_faults_between_clients_and_stops_on_sigint() {
    let server = Server::start(&[
        "--preset",
        "ideal",
        "--effect",
        "speed-dependent-axial-friction",
    ]);
    assert_eq!(server.ready["preset"], "ideal");
    assert_eq!(server.ready["speed"], 5.0);
    assert_eq!(server.ready["seed"], 1);
    assert_eq!(
        server.ready["effects"][0], "speed-dependent-axial-friction",
        "{}",
        server.ready
    );
    let info = server.json(&["info", "--json"]);
    assert_eq!(info["board"], "virtual", "{info}");

    // A calibration written by one command is read back by the next.
    let dir = tempfile::tempdir().unwrap();
    calibration_round_trip(&server, dir.path(), 62.0);

    // A client that vanishes during a release leaves a latched fault (the comms timeout, or
    // the spin-up's CANNOT_RELEASE when the link went while spinning up), which the next
    // clients see until one clears it.
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut release = std::process::Command::new(bin)
        .args(["--port", &server.port, "release", "on", "--for", "30"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // It vanishes once the release was accepted (its first line), whatever this machine's
    // load: a guessed sleep could kill it before it opened the port.
    let mut lines = std::io::BufReader::new(release.stdout.take().unwrap());
    let mut first = String::new();
    std::io::BufRead::read_line(&mut lines, &mut first).unwrap();
    assert!(first.starts_with("released"), "{first}");
    release.kill().unwrap();
    release.wait().unwrap();
    let t0 = Instant::now();
    loop {
        let f = server.faults();
        if !f["latched"].as_array().unwrap().is_empty() {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no latched fault: {f}"
        );
        std::thread::sleep(Duration::from_millis(300));
    }
    let latched = server.faults()["latched"].clone();
    let again = server.faults();
    assert!(!latched.as_array().unwrap().is_empty());
    assert_eq!(again["latched"], latched, "still latched in a new command");
    server.client(&["clear"]).assert().success();
    let f = server.faults();
    assert!(f["latched"].as_array().unwrap().is_empty(), "{f}");

    let status = server.interrupt();
    assert_eq!(status.code(), Some(130), "SIGINT ends serve with 128 + 2");
}

/// A second client of a port one client holds is told the port is busy and who holds it,
/// not that it is missing, and cannot drive the rig; once the first ends, the port opens.
#[test]
fn a_second_client_is_told_the_port_is_busy_and_by_whom() {
    let server = Server::start_at("1", &["--preset", "ideal"]);
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut release = std::process::Command::new(bin)
        .args(["--port", &server.port, "release", "on", "--for", "60"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The first line is printed once the release was accepted: the port is open by then.
    // The reader lives to the end: a closed pipe would end the release at its next line.
    let mut lines = std::io::BufReader::new(release.stdout.take().unwrap());
    let mut first = String::new();
    std::io::BufRead::read_line(&mut lines, &mut first).unwrap();
    assert!(first.starts_with("released"), "{first}");

    let out = server.client(&["info"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{first} {err} {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        err.contains(&format!("serial port {} is busy", server.port)),
        "{err}"
    );
    assert!(
        err.contains(&format!("held by process {} (rig)", release.id())),
        "{err}"
    );
    assert!(err.contains("close that program"), "{err}");
    assert!(!err.contains("does not exist"), "{err}");
    // The release the first client holds is untouched by the refused one.
    assert_eq!(
        release.try_wait().unwrap(),
        None,
        "the first client still runs"
    );

    let sent = std::process::Command::new("kill")
        .args(["-INT", &release.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = release.wait().unwrap();
    assert_eq!(
        status.code(),
        Some(130),
        "Ctrl-C ends release on, locked, with 128 + 2: {status}"
    );
    let info = server.json(&["info", "--json"]);
    assert_eq!(
        info["board"], "virtual",
        "the port opens once its holder ended: {info}"
    );
}

/// Issue 12's "done when", in one session: a served ideal rig with the effect hidden, info,
/// a calibration written by one command and read by the next, a quick torque sweep through
/// 50 random bytes a second on the line, `rig explain` naming the hidden effect first, and
/// SIGINT ending the server with exit 0.
#[test]
fn issue_12_done_when_served_rig_sweep_through_line_noise_explained() {
    // At the board's own pace: a client has the board's 0.5 s comms timeout of wall time
    // (less a heartbeat period) between heartbeats, as at a real rig (the served rig keeps
    // board time and never waits for a host). At 2x (250 ms) a client starved by a machine
    // under load 11 lost its release in the first point; at 20x it had 25 ms.
    let server = Server::start_at(
        "1",
        &[
            "--preset",
            "ideal",
            "--effect",
            "speed-dependent-axial-friction",
            "--line-noise-bytes-per-s",
            "50",
        ],
    );
    let info = server.json(&["info", "--json"]);
    assert_eq!(info["board"], "virtual", "{info}");

    let dir = tempfile::tempdir().unwrap();
    calibration_round_trip(&server, dir.path(), 62.3);

    let csv = dir.path().join("sweep.csv");
    server
        .client(&["experiment", "torque-sweep", "--quick", "--csv"])
        .arg(&csv)
        .assert()
        .success();
    let body = std::fs::read_to_string(&csv).unwrap();
    let rows = body
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("point"))
        .count();
    assert_eq!(rows, 30, "{body}");

    let out = rig()
        .args(["explain", "--no-report", "--json", "--measured"])
        .arg(&csv)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let e: Value = serde_json::from_slice(&out).unwrap();
    // Named first: the first effect the verdict adds, and nothing stacked on it.
    let first = e["effects"][0]["name"].as_str().unwrap_or_default();
    assert_eq!(first, "speed-dependent-axial-friction", "{e}");
    assert_eq!(e["effects"].as_array().map(Vec::len), Some(1), "{e}");
    // The served rig's window means are precise to a cell-mean noise well under 1 mA, so
    // what the library's law leaves of the virtual plant (a few mA, at the model's own
    // resolution of 2.9 mA) may test as a significant remainder when the host's timing moves
    // the windows: `explained` or `partly-explained`, never a wrong or ambiguous verdict, and
    // the gap shrinks from about 37 mA to within twice that resolution (3.5-4.4 mA seen).
    let verdict = e["verdict"].as_str().unwrap_or_default();
    assert!(
        verdict == "explained" || verdict == "partly-explained",
        "{verdict}: {e}"
    );
    let (before, after) = (
        e["rmse_before_a"].as_f64().unwrap(),
        e["rmse_after_a"].as_f64().unwrap(),
    );
    let floor = e["lack_of_fit"]["floor_a"].as_f64().unwrap();
    assert!(
        before > 0.03 && after < 2.0 * floor,
        "{after} A after, {before} A before, resolution {floor} A: {e}"
    );

    assert_eq!(
        server.interrupt().code(),
        Some(130),
        "SIGINT ends serve with 128 + 2"
    );
}

#[test]
fn a_client_works_through_line_noise() {
    // 50 random bytes per second into each direction of the line.
    let server = Server::start(&["--line-noise-bytes-per-s", "50", "--seed", "3"]);
    for _ in 0..3 {
        let info = server.json(&["info", "--json"]);
        assert_eq!(info["board"], "virtual", "{info}");
        let f = server.json(&["faults", "--json"]);
        assert!(f["latched"].as_array().unwrap().is_empty(), "{f}");
    }
    let status = server.interrupt();
    assert_eq!(status.code(), Some(130));
}

#[test]
fn serve_refuses_an_unknown_effect_naming_the_known_ones() {
    let out = rig()
        .args(["sim", "serve", "--effect", "gremlins"])
        .assert()
        .failure();
    let e = String::from_utf8_lossy(&out.get_output().stderr).into_owned();
    assert!(
        e.contains("gremlins") && e.contains("linear-bush-friction"),
        "{e}"
    );
    // The seeds' effects are served (the plant runs them as physics of the teeth); a value
    // the plant cannot take is refused naming it.
    let out = rig()
        .args([
            "sim",
            "serve",
            "--effect",
            "mesh-load-sharing-ripple:ripple_rms=2",
        ])
        .assert()
        .failure();
    let e = String::from_utf8_lossy(&out.get_output().stderr).into_owned();
    assert!(e.contains("ripple_rms"), "{e}");
}

/// The `paper` preset behaves as the paper's rig measured: no backdrive at 0.368 N m with
/// 3.6 and 6.2 V (but at 8.8 V), the torque furthest below Eq. (10) at 3.6 V, and
/// `rig explain` names both of the paper's own explanations.
#[test]

fn paper_preset_sweep_shows_what_the_paper_measured() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sweep.csv");
    rig()
        .args([
            "sim",
            "torque-sweep",
            "--levels",
            "4",
            "--repeats",
            "2",
            "--rest",
            "2",
        ])
        .arg("--csv")
        .arg(&csv)
        .assert()
        .success();
    // The provenance (`#` lines: the command, the drive) comes before the column names.
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(&csv)
        .unwrap();
    let head = r.headers().unwrap().clone();
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let (v, tau, meas, eq10, back, w) = (
        col("v_in_v"),
        col("tau_rot_nm"),
        col("tau_cam_meas_nm"),
        col("tau_cam_eq10_nm"),
        col("backdriven"),
        col("omega_n_rad_s"),
    );
    // The paper's rig took no power back (`sim::Preset::PAPER_DRIVE`); the board's braking
    // drive returns -kappa of Eq. (10)'s inertia term, which grows with w^2 and would hide
    // the low-speed dip. So the comparison is with Eq. (10) as the drive realises it.
    let drive = model::CamDrive::paper(model::GearSet::paper(model::paper::RIG_Z).unwrap());
    let kappa = model::effects::drive_kappa(model::hardware::board::REGENERATIVE_DECAY);
    let mut diff = std::collections::BTreeMap::<String, (f64, f64)>::new();
    let mut lowest = 0;
    for row in r.records() {
        let row = row.unwrap();
        let f = |i: usize| row[i].parse::<f64>().unwrap();
        let e = diff.entry(row[v].to_string()).or_default();
        e.0 += f(meas) - (f(eq10) + kappa * drive.required_inertia_torque(f(w)));
        e.1 += 1.0;
        if (f(tau) - 0.368).abs() < 1e-6 {
            lowest += 1;
            let want = if f(v) < 7.0 { "0" } else { "1" };
            assert_eq!(&row[back], want, "{row:?}");
        }
    }
    assert_eq!(lowest, 6);
    let mean = |k: &str| diff[k].0 / diff[k].1;
    assert!(
        mean("3.6") < mean("6.2") && mean("3.6") < mean("8.8"),
        "mean(measured - Eq. 10): {diff:?}"
    );
    let out = rig()
        .args(["explain", "--no-report", "--json", "--measured"])
        .arg(&csv)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let e: Value = serde_json::from_slice(&out).unwrap();
    // Both of the paper's explanations are named (with them, on this sweep, the
    // load-dependent form of inertia rectification takes up the few mA by which the virtual
    // plant and the library's law differ; it may be named first, as a pair with the axial
    // friction).
    let named: Vec<&str> = e["effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f["name"].as_str())
        .collect();
    // With the sweep's stated drive in the base (issue 31), the paper's speed-dependent
    // axial friction is named first and the drive's own return never is; the bush
    // friction (a few mA on this quick sweep) is in 8 % of the resamples and not named:
    // session 10 left it to trace (it was named before the drive line, beside a
    // load-dependent inertia form that took up the plant/law difference).
    assert_eq!(
        named.first(),
        Some(&"speed-dependent-axial-friction"),
        "{e}"
    );
    assert!(!named.contains(&"inertia-rectification"), "{e}");
}

/// `--preset ideal` is the paper's equations alone: every point is backdriven.
#[test]
fn ideal_preset_sweep_backdrives_everywhere() {
    let v: Value = serde_json::from_slice(
        &rig()
            .args([
                "sim",
                "torque-sweep",
                "--levels",
                "2",
                "--repeats",
                "1",
                "--rest",
                "1",
            ])
            .args(["--preset", "ideal", "--json"])
            .assert()
            .success()
            .get_output()
            .stdout,
    )
    .unwrap();
    assert_eq!(v["not_backdriven"], 0, "{v}");
}

/// docs/examples/rig_client.py talks to the served rig (with pyserial when installed, else
/// through its raw-file fallback); skipped without python3.
#[test]
fn python_example_reads_info_and_telemetry() {
    let Ok(status) = std::process::Command::new("python3")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
    else {
        eprintln!("skipped: no python3 on this machine");
        return;
    };
    assert!(status.success());
    let server = Server::start(&[]);
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/rig_client.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(&server.port)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["info"]["board"], "virtual", "{v}");
    assert_eq!(
        v["info"]["protocol_version"],
        protocol::PROTOCOL_VERSION,
        "{v}"
    );
    assert_eq!(v["telemetry"]["state"], "locked", "{v}");
    // The rig serves the next client as before.
    assert_eq!(server.json(&["info", "--json"])["board"], "virtual");
    assert_eq!(server.interrupt().code(), Some(130));
}

#[test]
fn a_firmware_image_that_is_not_there_or_not_an_elf_is_refused_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.elf");
    let out = rig()
        .args(["sim", "serve"])
        .arg(format!("--firmware={}", missing.display()))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("--firmware") && e.contains("cargo xtask firmware"),
        "{e}"
    );
    // A file that is not an ELF: named, with what to give instead (needs the emulator
    // only after the file is read, so it is checked first).
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, "not an image").unwrap();
    let out = rig()
        .args(["sim", "serve"])
        .arg(format!("--firmware={}", text.display()))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("notes.txt"), "{e}");
    // On a device verb, --firmware needs --sim.
    let out = rig().args(["--firmware", "info"]).output().unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("--firmware") && e.contains("add --sim"), "{e}");
}
