//! `rig record`: the continuous stream to CSV or binary on the virtual device (`--sim`) and
//! on a served virtual rig (`--port`), `--decode`, a refused rate, and Ctrl-C mid-record
//! leaving a complete file.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

use assert_cmd::Command;

mod support {
    pub mod emulated;
    pub mod served;
}
use support::served::Server;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

/// The columns line and the data rows of a recording's CSV (after its `#` lines).
fn csv_rows(path: &Path) -> (String, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).expect("the CSV was written");
    assert!(text.ends_with('\n'), "the last row is whole");
    let mut lines = text.lines().skip_while(|l| l.starts_with('#'));
    let columns = lines.next().expect("a columns line").to_owned();
    let rows = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (columns, rows)
}

/// Every row is a sample numbered one after the other from 0, none lost.
fn assert_whole(rows: &[Vec<String>]) {
    for (i, r) in rows.iter().enumerate() {
        assert_eq!(r[0], i.to_string(), "row {i}: {r:?}");
        assert_eq!(r[13], "0", "row {i} says samples were lost: {r:?}");
    }
}

#[test]
fn a_second_at_10_khz_is_ten_thousand_rows_with_units_and_provenance() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("stream.csv");
    let out = rig()
        .args([
            "--sim",
            "--speed",
            "2",
            "record",
            "--rate",
            "10000",
            "--seconds",
            "1",
            "--out",
        ])
        .arg(&csv)
        .assert()
        .success()
        .get_output()
        .clone();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("recorded 10000 samples at 10000 Hz (1 s), 0 lost"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("# rig record ("), "{}", &text[..200]);
    assert!(text.contains("\n# firmware: "), "the device is named");
    assert!(text.contains("\n# stream: 10000 Hz"));
    let (columns, rows) = csv_rows(&csv);
    assert_eq!(
        columns,
        "seq,t_s,current_adc,current_a,cam_count,cam_angle_rad,output_count,output_angle_rad,duty,tau_cam_nm,state,fault_latched,status,lost"
    );
    assert_eq!(rows.len(), 10_000);
    assert_whole(&rows);
    // t_s is the sample's number over the rate.
    assert_eq!(rows[9_999][1], "0.999900");
    // The progress line said the rate, samples, lost and the file's size.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("10000 Hz: 10000 samples, 0 lost, ") && stderr.contains(" kB written"),
        "{stderr}"
    );
}

#[test]
fn a_binary_recording_is_compact_and_decodes_to_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("stream.bin");
    let csv = dir.path().join("stream.csv");
    rig()
        .args([
            "--sim",
            "--speed",
            "2",
            "record",
            "--rate",
            "5000",
            "--seconds",
            "1",
        ])
        .args(["--format", "bin", "--out"])
        .arg(&bin)
        .assert()
        .success();
    let out = rig()
        .args(["record", "--decode"])
        .arg(&bin)
        .arg("--out")
        .arg(&csv)
        .assert()
        .success()
        .get_output()
        .clone();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("decoded 5000 samples, 0 lost"), "{stdout}");
    let (_, rows) = csv_rows(&csv);
    assert_eq!(rows.len(), 5_000);
    assert_whole(&rows);
    // The provenance came along; the binary is far smaller than the CSV.
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("# rig record ("));
    assert!(text.contains("\n# stream: 5000 Hz"));
    let (b, c) = (
        std::fs::metadata(&bin).unwrap().len(),
        std::fs::metadata(&csv).unwrap().len(),
    );
    assert!(b * 5 < c, "binary {b} B, CSV {c} B");
    // Decoding twice refuses to overwrite.
    let out = rig()
        .args(["record", "--decode"])
        .arg(&bin)
        .arg("--out")
        .arg(&csv)
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("already exists") && err.contains("--force"),
        "{err}"
    );
}

#[test]
fn a_rate_the_device_cannot_stream_names_the_rate_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("x.csv");
    let out = rig()
        .args([
            "--sim",
            "record",
            "--rate",
            "3000",
            "--seconds",
            "1",
            "--out",
        ])
        .arg(&csv)
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("2500 Hz") && err.contains("--rate 2500"),
        "{err}"
    );
    assert!(!csv.exists(), "no file of a header alone");
}

#[test]
fn ctrl_c_mid_record_on_a_served_rig_leaves_a_complete_file() {
    // The served rig at real time: the board's pace and its link's byte rate.
    let server = Server::start_at("1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("long.csv");
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut child = std::process::Command::new(bin)
        .env_remove("RIG_PORT")
        .args(["--port", &server.port, "record", "--rate", "10000", "--out"])
        .arg(&csv)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the first progress line (samples are in the file), not for a wall time.
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut said = String::new();
    loop {
        let mut line = String::new();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "no progress line: {said}"
        );
        said += &line;
        if line.starts_with("10000 Hz: ") {
            break;
        }
    }
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = child.wait().unwrap();
    let mut rest = String::new();
    err.read_to_string(&mut rest).unwrap();
    let mut stdout = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    assert_eq!(status.code(), Some(130), "{said}{rest}");
    assert!(
        rest.contains("stopped by Ctrl-C") && rest.contains("is complete"),
        "{rest}"
    );
    let (_, rows) = csv_rows(&csv);
    assert!(rows.len() >= 1000, "{} rows", rows.len());
    assert_whole(&rows);
    // The summary counts exactly the rows in the file.
    assert!(
        stdout.contains(&format!("recorded {} samples at 10000 Hz", rows.len())),
        "{stdout}"
    );
}

#[test]
fn help_states_the_rates_each_link_carries() {
    let out = rig()
        .args(["record", "--help"])
        .assert()
        .success()
        .get_output()
        .clone();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(
        help.contains("921,600 Bd") && help.contains("92,160 B/s"),
        "{help}"
    );
    assert!(help.contains("4,000,000 Bd"), "{help}");
}

#[test]
fn at_4_mbaud_the_stream_records_beside_the_link_and_another_rate_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("fast.csv");
    rig()
        .args([
            "--sim",
            "--speed",
            "2",
            "--baud",
            "4000000",
            "record",
            "--seconds",
            "0.5",
        ])
        .arg("--out")
        .arg(&csv)
        .assert()
        .success();
    let (_, rows) = csv_rows(&csv);
    assert_eq!(rows.len(), 5_000);
    assert_whole(&rows);
    let out = rig()
        .args(["--sim", "--baud", "2000000", "info"])
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--baud 2000000") && err.contains("--baud 4000000"),
        "{err}"
    );
}

#[test]
fn the_release_image_streams_10_khz_through_its_usart_at_both_link_rates() {
    if !support::emulated::ready() {
        return;
    }
    for baud in ["921600", "4000000"] {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("image.csv");
        let out = rig()
            .args(["--sim", "--firmware", "--baud", baud])
            .args(["record", "--rate", "10000", "--seconds", "1", "--out"])
            .arg(&csv)
            .assert()
            .success()
            .get_output()
            .clone();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            stdout.contains("recorded 10000 samples at 10000 Hz (1 s), 0 lost"),
            "{baud} Bd: {stdout}"
        );
        let (_, rows) = csv_rows(&csv);
        assert_eq!(rows.len(), 10_000, "{baud} Bd");
        assert_whole(&rows);
    }
}
