//! Issue 33's hostile pass as a batch that prints its figures (not run by CI: each part
//! takes about a minute and they measure rather than gate). Run one with
//! `cargo test -p host --test hostile_batch -- --ignored --nocapture frames` (or
//! `signals`, `files`, `soak`; all of them without a name).
//!
//! - frames: mutated and random frames into the device's and the host's decoders in
//!   process, and into a served virtual rig's port at speed 1 and 20; counts frames,
//!   decoder errors and panics, then checks the served rig still answers with nothing
//!   latched.
//! - signals: SIGINT, SIGTERM and SIGHUP at random moments into the verbs that move the
//!   rig (a served virtual rig); counts runs, exit statuses and faults left latched.
//! - files: hostile files (/dev/zero, a FIFO, a 1 MB line, binary, empty, a CSV cut
//!   mid-row, a rig file of NaN) into every verb that reads a file; counts those refused
//!   cleanly (exit 1 naming the file), accepted, and anything else (a panic, a hang).
//! - soak: a served rig at speed 1 streaming 1,000 samples a second to a monitor for
//!   `RIG_SOAK_S` seconds (default 60); counts samples, lost and bad frames, the served
//!   rig's memory before and after.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use protocol::{DeviceDeframer, Request, RequestDeframer, encode_frame_vec};
use serde_json::Value;

mod support {
    pub mod served;
}
use support::served::Server;

/// A small deterministic generator (xorshift64*), seeded per run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

fn rig_bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("rig")
}

fn rig(port: &str) -> Command {
    let mut c = Command::new(rig_bin());
    c.env_remove("RIG_PORT").args(["--port", port]);
    c
}

/// The faults latched on the served rig at `port`.
fn latched(port: &str) -> Vec<String> {
    let out = rig(port).args(["faults", "--json"]).output().unwrap();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
    v["latched"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|f| f.as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default()
}

/// Valid request frames to mutate.
fn seeds() -> Vec<Vec<u8>> {
    let requests = [
        Request::GetInfo,
        Request::GetFaults,
        Request::ClearFaults,
        Request::GetParameters,
        Request::StopTelemetry,
        Request::StartTelemetry { rate_hz: 50 },
    ];
    requests
        .iter()
        .enumerate()
        .map(|(k, r)| encode_frame_vec(k as u16, r).unwrap())
        .collect()
}

/// A hostile frame: a valid one with bits flipped, bytes cut, inserted or repeated, or
/// random bytes, ending in the frame delimiter.
fn hostile_frame(rng: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    let mut f = seeds[rng.below(seeds.len() as u64) as usize].clone();
    match rng.below(6) {
        0 => {
            for _ in 0..=rng.below(3) {
                let i = rng.below(f.len() as u64) as usize;
                f[i] ^= 1 << rng.below(8);
            }
        }
        1 => f.truncate(rng.below(f.len() as u64) as usize),
        2 => {
            let i = rng.below(f.len() as u64) as usize;
            f.insert(i, rng.next() as u8);
        }
        3 => {
            let copy = f.clone();
            f.extend_from_slice(&copy);
        }
        4 => {
            f = (0..rng.below(300)).map(|_| rng.next() as u8).collect();
        }
        _ => {
            // A frame longer than any message.
            f = (0..2000).map(|_| 1 + rng.below(255) as u8).collect();
        }
    }
    if f.last() != Some(&0) {
        f.push(0);
    }
    f
}

#[test]
#[ignore = "hostile batch: prints figures"]
fn frames() {
    let seeds = seeds();
    let mut rng = Rng(0x33_0001);
    // In process: both decoders, every frame, panics caught and counted.
    let n = 200_000;
    let (mut device, mut host) = (RequestDeframer::new(), DeviceDeframer::new());
    let mut panics = 0;
    let mut results = 0u64;
    for _ in 0..n {
        let f = hostile_frame(&mut rng, &seeds);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let mut k = 0u64;
            device.push(&f, |_| k += 1);
            host.push(&f, |_| k += 1);
            k
        }));
        match r {
            Ok(k) => results += k,
            Err(_) => panics += 1,
        }
    }
    let (d, h) = (device.stats(), host.stats());
    println!(
        "frames in process: {n} hostile frames into both decoders: device {} ok / {} errors, host {} ok / {} errors, {results} results, {panics} panics",
        d.frames_ok,
        d.errors(),
        h.frames_ok,
        h.errors()
    );
    assert_eq!(panics, 0);
    // Into a served rig's port, at speed 1 and 20.
    for speed in ["1", "20"] {
        let mut server = Server::start_at(speed, &[]);
        let sent = 20_000;
        let mut bytes = 0usize;
        {
            let mut port = serialport::new(&server.port, 115_200)
                .timeout(Duration::from_secs(5))
                .open()
                .expect("the served port opens");
            for _ in 0..sent {
                let f = hostile_frame(&mut rng, &seeds);
                port.write_all(&f).unwrap();
                bytes += f.len();
            }
            port.flush().unwrap();
        }
        let info = rig(&server.port).args(["info", "--json"]).output().unwrap();
        let alive = server.child.try_wait().unwrap().is_none();
        let faults = latched(&server.port);
        println!(
            "frames served at speed {speed}: {sent} hostile frames ({bytes} bytes) sent; served rig alive: {alive}; info after: exit {:?}; latched: {faults:?}",
            info.status.code()
        );
        assert!(alive && info.status.success() && faults.is_empty());
    }
}

#[test]
#[ignore = "hostile batch: prints figures"]
fn signals() {
    let server = Server::start_at("1", &[]);
    let port = server.port.clone();
    let dir = tempfile::tempdir().unwrap();
    let sweep_csv = dir.path().join("sweep.csv");
    let cap_csv = dir.path().join("cap.csv");
    let verbs: Vec<Vec<String>> = vec![
        vec!["release", "on", "--freq", "5", "--for", "3"],
        vec![
            "monitor",
            "--plain",
            "--release",
            "5",
            "--seconds",
            "3",
            "--rate",
            "50",
        ],
        vec!["capture", "--seconds", "0.5", "--release", "5"],
        vec!["experiment", "torque-sweep", "--quick", "--force", "--csv"],
    ]
    .into_iter()
    .map(|v| v.into_iter().map(str::to_owned).collect())
    .collect();
    let signals = [("INT", 2), ("TERM", 15), ("HUP", 1)];
    let mut rng = Rng(0x33_0002);
    let runs: usize = std::env::var("RIG_SIGNAL_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(24);
    let mut codes = std::collections::BTreeMap::<String, usize>::new();
    let (mut bad, mut latched_runs) = (0, 0);
    for k in 0..runs {
        let verb = &verbs[k % verbs.len()];
        let (name, number) = signals[rng.below(3) as usize];
        let mut cmd = rig(&port);
        cmd.args(verb);
        if verb[0] == "experiment" {
            cmd.arg(&sweep_csv);
        }
        if verb[0] == "capture" {
            cmd.arg("--csv").arg(&cap_csv);
        }
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // A random moment within the run (0.1-2.5 s of wall time): this is the moment
        // measured, not a wait for anything.
        std::thread::sleep(Duration::from_millis(100 + rng.below(2400)));
        let _ = Command::new("kill")
            .args([format!("-{name}"), child.id().to_string()])
            .status();
        let end = Instant::now() + Duration::from_secs(60);
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break Some(s);
            }
            if Instant::now() > end {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let code = status.and_then(|s| s.code());
        let ok = code == Some(128 + number) || code == Some(0);
        if !ok {
            bad += 1;
        }
        let faults = latched(&port);
        if !faults.is_empty() {
            latched_runs += 1;
            let _ = rig(&port).arg("clear").output();
        }
        println!(
            "signal {k}: SIG{name} into `rig {}`: exit {code:?}{}",
            verb.join(" "),
            if faults.is_empty() {
                String::new()
            } else {
                format!(", latched {faults:?}")
            }
        );
        *codes.entry(format!("{}:{code:?}", verb[0])).or_default() += 1;
    }
    println!(
        "signals: {runs} runs; exit statuses by verb {codes:?}; {bad} not 0 or 128+N; {latched_runs} left a fault latched"
    );
    assert_eq!(bad, 0);
    assert_eq!(latched_runs, 0);
}

/// Runs `rig` with `args` for at most 60 s; (exit code, stderr), `None` for a hang.
fn run_bounded(args: &[String]) -> (Option<i32>, String) {
    let mut child = Command::new(rig_bin())
        .env_remove("RIG_PORT")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let end = Instant::now() + Duration::from_secs(60);
    let code = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s.code();
        }
        if Instant::now() > end {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    (code, reader.join().unwrap_or_default())
}

#[test]
#[ignore = "hostile batch: prints figures"]
fn files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, bytes: &[u8]| -> PathBuf {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let mut rng = Rng(0x33_0003);
    let binary: Vec<u8> = (0..100_000).map(|_| rng.next() as u8).collect();
    let mut files: Vec<(&str, PathBuf)> = vec![
        ("/dev/zero", PathBuf::from("/dev/zero")),
        ("huge line", write("huge.csv", &vec![b'7'; 1 << 20])),
        ("binary", write("binary.csv", &binary)),
        ("empty", write("empty.csv", b"")),
        (
            "CSV cut mid-row",
            write(
                "cut.csv",
                b"omega_n_rad_s,tau_rot_nm,i_in_a\n62.8,0.4,2.6\n62.8,0.8,2.7\n62.8,1.",
            ),
        ),
        (
            "rig file of NaN",
            write(
                "nan.toml",
                b"[gear]\nmodule_mm = nan\n[calibration]\nc1 = inf\n",
            ),
        ),
    ];
    let fifo = d.join("fifo");
    if Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        files.push(("FIFO", fifo));
    }
    let out = d.join("out").display().to_string();
    // A measured file every verb accepts, for the verbs whose hostile file is another one.
    let mut good = String::from("omega_n_rad_s,tau_rot_nm,i_in_a\n");
    for k in 0..12 {
        good += &format!("62.8,{},{}\n", 0.3 * (k % 6) as f64, 2.6 + 0.01 * k as f64);
    }
    let ok = write("ok.csv", good.as_bytes());
    let verbs: Vec<(&str, Vec<&str>)> = vec![
        (
            "explain --measured",
            vec!["explain", "--json", "--measured"],
        ),
        (
            "compare --measured",
            vec!["compare", "--json", "--measured"],
        ),
        (
            "explain --model",
            vec!["explain", "--measured", "ok.csv", "--model"],
        ),
        (
            "compare --rig",
            vec!["compare", "--measured", "ok.csv", "--rig"],
        ),
        ("calibration set", vec!["--sim", "calibration", "set"]),
        (
            "experiment --plan",
            vec![
                "--sim",
                "experiment",
                "torque-sweep",
                "--csv",
                "new.csv",
                "--plan",
            ],
        ),
        (
            "calibrate --from-points",
            vec!["calibrate", "--out", "o", "--from-points"],
        ),
        (
            "calibrate --gauge-csv",
            vec!["--sim", "calibrate", "--yes", "--out", "o", "--gauge-csv"],
        ),
        (
            "torque-sweep --resume",
            vec![
                "--sim",
                "experiment",
                "torque-sweep",
                "--quick",
                "--resume",
                "--csv",
            ],
        ),
        (
            "monitor --resume",
            vec![
                "--sim",
                "monitor",
                "--plain",
                "--seconds",
                "0.1",
                "--resume",
                "--csv",
            ],
        ),
        ("--sim --model", vec!["--sim", "--model"]),
    ];
    let (mut cases, mut refused, mut accepted, mut bad) = (0, 0, 0, 0);
    for (verb, args) in &verbs {
        for (what, file) in &files {
            // A file a verb would change is a copy (the originals serve every verb).
            let file = if verb.contains("--resume") && file.is_file() {
                let copy = d.join(format!("copy-{}", file.file_name().unwrap().display()));
                let _ = std::fs::copy(file, &copy);
                copy
            } else {
                file.clone()
            };
            let mut a: Vec<String> = args
                .iter()
                .map(|s| match *s {
                    "o" => out.clone(),
                    "ok.csv" => ok.display().to_string(),
                    "new.csv" => d.join("new.csv").display().to_string(),
                    s => s.to_owned(),
                })
                .collect();
            a.push(file.display().to_string());
            if *verb == "--sim --model" {
                a.extend(["info".to_owned(), "--json".to_owned()]);
            }
            let _ = std::fs::remove_file(d.join("new.csv"));
            cases += 1;
            let (code, err) = run_bounded(&a);
            let named = err.contains(&file.display().to_string())
                || err.contains(file.file_name().unwrap().to_string_lossy().as_ref());
            let verdict = match code {
                Some(0) => {
                    accepted += 1;
                    "accepted"
                }
                Some(1) | Some(2) if named => {
                    refused += 1;
                    "refused"
                }
                _ => {
                    bad += 1;
                    "NOT CLEAN"
                }
            };
            let first = err
                .lines()
                .last()
                .unwrap_or("")
                .chars()
                .take(150)
                .collect::<String>();
            println!("file: {what} into `{verb}`: {verdict} (exit {code:?}): {first}");
        }
    }
    println!(
        "files: {cases} hostile files into {} verbs: {refused} refused naming the file, {accepted} accepted, {bad} otherwise (a panic, a hang, an unnamed refusal)",
        verbs.len()
    );
    assert_eq!(bad, 0);
}

/// Resident memory of process `pid`, kB.
fn rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

#[test]
#[ignore = "hostile batch: prints figures"]
fn soak() {
    let seconds: f64 = std::env::var("RIG_SOAK_S")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(60.0);
    let server = Server::start_at("1", &[]);
    let pid = server.child.id();
    // A first client, so the served rig's buffers are in use before the first reading.
    let _ = rig(&server.port).args(["info"]).output();
    let before = rss_kb(pid);
    let started = Instant::now();
    let mut child = rig(&server.port)
        .args(["monitor", "--plain", "--rate", "1000", "--release", "5"])
        .args(["--seconds", &seconds.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lines = BufReader::new(child.stdout.take().unwrap()).lines().count();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    let after = rss_kb(pid);
    let faults = latched(&server.port);
    println!(
        "soak: {seconds} s at speed 1, 1000 samples/s, released at 5 Hz: {} lines printed in {:.0} s of wall time; monitor said: {}; exit {:?}; served rig RSS {before:?} kB before, {after:?} kB after; latched {faults:?}",
        lines.saturating_sub(1),
        started.elapsed().as_secs_f64(),
        err.trim(),
        status.code()
    );
    assert!(status.success(), "{err}");
}
