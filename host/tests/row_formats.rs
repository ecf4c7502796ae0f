//! The three CSVs of measured test points, byte for byte: `rig sim torque-sweep --csv`
//! (the simulator's columns), `rig experiment torque-sweep --csv` (the procedure's, with
//! provenance) and `rig explain --save-data` (explain's standard columns). The files under
//! `fixtures/rows/` were written by the tools before the three row types became one
//! (`rigfile::row`); a new file must match them exactly, and an old file must still read.

use std::path::Path;

use host::experiment::sweep::{self, SweepSetup, Window};
use host::experiment::{InProcessBench, Operator, Plan, paper};
use sim::scenarios::sweep::SweepOptions;

fn fixture(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/rows")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `got` against the fixture `name`; with `UPDATE_ROWS=1` the fixture is rewritten instead
/// (when the virtual rig's physics changes the values, as issue 30's braking drive did;
/// the columns and number formats must not change: review the diff).
fn check_fixture(got: &str, name: &str) {
    if std::env::var_os("UPDATE_ROWS").is_some() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/rows")
            .join(name);
        std::fs::write(&path, got).unwrap();
        return;
    }
    assert_eq!(got, fixture(name));
}

/// The lines of `text` that are not provenance (`#`): the date and command differ per run.
fn body(text: &str) -> String {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Ten points on the virtual rig (5 loads x 2 voltages), as `rig sim torque-sweep` runs them.
fn sim_points() -> Vec<sim::scenarios::sweep::SweepPoint> {
    let opts = SweepOptions {
        loads: vec![0.368, 1.104, 1.84, 2.576, 3.312],
        voltages: vec![3.6, 8.8],
        repeats: 1,
        rest_s: 0.5,
        seed: 3,
        ..SweepOptions::default()
    };
    paper::torque_sweep(&opts).unwrap()
}

#[test]
fn the_simulators_sweep_csv_is_unchanged() {
    let mut out = Vec::new();
    sim::scenarios::sweep::write_csv(&sim_points(), &mut out).unwrap();
    check_fixture(&String::from_utf8(out).unwrap(), "sim_sweep.csv");
    // No points: no header either (as before).
    let mut out = Vec::new();
    sim::scenarios::sweep::write_csv(&[], &mut out).unwrap();
    assert!(out.is_empty());
}

fn experiment_csv(plan: &str, window: Window, dir: &Path, name: &str) -> String {
    let plan = Plan::parse(plan, "p.toml").unwrap();
    let mut bench = InProcessBench::new(sim::SimConfig::paper()).unwrap();
    let mut op = Operator::scripted(b"", false);
    let setup = SweepSetup {
        plan,
        window,
        resume: false,
        force: false,
        command: "test".into(),
    };
    let csv = dir.join(name);
    sweep::run(&mut bench, &mut op, &setup, &csv, &mut |_| {}).unwrap();
    std::fs::read_to_string(&csv).unwrap()
}

#[test]
fn the_procedures_sweep_csv_is_unchanged_open_and_closed_loop() {
    let dir = tempfile::tempdir().unwrap();
    let open = experiment_csv(
        "rest_s = 0.5\nrepeats = 2\n[[points]]\nload_nm = 0.5\nvolts = 3.6\n[[points]]\nload_nm = 2.0\nvolts = 8.8\n",
        Window::Start,
        dir.path(),
        "open.csv",
    );
    assert!(open.starts_with("# "), "provenance first: {open}");
    check_fixture(&body(&open), "experiment_open.csv");
    let closed = experiment_csv(
        "mode = \"closed-loop\"\nrest_s = 0.5\n[[points]]\nload_nm = 1.0\nhz = 5.0\n[[points]]\nload_nm = 1.0\nhz = 10.0\n",
        Window::Revolutions,
        dir.path(),
        "closed.csv",
    );
    check_fixture(&body(&closed), "experiment_closed.csv");
    // The rows read back and written again (as `rig discover` appends a round) give the
    // same bytes.
    for (text, name) in [(&open, "open.csv"), (&closed, "closed.csv")] {
        let (rows, plan) = sweep::read_rows(&dir.path().join(name)).unwrap();
        assert!(plan.is_some());
        assert_eq!(sweep::csv_text(&rows, true).unwrap(), body(text));
    }
}

#[test]
fn explains_saved_data_is_unchanged() {
    let mut out = Vec::new();
    sim::scenarios::sweep::write_csv(&sim_points(), &mut out).unwrap();
    let data = explain::Dataset::parse_csv(out.as_slice(), "sweep.csv").unwrap();
    let mut saved = Vec::new();
    data.write_csv(&mut saved).unwrap();
    check_fixture(&String::from_utf8(saved).unwrap(), "explain_saved.csv");
}

#[test]
fn files_written_before_the_load_kg_column_and_cut_rows_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old.csv");
    std::fs::write(
        &old,
        "# plan: x\npoint,repeat,t_s,v_in_v,target_hz,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c,tau_cam_est_nm,backdriven\n\
         0,0,12.5,3.6,,31.4,0.368,2.5,,0.12,0\n\
         1,0,20.25,,5,31.5,1.5,2.75,25.5,0.2,\n\
         2,1,30,8.8,,90.1,3.68,3.",
    )
    .unwrap();
    let (rows, plan) = sweep::read_rows(&old).unwrap();
    assert_eq!(plan.as_deref(), Some("x"));
    // The third row was cut mid-write: not a completed row.
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].point, Some(0));
    assert_eq!(rows[0].v_in, Some(3.6));
    assert_eq!(rows[0].target_hz, None);
    assert_eq!(rows[0].temp_c, None);
    assert_eq!(rows[0].backdriven, Some(false));
    assert_eq!(rows[0].load_kg, None);
    assert_eq!(rows[1].v_in, None);
    assert_eq!(rows[1].target_hz, Some(5.0));
    assert_eq!(rows[1].temp_c, Some(25.5));
    assert_eq!(rows[1].backdriven, None);
    assert_eq!(
        sweep::csv_text(&rows, true).unwrap(),
        "point,repeat,t_s,v_in_v,target_hz,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c,tau_cam_est_nm,backdriven,load_kg\n\
         0,0,12.5,3.6,,31.4,0.368,2.5,,0.12,0,\n\
         1,0,20.25,,5.0,31.5,1.5,2.75,25.5,0.2,,\n"
    );
}
