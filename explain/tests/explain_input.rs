//! Units and sanity of `rig explain`'s input (issue 19, item 6 and the bounded reads): loads in
//! N mm and cam speeds in Hz are refused naming the column and the probable unit; repeated
//! rows and time stamps are reported; a file without line ends, a pipe and a huge header are
//! refused after a bounded read without echoing the file back; user effects have stated
//! limits.

use std::io::Write as _;

use explain::synth::{self, SweepPlan};
use explain::{self, Dataset, ExplainError, MeasuredRow, Options, Verdict};
use rigfile::RigFile;

fn sweep(seed: u64) -> Vec<MeasuredRow> {
    let model = RigFile::paper().current_model().unwrap();
    synth::generate(
        &model,
        &SweepPlan {
            noise_a: 0.01,
            ..SweepPlan::default()
        },
        seed,
    )
}

fn explain_rows(rows: Vec<MeasuredRow>) -> Result<explain::Explanation, ExplainError> {
    let data = Dataset::from_rows("units.csv", rows)?;
    let options = Options {
        replicates: 0,
        ..Options::default()
    };
    explain::explain(&data, &RigFile::paper(), &options).map(|o| o.explanation)
}

#[test]
fn loads_in_n_mm_are_refused_naming_the_column_and_the_unit() {
    let rows: Vec<MeasuredRow> = sweep(1)
        .into_iter()
        .map(|r| MeasuredRow {
            tau_rot: r.tau_rot * 1e3,
            ..r
        })
        .collect();
    let err = explain_rows(rows).unwrap_err().to_string();
    assert!(err.contains("tau_rot_nm") && err.contains("N mm"), "{err}");
    assert!(err.contains("divide the column by 1000"), "{err}");
}

#[test]
fn cam_speeds_in_hz_are_refused_naming_the_column_and_the_unit() {
    let rows: Vec<MeasuredRow> = sweep(2)
        .into_iter()
        .map(|r| MeasuredRow {
            omega_n: r.omega_n / std::f64::consts::TAU,
            ..r
        })
        .collect();
    let err = explain_rows(rows).unwrap_err().to_string();
    assert!(err.contains("omega_n_rad_s") && err.contains("Hz"), "{err}");
    assert!(err.contains("2 pi"), "{err}");
}

#[test]
fn data_in_si_units_passes_the_unit_screen() {
    for seed in 3..6 {
        let e = explain_rows(sweep(seed)).unwrap();
        assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
    }
}

#[test]
fn repeated_rows_and_time_stamps_are_reported() {
    let mut rows = sweep(7);
    let copies: Vec<MeasuredRow> = rows[10..14].to_vec();
    rows.extend(copies);
    let e = explain_rows(rows).unwrap();
    assert!(
        e.warnings
            .iter()
            .any(|w| w.starts_with("4 of 154 rows repeat an earlier row")),
        "{:?}",
        e.warnings
    );
    let mut rows = sweep(8);
    rows[20].t_s = rows[19].t_s;
    let e = explain_rows(rows).unwrap();
    assert!(
        e.warnings.iter().any(|w| w.contains("share their t_s")),
        "{:?}",
        e.warnings
    );
}

#[test]
fn a_file_without_line_ends_is_refused_after_a_bounded_read() {
    let dir = tempfile::tempdir().unwrap();
    // 8 MiB of zeros, as /dev/zero or a sparse file gives (the read stops at 64 KiB).
    let zeros = dir.path().join("zeros.csv");
    std::fs::File::create(&zeros)
        .unwrap()
        .set_len(8 << 20)
        .unwrap();
    let err = Dataset::read_csv(&zeros).unwrap_err().to_string();
    assert!(err.contains("longer than 64 KiB"), "{err}");
    assert!(err.len() < 400, "{err}");
    // A 2 MB header of unknown columns: refused without echoing it.
    let wide = dir.path().join("wide.csv");
    let mut f = std::fs::File::create(&wide).unwrap();
    let header: Vec<String> = (0..200_000).map(|k| format!("c{k}")).collect();
    writeln!(f, "{}", header.join(",")).unwrap();
    drop(f);
    let err = Dataset::read_csv(&wide).unwrap_err().to_string();
    assert!(
        err.len() < 400,
        "{} bytes: {}",
        err.len(),
        &err[..400.min(err.len())]
    );
    // A long header within the limit: the list of columns found is cut.
    let long = dir.path().join("long.csv");
    let mut f = std::fs::File::create(&long).unwrap();
    let header: Vec<String> = (0..3_000).map(|k| format!("c{k}")).collect();
    writeln!(f, "{}", header.join(",")).unwrap();
    writeln!(f, "{}", vec!["1"; 3_000].join(",")).unwrap();
    drop(f);
    let err = Dataset::read_csv(&long).unwrap_err().to_string();
    assert!(err.contains("omega_n_rad_s"), "{err}");
    assert!(
        err.contains("more bytes not shown") && err.len() < 800,
        "{err}"
    );
}

#[cfg(unix)]
#[test]
fn a_pipe_or_a_folder_is_refused_without_reading() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.csv");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if made {
        // Opening a FIFO without a writer would block: the refusal comes first.
        let err = Dataset::read_csv(&fifo).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        let err = RigFile::load(&fifo).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
    }
    let err = Dataset::read_csv(dir.path()).unwrap_err().to_string();
    assert!(err.contains("not a regular file"), "{err}");
}

#[test]
fn user_effects_have_stated_limits_on_size_and_count() {
    let long = "w * a".repeat(300);
    let text = format!(
        "[[user_effects]]\nname = \"big\"\nexpression = \"{long}\"\n[user_effects.params.a]\nunit = \"A\"\nbounds = [-1.0, 1.0]\nnull = 0.0\n"
    );
    let err = RigFile::parse(&text, "big.toml").unwrap_err().to_string();
    assert!(err.contains("at most 1024"), "{err}");
    let many: String = (0..20)
        .map(|k| {
            format!(
                "[[user_effects]]\nname = \"u{k}\"\nexpression = \"a * w\"\n[user_effects.params.a]\nunit = \"A\"\nbounds = [-1.0, 1.0]\nnull = 0.0\n"
            )
        })
        .collect();
    let err = RigFile::parse(&many, "many.toml").unwrap_err().to_string();
    assert!(err.contains("at most 16"), "{err}");
}
