//! `torque-sweep` (Figs. 8-9): every run of a [`Plan`] on a [`Bench`]: hang the load, drive
//! the vibrator (open loop at a supply voltage, as the paper's bench supply, or closed
//! loop at a frequency), average the current and the cam speed over the window that
//! starts with constant cam rotation (as the paper: 0.5 s) or over whole revolutions,
//! once the cam has settled ([`SETTLE_TIME_CONSTANTS`]),
//! stop, note whether the output moved, rest. Each row is appended to the CSV (`rig
//! explain`'s columns) as it completes, and synced, so an interruption keeps every
//! completed row and `--resume` continues the plan.

use std::path::Path;

use protocol::{SupervisorState, TelemetrySample};
use rigfile::row::EXPERIMENT_SWEEP;
use serde::Serialize;

use super::bench::{Bench, Go, Operator, Verdict, interrupted};
use super::plan::{Plan, Run};
use crate::RigError;
use crate::provenance::{Header, Provenance};
use crate::row_log::{self, Appender};

/// Telemetry rate during a point, Hz.
pub const TELEMETRY_HZ: u16 = 100;

/// Mechanical time constants of the vibrator ([`model::plant::MotorParams`]) waited after
/// the firmware reports constant rotation (`Vibrating`) before the window opens. The
/// firmware judges it from whole revolutions (within 2 % for 100 ms), while the speed still
/// creeps towards its final value as exp(-t / tau); until it arrives the current carries
/// the accelerating torque J dw/dt, which no steady-state model (Eq. 10 with Eqs. 15-17)
/// contains: on the paper's rig +3 mA at 8.8 V, enough to bias a fitted kappa by +0.025.
/// Four time constants leave 2 % of it.
pub const SETTLE_TIME_CONSTANTS: f64 = 4.0;

/// Device time waited after `Vibrating` before the window opens, s (see
/// [`SETTLE_TIME_CONSTANTS`]; about 0.3 s for the RS-735 and its cam).
pub fn settle_s() -> f64 {
    SETTLE_TIME_CONSTANTS * model::plant::MotorParams::default().mechanical_time_constant_s()
}

/// Longest wait for constant cam rotation, device s.
const SPIN_UP_LIMIT_S: f64 = 8.0;

/// How the averaging window is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Window {
    /// `window_s` from the start of constant cam rotation (the paper: 0.5 s).
    #[default]
    Start,
    /// From the start of constant rotation, at least `window_s`, ended at a whole number
    /// of cam revolutions (the cam's torque ripple averages out).
    Revolutions,
}

/// One row of the sweep's CSV: the rig tools' one measured-row type, with the columns of
/// [`rigfile::row::EXPERIMENT_SWEEP`] (the first ones `rig explain` reads). The procedure
/// fills the point, repeat, window start, drive (`v_in` in open loop, `target_hz` in closed
/// loop), cam speed, load, current, temperature (when sensed), tau_cam estimate,
/// `backdriven` (when someone could tell) and `load_kg`.
pub type Row = rigfile::row::MeasuredRow;

/// What a sweep did.
#[derive(Debug, Clone, Serialize)]
pub struct SweepOutcome {
    /// Runs in the plan.
    pub planned: usize,
    /// Rows already in the file before this run (`--resume`).
    pub resumed: usize,
    /// Rows written by this run.
    pub written: usize,
    /// Runs the operator skipped.
    pub skipped: usize,
    /// The rows this run measured, in order.
    #[serde(skip)]
    pub rows: Vec<Row>,
}

/// The sweep's settings beyond the plan.
#[derive(Debug, Clone)]
pub struct SweepSetup {
    /// The plan.
    pub plan: Plan,
    /// How the averaging window is chosen.
    pub window: Window,
    /// Continue the plan in an existing CSV.
    pub resume: bool,
    /// Replace an existing CSV (the operator said so: `--force`).
    pub force: bool,
    /// The command line, for the provenance.
    pub command: String,
}

/// The provenance header of a sweep on `bench` ([`crate::provenance`]).
pub fn provenance<B: Bench + ?Sized>(
    bench: &mut B,
    setup: &SweepSetup,
) -> Result<String, RigError> {
    let info = bench.info().clone();
    let calibration = bench.calibration()?;
    Ok(Provenance {
        procedure: "rig experiment torque-sweep",
        command: &setup.command,
        date: std::time::SystemTime::now(),
        info: &info,
        calibration: &calibration,
        window: setup.window.describe(),
        plan: &setup.plan,
        // The device's drive, as its `Info` states it (`Capabilities::BRAKING_DECAY`).
        regenerative: info
            .capabilities
            .contains(protocol::Capabilities::BRAKING_DECAY),
    }
    .header())
}

impl Window {
    /// The window in words, as the provenance states it.
    pub fn describe(self) -> &'static str {
        match self {
            Window::Start => "start of constant cam rotation",
            Window::Revolutions => "whole cam revolutions from the start of constant rotation",
        }
    }
}

/// The rows already in `path` and its plan line (for `--resume`).
pub fn read_rows(path: &Path) -> Result<(Vec<Row>, Option<String>), RigError> {
    let text =
        rigfile::text_input::read_text(path, rigfile::text_input::MAX_TABLE_BYTES, "a sweep CSV")
            .map_err(|why| RigError::MeasuredFile {
            file: path.display().to_string(),
            why,
        })?;
    let plan = Header::parse(&text).plan_line;
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .from_reader(text.as_bytes());
    let mut rows = Vec::new();
    for r in reader.deserialize::<Row>() {
        // A row cut short by a crash mid-write is not a completed row.
        match r {
            Ok(row) if EXPERIMENT_SWEEP.is_complete(&row) => rows.push(row),
            _ => break,
        }
    }
    Ok((rows, plan))
}

/// `row` as a person writes it: the means of `f32` telemetry to the 7 significant digits
/// they carry (3.16632, not 3.166320013999939), `f32` readings as written.
pub fn for_people(row: &Row) -> Row {
    let mean = |v: f64| reporting::significant(v, 7);
    Row {
        v_in: row.v_in.map(reporting::human_f64),
        target_hz: row.target_hz.map(reporting::human_f64),
        omega_n: mean(row.omega_n),
        tau_rot: reporting::human_f64(row.tau_rot),
        i_in: row.i_in.map(mean),
        temp_c: row.temp_c.map(reporting::human_f64),
        tau_cam_est: row.tau_cam_est.map(mean),
        load_kg: row.load_kg.map(|m| reporting::significant(m, 6)),
        ..*row
    }
}

fn csv_line(row: &Row) -> Result<String, RigError> {
    csv_text([row], false)
}

/// `rows` as CSV text ([`EXPERIMENT_SWEEP`]), numbers as people write them
/// ([`for_people`]), under the column names when `header` (and there is a row).
pub fn csv_text<'a>(
    rows: impl IntoIterator<Item = &'a Row>,
    header: bool,
) -> Result<String, RigError> {
    let mut bytes = Vec::new();
    EXPERIMENT_SWEEP
        .write_csv(&mut bytes, header, rows.into_iter().map(for_people))
        .map_err(|e| RigError::BadValue {
            what: "a sweep row".into(),
            why: e.to_string(),
        })?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// Refuses to start a sweep over an existing data file: without `resume` (continue it) or
/// `force` (replace it) an existing `path` is an error naming the file, its rows and the
/// options, before anything moves; nothing in it is touched.
pub fn check_output(path: &Path, resume: bool, force: bool) -> Result<(), RigError> {
    if resume || force {
        return Ok(());
    }
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(RigError::File {
            action: "check",
            path: path.display().to_string(),
            source,
        }),
        Ok(meta) if meta.is_dir() => Err(RigError::BadValue {
            what: format!("--csv {}", path.display()),
            why: "is a folder: give a file name".into(),
        }),
        Ok(_) => {
            let rows = read_rows(path).map(|r| r.0.len()).unwrap_or(0);
            Err(RigError::BadValue {
                what: format!("--csv {}", path.display()),
                why: format!(
                    "already exists ({rows} completed rows): it was left unchanged; pass --resume to continue it with the same plan, --force to replace it, or give a new file name"
                ),
            })
        }
    }
}

/// As [`check_output`] for a verb that writes its data file whole at the end (nothing to
/// resume): an existing `path` only with `force`.
pub fn check_new_output(path: &Path, force: bool) -> Result<(), RigError> {
    if force || !path.exists() {
        return Ok(());
    }
    Err(RigError::BadValue {
        what: format!("--csv {}", path.display()),
        why: "already exists: it was left unchanged; pass --force to replace it, or give a new file name".into(),
    })
}

/// Opens a new data file for writing: `force` replaces an existing one, else an existing
/// file is refused (created exclusively, so a file that appeared since
/// [`check_output`] is not truncated either).
pub fn create_new(path: &Path, force: bool) -> Result<std::fs::File, RigError> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true);
    if force {
        options.create(true).truncate(true);
    } else {
        options.create_new(true);
    }
    options.open(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::AlreadyExists {
            RigError::BadValue {
                what: format!("--csv {}", path.display()),
                why: "already exists: it was left unchanged; pass --resume to continue it, --force to replace it, or give a new file name".into(),
            }
        } else {
            RigError::File {
                action: "write",
                path: path.display().to_string(),
                source,
            }
        }
    })
}

/// Where `--force` writes a sweep while the file it replaces stays whole: `FILE.new`,
/// renamed over `FILE` once every planned run is done.
pub fn forced_path(csv: &Path) -> std::path::PathBuf {
    let mut name = csv.as_os_str().to_owned();
    name.push(".new");
    name.into()
}

/// Runs the sweep on `bench`, writing rows to `csv`; `progress` gets a line per point.
pub fn run<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &mut Operator,
    setup: &SweepSetup,
    csv: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<SweepOutcome, RigError> {
    run_to(bench, operator, setup, Some(csv), progress)
}

/// As [`run`], writing the CSV only when `csv` is given (the rows are in the outcome).
pub fn run_to<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &mut Operator,
    setup: &SweepSetup,
    csv: Option<&Path>,
    progress: &mut dyn FnMut(&str),
) -> Result<SweepOutcome, RigError> {
    let runs = setup.plan.runs();
    // Every point against the rig's limits before the first one runs: an impossible point
    // is found now, not hours into the sweep.
    let calibration = bench.calibration()?;
    check_plan(&setup.plan, &calibration)?;
    let top = runs.iter().map(|r| r.load_nm).fold(0.0, f64::max);
    super::bench::allow_load(bench, top)?;
    let (done, mut out, replaces) = match csv {
        Some(csv) => {
            let (done, out, replaces) = open_csv(bench, setup, csv, progress)?;
            (done, Some(out), replaces)
        }
        None => (Vec::new(), None, None),
    };
    let resumed = done.len();
    let mut outcome = SweepOutcome {
        planned: runs.len(),
        resumed,
        written: 0,
        skipped: 0,
        rows: Vec::new(),
    };
    // The release limit sits above the heaviest load on a virtual rig (its calibration is
    // the paper's 1.0 N m); a real rig's is the operator's business (`rig calibration`).
    bench.start_telemetry(TELEMETRY_HZ)?;
    let mut hung: Option<f64> = None;
    let todo: Vec<&Run> = runs
        .iter()
        .filter(|r| !done.iter().any(|d| d.point == Some(r.index)))
        .collect();
    let eta = crate::progress::Progress::start(runs.len(), resumed);
    let result = (|| {
        for run in todo {
            if operator.interrupted() {
                return Err(interrupted());
            }
            loop {
                // A virtual rig's load is hung again, still, before every run (its
                // output may still be turning from the last run: the paper's rig keeps
                // falling after the vibration stops when mu_d Lambda < 1), as the
                // operator re-hangs a fallen load; a real rig's operator is asked only
                // when the load changes.
                let asks = operator.forced || !bench.is_virtual();
                if asks && hung != Some(run.load_nm) {
                    // The operator hangs the load with the drive off, the gear locked and
                    // the telemetry stopped: however long it takes, nothing times out.
                    let q = format!(
                        "point {}/{}: hang {}",
                        run.index + 1,
                        runs.len(),
                        super::load_text(run.load_nm)
                    );
                    if quiet_prompt(bench, || operator.before(&q))? == Go::Skip {
                        outcome.skipped += 1;
                        break;
                    }
                }
                // A virtual rig's load is hung again, still, before every run (its output
                // may still be turning from the last run: the paper's rig keeps falling
                // after the vibration stops when mu_d Lambda < 1), as the operator re-hangs
                // a fallen load; with `--operator` it is what the operator just confirmed.
                if bench.is_virtual() {
                    bench.set_load(run.load_nm)?;
                }
                hung = Some(run.load_nm);
                wait_for_temperature(bench, operator, run)?;
                let mut row = match measure(bench, operator, setup, run) {
                    Ok(row) => row,
                    Err(e) => match beyond_the_rig(&e) {
                        // The point cannot be measured on this rig (see `beyond_the_rig`).
                        // The drive is already stopped: a virtual rig's operator lets the
                        // output come to rest with the gear locked, clears a latched
                        // protection and goes on; a real rig stops here for the operator.
                        Some((note, latched)) if bench.is_virtual() => {
                            progress(&note);
                            bench.wait(2.0)?;
                            if latched {
                                bench.request(&protocol::Request::ClearFaults)?;
                            }
                            hung = None;
                            outcome.skipped += 1;
                            break;
                        }
                        _ => return Err(e),
                    },
                };
                let summary = format!(
                    "point {}/{}: {}, {}: i = {:.3} A, w = {:.1} rad/s",
                    run.index + 1,
                    runs.len(),
                    super::load_text(run.load_nm),
                    drive_text(run),
                    row.i_in.unwrap_or(f64::NAN),
                    row.omega_n
                );
                if asks {
                    let ask_moved = row.backdriven.is_none();
                    match quiet_prompt(bench, || operator.after(&summary, ask_moved))? {
                        Verdict::Redo => continue,
                        Verdict::Keep(moved) => {
                            if let Some(m) = moved {
                                row.backdriven = Some(m);
                            }
                        }
                    }
                } else {
                    // Points done (this one included), time elapsed, and the end's estimate.
                    let done = resumed + outcome.written + outcome.skipped + 1;
                    progress(&format!("{summary}; {}", eta.line(done)));
                }
                if let Some(out) = out.as_mut() {
                    out.write(&csv_line(&row)?)?;
                }
                outcome.rows.push(row);
                outcome.written += 1;
                bench.wait(setup.plan.rest_s)?;
                break;
            }
        }
        Ok(())
    })();
    bench.lock_gear();
    let _ = bench.stop_telemetry();
    result?;
    // `--force`: the new sweep is complete, so it replaces the old file (in one rename).
    if let (Some((new, old)), Some(out)) = (replaces, out) {
        drop(out);
        std::fs::rename(&new, &old).map_err(|source| RigError::File {
            action: "replace",
            path: old.display().to_string(),
            source,
        })?;
    }
    Ok(outcome)
}

/// Runs an operator prompt with the telemetry stopped (the drive is already off and the
/// gear locked), then restarts it: a person may take minutes, and no stale samples pile up
/// for the next point to read.
fn quiet_prompt<B: Bench + ?Sized, R>(
    bench: &mut B,
    ask: impl FnOnce() -> Result<R, RigError>,
) -> Result<R, RigError> {
    bench.lock_gear();
    bench.stop_telemetry()?;
    let answer = ask();
    bench.start_telemetry(TELEMETRY_HZ)?;
    answer
}

/// Checks every point of `plan` against the limits a rig takes (the board's and the
/// calibration's): the load at most the gear's tooth-strength cap, a supply voltage the
/// bridge can give, a release frequency the controller accepts. All the points that do not
/// fit are named in one error, before anything moves.
pub fn check_plan(plan: &Plan, calibration: &protocol::RigParameters) -> Result<(), RigError> {
    let core = firmware_core::CoreConfig::default();
    let max_volts = f64::from(core.supply_v * core.motor.max_duty);
    let (lo_hz, hi_hz) = crate::limits::release_freq_range(calibration);
    let max_load = model::BoardLimits::PAPER.max_release_load_nm;
    let mut bad = Vec::new();
    for (k, p) in plan.points.iter().enumerate() {
        let mut why = Vec::new();
        if !(0.0..=max_load).contains(&p.load_nm) {
            why.push(format!(
                "load_nm {} is outside 0 to {} N m (the gear's tooth strength)",
                reporting::human(p.load_nm),
                reporting::human(max_load)
            ));
        }
        if let Some(v) = p.volts
            && !(v > 0.0 && v <= max_volts)
        {
            why.push(format!(
                "volts {} is outside 0 to {} V (the bridge's supply at its highest duty)",
                reporting::human(v),
                reporting::human(reporting::significant(max_volts, 4))
            ));
        }
        if let Some(hz) = p.hz
            && !(hz >= f64::from(lo_hz) && hz <= f64::from(hi_hz))
        {
            why.push(format!(
                "hz {} is outside {} to {} Hz (the controller and the calibration's max_freq_hz)",
                reporting::human(hz),
                reporting::human(f64::from(lo_hz)),
                reporting::human(f64::from(hi_hz))
            ));
        }
        if !why.is_empty() {
            bad.push(format!("point {}: {}", k + 1, why.join(", ")));
        }
    }
    if bad.is_empty() {
        Ok(())
    } else {
        Err(RigError::BadValue {
            what: format!("plan '{}'", plan.name),
            why: format!(
                "{} of its {} points cannot run on this rig, nothing was measured: {}; fix them in the plan file",
                bad.len(),
                plan.points.len(),
                bad.join("; ")
            ),
        })
    }
}

fn drive_text(run: &Run) -> String {
    match (run.volts, run.hz) {
        (Some(v), _) => format!("{} V", reporting::human(v)),
        (_, Some(hz)) => format!("{} Hz", reporting::human(hz)),
        _ => String::new(),
    }
}

/// The sweep's CSV, opened to append: the rows already done (`--resume`), the writer, and
/// with `--force` over an existing file, (the file written, the file it replaces once
/// complete).
#[allow(clippy::type_complexity, reason = "a private helper's three results")]
fn open_csv<B: Bench + ?Sized>(
    bench: &mut B,
    setup: &SweepSetup,
    csv: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<
    (
        Vec<Row>,
        Appender,
        Option<(std::path::PathBuf, std::path::PathBuf)>,
    ),
    RigError,
> {
    let path = csv.display().to_string();
    if setup.resume && csv.exists() {
        let (rows, plan) = read_rows(csv)?;
        if plan.as_deref() != Some(setup.plan.one_line().as_str()) {
            return Err(RigError::BadValue {
                what: format!("--resume {path}"),
                why: "the file was written with another plan (its `# plan:` line differs): give the same --plan/--quick as the interrupted run, or a new --csv".into(),
            });
        }
        // A row cut short (a crash or a full disk mid-write) is dropped, and said so, so
        // appended rows start on their own line and the file stays readable.
        let file = row_log::open_to_continue(csv, progress)?;
        let out = Appender::new(file, path, row_log::Sync::EveryRow)?;
        return Ok((rows, out, None));
    }
    check_output(csv, false, setup.force)?;
    let head = provenance(bench, setup)? + &EXPERIMENT_SWEEP.header();
    // `--force` over an existing file: the old one stays whole until the new one is done.
    let replaces = (setup.force && csv.exists()).then(|| (forced_path(csv), csv.to_path_buf()));
    let target = replaces.as_ref().map_or(csv, |(new, _)| new.as_path());
    let mut out = Appender::new(
        create_new(target, setup.force)?,
        target.display().to_string(),
        row_log::Sync::EveryRow,
    )?;
    out.write(&head)?;
    Ok((Vec::new(), out, replaces))
}

fn wait_for_temperature<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &Operator,
    run: &Run,
) -> Result<(), RigError> {
    let Some(want) = run.temp_c else {
        return Ok(());
    };
    // Cooling only happens at rest: wait (bounded) while the motor is warmer than asked.
    let mut waited = 0.0;
    while bench.motor_temp_c().is_some_and(|t| t > want) && waited < 600.0 {
        if operator.interrupted() {
            return Err(interrupted());
        }
        bench.wait(1.0)?;
        waited += 1.0;
    }
    Ok(())
}

/// Whether `e` says a point is beyond what the rig can measure: the cam never reached
/// constant rotation, or only the protections a heavy point trips latched
/// ([`load_protection_only`]). Then the note to print, and whether a fault is latched.
fn beyond_the_rig(e: &RigError) -> Option<(String, bool)> {
    match e {
        RigError::Unmeasurable { what, why } => {
            Some((format!("{what}: {why}; point skipped"), false))
        }
        RigError::DeviceFault { what, faults } if load_protection_only(*faults) => Some((
            format!("{what}: the device latched {faults}; point skipped, fault cleared"),
            true,
        )),
        _ => None,
    }
}

/// Whether `faults` are only the protections a heavy
/// point trips (`LOAD_LIMIT`, `OVERLOAD`: the load judged too heavy for a release;
/// `OVERCURRENT`: the drive's current trip): the point is beyond what this rig can
/// measure, nothing else is wrong.
fn load_protection_only(faults: protocol::FaultFlags) -> bool {
    use protocol::FaultFlags as F;
    !faults.is_empty() && (F::LOAD_LIMIT | F::OVERLOAD | F::OVERCURRENT).contains(faults)
}

fn fault_error(t: &TelemetrySample, run: &Run) -> RigError {
    RigError::DeviceFault {
        what: format!(
            "the sweep at {} N m, {}",
            reporting::human(run.load_nm),
            drive_text(run)
        ),
        faults: t.faults,
    }
}

/// One run: drive, wait for constant rotation, average, stop.
fn measure<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &Operator,
    setup: &SweepSetup,
    run: &Run,
) -> Result<Row, RigError> {
    let before = output_angle(bench, None);
    match (run.volts, run.hz) {
        (Some(v), _) => bench.open_loop(v)?,
        (_, Some(hz)) => bench.release(true, hz)?,
        _ => unreachable_drive()?,
    }
    let result = (|| {
        // The start of constant cam rotation, as the firmware judges it: `Vibrating`.
        let mut waited = 0.0;
        let mut last = None;
        loop {
            let t = next_sample(bench, operator, run)?;
            if let Some(prev) = last {
                waited += (t.device_time_us.saturating_sub(prev)) as f64 / 1e6;
            }
            last = Some(t.device_time_us);
            if t.state == SupervisorState::Vibrating {
                break average(bench, operator, setup, run, t);
            }
            if waited > SPIN_UP_LIMIT_S {
                return Err(RigError::Unmeasurable {
                    what: format!(
                        "the sweep at {} N m, {}",
                        reporting::human(run.load_nm),
                        drive_text(run)
                    ),
                    why: format!(
                        "the cam did not reach constant rotation within {SPIN_UP_LIMIT_S} s (state {}, cam {:.1} rad/s): the load may be too heavy for this drive",
                        t.state.name(),
                        t.cam_speed_rad_s
                    ),
                });
            }
        }
    })();
    // "During the run": from the drive's start to the end of the window, when the drive
    // stops (before the spin-down), on the encoder's reading or, without one, as seen.
    let after = match &result {
        Ok((_, last)) => output_angle(bench, last.as_ref()),
        Err(_) => None,
    };
    let stop = match (run.volts, run.hz) {
        (Some(_), _) => bench.open_loop(0.0),
        _ => bench.release(false, 0.0),
    };
    let (mut row, _) = result?;
    stop?;
    // The cam comes to rest before the output is judged and the next point starts.
    let mut waited = 0.0;
    while waited < 3.0 {
        match bench.sample()? {
            Some(t) if t.state == SupervisorState::Locked && t.cam_speed_rad_s.abs() < 0.5 => {
                break;
            }
            Some(_) => waited += 1.0 / f64::from(TELEMETRY_HZ),
            None => break,
        }
    }
    row.backdriven = super::bench::moved(before, after);
    Ok(row)
}

fn unreachable_drive() -> Result<(), RigError> {
    Err(RigError::BadValue {
        what: "plan point".into(),
        why: "gives neither volts nor hz".into(),
    })
}

/// The output angle from the output encoder (telemetry) or, on a virtual rig, as seen.
fn output_angle<B: Bench + ?Sized>(bench: &mut B, t: Option<&TelemetrySample>) -> Option<f64> {
    let from_encoder = match t {
        Some(t) => Some(t.output_angle_rad),
        None => bench.sample().ok().flatten().map(|t| t.output_angle_rad),
    }
    .map(f64::from)
    .filter(|a| a.is_finite());
    from_encoder.or_else(|| bench.peek_output())
}

/// The next telemetry sample of a run: an error when the operator interrupted, the
/// telemetry stopped, or the device reports a fault.
fn next_sample<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &Operator,
    run: &Run,
) -> Result<TelemetrySample, RigError> {
    if operator.interrupted() {
        return Err(interrupted());
    }
    let Some(t) = bench.sample()? else {
        return Err(RigError::Protocol(
            "telemetry stopped during the sweep: check the link".into(),
        ));
    };
    if !t.faults.is_empty() || t.state == SupervisorState::Fault {
        return Err(fault_error(&t, run));
    }
    Ok(t)
}

/// Averages over the window; returns the row (without `backdriven`) and the last sample.
fn average<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &Operator,
    setup: &SweepSetup,
    run: &Run,
    first: TelemetrySample,
) -> Result<(Row, Option<TelemetrySample>), RigError> {
    // The cam settles first (see `SETTLE_TIME_CONSTANTS`).
    let mut first = first;
    let settled_at = first.device_time_us + (settle_s() * 1e6).round() as u64;
    while first.device_time_us < settled_at {
        first = next_sample(bench, operator, run)?;
    }
    let t0 = first.device_time_us;
    let temp_c = bench.motor_temp_c();
    let (mut sum_i, mut sum_w, mut n) = (0.0, 0.0, 0u32);
    // The firmware's estimate changes once per cam revolution: average the fresh ones.
    let mut estimates: Vec<f64> = Vec::new();
    let mut angle = 0.0;
    let mut prev = first;
    let mut prev_tau = first.tau_cam_nm;
    let mut last;
    let window = setup.plan.window_s;
    loop {
        let t = next_sample(bench, operator, run)?;
        let dt = t.device_time_us.saturating_sub(prev.device_time_us) as f64 / 1e6;
        angle += 0.5 * f64::from(t.cam_speed_rad_s + prev.cam_speed_rad_s).abs() * dt;
        prev = t;
        last = t;
        sum_i += f64::from(t.current_a);
        sum_w += f64::from(t.cam_speed_rad_s).abs();
        if t.tau_cam_nm.is_finite() && t.tau_cam_nm != prev_tau {
            estimates.push(f64::from(t.tau_cam_nm));
        }
        prev_tau = t.tau_cam_nm;
        n += 1;
        let elapsed = t.device_time_us.saturating_sub(t0) as f64 / 1e6;
        let long_enough = elapsed >= window - 0.5 / f64::from(TELEMETRY_HZ);
        let whole = match setup.window {
            Window::Start => true,
            Window::Revolutions => {
                let rev = std::f64::consts::TAU;
                // Within one sample of a whole revolution.
                let step = f64::from(t.cam_speed_rad_s.abs()) / f64::from(TELEMETRY_HZ);
                angle >= rev && (angle % rev) < step.max(1e-6)
            }
        };
        if long_enough && whole {
            break;
        }
        if elapsed > window + 10.0 {
            break;
        }
    }
    if let Some(d) = run.duration_s {
        let elapsed = last.device_time_us.saturating_sub(t0) as f64 / 1e6;
        if d > elapsed {
            bench.wait(d - elapsed)?;
        }
    }
    let n = f64::from(n.max(1));
    Ok((
        Row {
            point: Some(run.index),
            repeat: Some(run.repeat),
            t_s: Some(t0 as f64 / 1e6),
            v_in: run.volts,
            target_hz: run.hz,
            omega_n: sum_w / n,
            tau_rot: run.load_nm,
            i_in: Some(sum_i / n),
            temp_c,
            tau_cam_est: Some(if estimates.is_empty() {
                f64::from(last.tau_cam_nm)
            } else {
                estimates.iter().sum::<f64>() / estimates.len() as f64
            }),
            backdriven: None,
            load_kg: Some(super::load_mass_kg(run.load_nm)),
            tau_cam_meas: None,
            tau_cam_eq10: None,
        },
        Some(last),
    ))
}

#[cfg(test)]
mod tests {

    #[test]
    fn only_the_load_protections_skip_a_point() {
        use protocol::FaultFlags;
        let name = |f: FaultFlags| f;
        assert!(load_protection_only(name(FaultFlags::LOAD_LIMIT)));
        assert!(load_protection_only(name(
            FaultFlags::LOAD_LIMIT | FaultFlags::OVERLOAD
        )));
        assert!(load_protection_only(name(
            FaultFlags::OVERLOAD | FaultFlags::OVERCURRENT
        )));
        assert!(!load_protection_only(name(
            FaultFlags::OVERCURRENT | FaultFlags::ENCODER_LOSS
        )));
        assert!(!load_protection_only(name(FaultFlags::JAM)));
        assert!(!load_protection_only(FaultFlags::empty()));
    }

    use super::*;
    use crate::experiment::bench::InProcessBench;

    #[test]
    fn a_plan_is_checked_whole_before_the_first_point() {
        let plan = Plan::parse(
            "rest_s = 0.2\n[[points]]\nload_nm = 1.0\nvolts = 6.2\n[[points]]\nload_nm = 5.0\nvolts = 6.2\n[[points]]\nload_nm = 1.0\nvolts = 20.0\n",
            "p.toml",
        )
        .unwrap();
        let cal = protocol::RigParameters::paper();
        let e = check_plan(&plan, &cal).unwrap_err().to_string();
        assert!(e.contains("2 of its 3 points"), "{e}");
        assert!(
            e.contains("point 2: load_nm 5") && e.contains("3.68"),
            "{e}"
        );
        assert!(e.contains("point 3: volts 20"), "{e}");
        assert!(check_plan(&Plan::paper(), &cal).is_ok());
        let hz = Plan::parse(
            "mode = \"closed-loop\"\n[[points]]\nload_nm = 1.0\nhz = 20.0\n",
            "h.toml",
        )
        .unwrap();
        let e = check_plan(&hz, &cal).unwrap_err().to_string();
        assert!(e.contains("hz 20") && e.contains("15 Hz"), "{e}");
        // Nothing ran: the sweep refuses before its first point and writes no file.
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("x.csv");
        let mut bench = InProcessBench::new(sim::SimConfig::paper()).unwrap();
        let mut op = Operator::scripted(b"", false);
        let setup = SweepSetup {
            plan,
            window: Window::Start,
            resume: false,
            force: false,
            command: "test".into(),
        };
        assert!(run(&mut bench, &mut op, &setup, &csv, &mut |_| {}).is_err());
        assert!(!csv.exists());
    }

    #[test]
    fn quick_sweep_on_the_virtual_rig_is_read_by_explain() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("sweep.csv");
        let mut bench = InProcessBench::new(sim::SimConfig::paper()).unwrap();
        let mut op = Operator::scripted(b"", false);
        let setup = SweepSetup {
            plan: Plan::quick(),
            window: Window::Start,
            resume: false,
            force: false,
            command: "test".into(),
        };
        let out = run(&mut bench, &mut op, &setup, &csv, &mut |_| {}).unwrap();
        assert_eq!((out.planned, out.written), (30, 30));
        let data = explain::Dataset::read_csv(&csv).unwrap();
        assert_eq!(data.len(), 30);
        let (rows, plan) = read_rows(&csv).unwrap();
        assert_eq!(plan.unwrap(), setup.plan.one_line());
        // The mean current over the repeats grows with load at every voltage; cam speed
        // with the voltage.
        for v in model::paper::SUPPLY_VOLTAGES {
            let mut means: Vec<(f64, f64)> = Vec::new();
            for load in setup.plan.points.iter().map(|p| p.load_nm) {
                if means.iter().any(|m| m.0 == load) {
                    continue;
                }
                let at: Vec<f64> = rows
                    .iter()
                    .filter(|r| r.v_in == Some(v) && r.tau_rot == load)
                    .filter_map(|r| r.i_in)
                    .collect();
                assert_eq!(at.len(), 2, "two repeats at {load} N m, {v} V");
                means.push((load, at.iter().sum::<f64>() / 2.0));
            }
            means.sort_by(|a, b| a.0.total_cmp(&b.0));
            assert!(
                means.windows(2).all(|w| w[1].1 > w[0].1),
                "{v} V: {means:?}"
            );
        }
        let speed = |v: f64| {
            rows.iter()
                .filter(|r| r.v_in == Some(v))
                .map(|r| r.omega_n)
                .sum::<f64>()
        };
        assert!(speed(3.6) < speed(6.2) && speed(6.2) < speed(8.8));
        assert!(rows.iter().all(|r| r.backdriven.is_some()));
    }

    #[test]
    fn closed_loop_plan_over_whole_revolutions() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("cl.csv");
        let plan = Plan::parse(
            "mode = \"closed-loop\"\nrest_s = 0.2\n[[points]]\nload_nm = 1.0\nhz = 5.0\n[[points]]\nload_nm = 1.0\nhz = 10.0\n",
            "cl.toml",
        )
        .unwrap();
        let mut bench = InProcessBench::new(sim::SimConfig::paper()).unwrap();
        let mut op = Operator::scripted(b"", false);
        let setup = SweepSetup {
            plan,
            window: Window::Revolutions,
            resume: false,
            force: false,
            command: "test".into(),
        };
        run(&mut bench, &mut op, &setup, &csv, &mut |_| {}).unwrap();
        let (rows, _) = read_rows(&csv).unwrap();
        assert_eq!(rows.len(), 2);
        for r in &rows {
            let hz = r.target_hz.unwrap();
            assert!(r.v_in.is_none());
            let measured = r.omega_n / std::f64::consts::TAU;
            assert!((measured - hz).abs() < 0.1 * hz, "{measured} Hz at {hz} Hz");
            assert_eq!(r.backdriven, Some(true), "1 N m falls once released");
        }
    }
}
