//! `rig calibrate`: the paper's vibrator calibration on the device (see
//! [`crate::calibrate`]): measure, fit, report, plot, write the rig file
//! (`docs/rig-file.md`: the device's record with the measured C1-C6 and the fit
//! statistics), and write the constants to the device after confirmation. Every file is
//! written atomically.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::SystemTime;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use super::connect::{Connection, DeviceOpts, confirm};
use crate::RigError;
use crate::calibrate::operator::{TerminalOperator, VirtualOperator};
use crate::calibrate::plot::{self, FitPlot};
use crate::calibrate::{
    self, CalibrationResult, CalibrationSchedule, GaugeOperator, GaugeUnit, Measurements, Progress,
    Setup,
};
use rigfile::{RigFile, paper_units};

/// Arguments of `rig calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Folder for calibration.toml (the rig file, docs/rig-file.md), the two fit plots (SVG) and the measured points (CSV) [default: report/calibrate-YYYYMMDDTHHMMSSZ, the start time in UTC].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Gauge torques (N mm) from this CSV (a `gauge_nmm` column, one row per torque step)
    /// instead of typing them.
    #[arg(long, value_name = "FILE")]
    gauge_csv: Option<PathBuf>,
    /// Write the result to the device without asking.
    #[arg(long, short = 'y')]
    yes: bool,
    /// Measure, fit and report only: no files, nothing written to the device.
    #[arg(long)]
    dry_run: bool,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Fit the points of an earlier run (its points.csv, kept also when Ctrl-C ended it)
    /// instead of measuring.
    #[arg(long, value_name = "FILE", conflicts_with = "gauge_csv")]
    from_points: Option<PathBuf>,
    /// What the gauge reads: `torque` (N mm) or `force` (N, on an arm: --arm-m, or typed
    /// with each reading as `F N @ L m`).
    #[arg(long, value_enum, default_value_t = GaugeKind::Torque)]
    gauge: GaugeKind,
    /// The arm from the shaft's axis to a force gauge, m (with --gauge force).
    #[arg(long, value_name = "M", value_parser = crate::args::positive)]
    arm_m: Option<f64>,
    /// Prompt as on a real rig even on the virtual one (set up, read the gauge): to
    /// rehearse, and for tests.
    #[arg(long)]
    operator: bool,
    /// Write a fit that is implausible for the vibrator's motor (the firmware's rule,
    /// model::Calibration::check) anyway: to the rig file only, the firmware refuses it.
    /// Also replaces an earlier run's points.csv in --out.
    #[arg(long)]
    force: bool,
    /// Continue the interrupted run in --out DIR: the steps in its points.csv are kept,
    /// the others measured (the set-up prompts start at the first missing step).
    #[arg(long, requires = "out", conflicts_with_all = ["from_points", "dry_run"])]
    resume: bool,
    /// The two fit plots' format and printed size.
    #[command(flatten)]
    figures: super::figures::FigureArgs,
}

/// `rig calibrate --gauge`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GaugeKind {
    /// A torque gauge, N mm.
    Torque,
    /// A force gauge on an arm, N.
    Force,
}

/// Files written by `rig calibrate`.
#[derive(Debug, Serialize)]
pub struct CalibrationFiles {
    /// The calibration file.
    pub calibration: String,
    /// Torque-current fit plot.
    pub torque_plot: String,
    /// No-load fit plot.
    pub no_load_plot: String,
    /// Measured points.
    pub points: String,
    /// The fit plots in `--format` when it is not SVG (PNG or PDF beside each SVG).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub figures: Vec<String>,
}

/// What `rig calibrate --json` prints.
#[derive(Debug, Serialize)]
pub struct CalibrateReport {
    /// The fit (c1..c6 in the paper's units at the top level).
    #[serde(flatten)]
    pub result: CalibrationResult,
    /// Units of c1..c6.
    pub units: [&'static str; 6],
    /// What was measured.
    pub measurements: Measurements,
    /// Files written (none for `--dry-run`).
    pub files: Option<CalibrationFiles>,
    /// Whether the constants were written to the device.
    pub written_to_device: bool,
    /// Whether this was a dry run.
    pub dry_run: bool,
    /// Whether the device was the virtual one.
    pub sim: bool,
}

/// Units of C1..C6 as in Table 2.
pub const UNITS: [&str; 6] = paper_units::UNITS;

/// `time` in UTC as `YYYYMMDDTHHMMSSZ` (for folder names).
fn utc_stamp(time: SystemTime) -> String {
    reporting::UtcTime::of(time).compact()
}

/// The default output folder: `report/calibrate-<UTC time>`.
pub fn default_out_dir(now: SystemTime) -> PathBuf {
    Path::new("report").join(format!("calibrate-{}", utc_stamp(now)))
}

/// Runs `rig calibrate`.
pub fn run(a: CalibrateArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let plan = CalibrationSchedule::default();
    let unit = gauge_unit(&a)?;
    // Check the inputs before anything moves.
    let gauge = a
        .gauge_csv
        .as_deref()
        .map(|p| calibrate::read_gauge_csv(p, &plan))
        .transpose()?;
    let from_points = a
        .from_points
        .as_deref()
        .map(calibrate::read_points_csv)
        .transpose()?;
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| default_out_dir(SystemTime::now()));
    let resumed = prepare_out(&a, &out)?;
    let stop = super::connect::interrupt_flag();
    // Refitting earlier points needs the device only to read its record and write the
    // result: a dry run refits offline against the paper's record.
    let offline = from_points.is_some() && a.dry_run;
    let mut session = (!offline).then(|| dev.connect()).transpose()?;
    let base = match session.as_mut() {
        Some(s) => s.client.calibration()?,
        None => protocol::RigParameters::paper(),
    };
    let measured = match (from_points, session.as_mut()) {
        (Some(m), _) => Ok(m),
        (None, Some(session)) => measure(session, &a, &plan, gauge, unit, &out, &stop, resumed),
        (None, None) => unreachable_offline(),
    };
    let measurements = match measured {
        Ok(m) => m,
        Err(e) if stop.load(Ordering::SeqCst) => {
            eprintln!("{e}");
            return Ok(crate::signals::interrupt_exit_code());
        }
        Err(e) => return Err(e),
    };
    let result = calibrate::analyse(&measurements)
        .map_err(|e| partial_refit(&measurements, &plan, a.from_points.as_deref(), e))?;
    let plausible = check_plausible(&a, &result, &measurements, &out)?;
    let port = session
        .as_ref()
        .map_or_else(|| "(refit offline)".to_string(), |s| s.port().to_string());
    let files = if a.dry_run {
        None
    } else {
        let options = a.figures.options();
        let mut files = write_files(&out, &result, &measurements, &base, &port, options.size)?;
        if options.format != reporting::figure::Format::Svg {
            for plot in [&files.torque_plot, &files.no_load_plot] {
                let written = reporting::figure::export(Path::new(plot), &options)?;
                files.figures.push(written.display().to_string());
            }
        }
        Some(files)
    };
    let new_cal = result.apply_to(&base);
    let write = decide_write(
        &a,
        plausible.is_err(),
        &result,
        &measurements,
        files.as_ref(),
    )?;
    if write && let Some(session) = session.as_mut() {
        store(session, &new_cal)?;
    }
    let report = CalibrateReport {
        result,
        units: UNITS,
        measurements,
        files,
        written_to_device: write,
        dry_run: a.dry_run,
        sim: session.as_ref().is_some_and(|s| s.device.is_some()),
    };
    print(&a, &report, plausible.is_err(), write, &port)?;
    Ok(ExitCode::SUCCESS)
}

/// The error of a fit that needs more points: for a partial points file (an interrupted
/// run), what its points do give (the no-load fit's C5 and C6 when the sweep is complete)
/// and how to measure the rest.
fn partial_refit(
    m: &Measurements,
    plan: &CalibrationSchedule,
    from: Option<&Path>,
    fit_error: RigError,
) -> RigError {
    let Some(file) = from else {
        return fit_error;
    };
    let missing_torque = plan.torque_volts.len().saturating_sub(m.torque.len());
    let missing_sweep = plan.sweep_volts.len().saturating_sub(m.no_load.len());
    if missing_torque == 0 && missing_sweep == 0 {
        return fit_error;
    }
    let (w, i): (Vec<f64>, Vec<f64>) = m
        .no_load
        .iter()
        .filter(|s| s.cam_speed_rad_s > 0.02)
        .map(|s| (s.cam_speed_rad_s, s.current_a))
        .unzip();
    let no_load = crate::calibrate::fit::LineFit::fit(&w, &i)
        .filter(|_| missing_sweep == 0)
        .map(|f| {
            format!(
                "its no-load sweep gives C5 = {} A s/rad, C6 = {} A (R^2 {:.5}); ",
                reporting::human(reporting::significant(f.slope, 4)),
                reporting::human(reporting::significant(f.intercept, 4)),
                f.r_squared
            )
        })
        .unwrap_or_default();
    let dir = file
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    RigError::CalibrationFit(format!(
        "{} is from an interrupted run ({} of {} no-load steps, {} of {} torque steps): {no_load}C1-C4 need the missing steps: `rig calibrate --resume --out {}` measures only those",
        file.display(),
        m.no_load.len(),
        plan.sweep_volts.len(),
        m.torque.len(),
        plan.torque_volts.len(),
        dir.display()
    ))
}

/// Measures on the device of `session`, writing the points to `out`/points.csv (atomically)
/// as they are taken, unless a dry run; Ctrl-C (`stop`) ends it with the gear locked.
/// `resumed`: the points of an interrupted run, kept and continued.
#[allow(clippy::too_many_arguments)]
fn measure(
    session: &mut Connection,
    a: &CalibrateArgs,
    plan: &CalibrationSchedule,
    gauge: Option<Vec<f64>>,
    unit: GaugeUnit,
    out: &Path,
    stop: &Arc<AtomicBool>,
    resumed: Option<Measurements>,
) -> Result<Measurements, RigError> {
    let latched = session.client.faults()?.latched;
    if !latched.is_empty() {
        return Err(RigError::DeviceFault {
            what: "calibrate needs a device without faults".into(),
            faults: latched,
        });
    }
    let bar = progress_bar(plan, a.json);
    let Connection { client, device, .. } = session;
    let mut sim_bench;
    let mut operator_bench;
    let bench: &mut dyn GaugeOperator = match device {
        Some(d) if !a.operator => {
            sim_bench = VirtualOperator::new(d, gauge);
            &mut sim_bench
        }
        d => {
            operator_bench = TerminalOperator::new(gauge, unit, bar.clone(), Arc::clone(stop));
            if let Some(d) = d {
                operator_bench = operator_bench.with_device(d);
            }
            &mut operator_bench
        }
    };
    let mut taken = resumed.unwrap_or_default();
    if taken.no_load.len() > plan.sweep_volts.len() || taken.torque.len() > plan.torque_volts.len()
    {
        return Err(RigError::BadValue {
            what: "--resume".into(),
            why: format!(
                "{} holds more steps ({} no-load, {} torque) than the procedure has ({}, {}): it is not from an interrupted `rig calibrate`",
                out.join("points.csv").display(),
                taken.no_load.len(),
                taken.torque.len(),
                plan.sweep_volts.len(),
                plan.torque_volts.len()
            ),
        });
    }
    bar.inc((taken.no_load.len() + taken.torque.len()) as u64);
    let mut write_error = None;
    let result = calibrate::measure(
        client,
        bench,
        plan,
        &mut taken,
        &mut |p, m| match p {
            Progress::Step { setup, volts } => bar.set_message(format!(
                "{} {volts:.2} V",
                if setup == Setup::NoLoad {
                    "no-load sweep"
                } else {
                    "torque step"
                }
            )),
            Progress::Done => {
                bar.inc(1);
                if !a.dry_run
                    && write_error.is_none()
                    && let Err(e) = write_points(out, m)
                {
                    write_error = Some(e);
                }
            }
        },
        &|| stop.load(Ordering::SeqCst),
    );
    bar.finish_and_clear();
    if let Some(e) = write_error {
        return Err(e);
    }
    result.map(|()| taken)
}

/// Writes the measured points to `dir`/points.csv, atomically.
fn write_points(dir: &Path, m: &Measurements) -> Result<PathBuf, RigError> {
    let path = dir.join("points.csv");
    let mut csv = Vec::new();
    calibrate::write_points_csv(m, &mut csv).map_err(|e| RigError::MeasuredFile {
        file: path.display().to_string(),
        why: e.to_string(),
    })?;
    reporting::write_atomic(&path, &csv)?;
    Ok(path)
}

fn progress_bar(plan: &CalibrationSchedule, json: bool) -> ProgressBar {
    if json || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(plan.steps() as u64);
    if let Ok(style) = ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps, {elapsed} elapsed, about {eta} left  {msg}",
    ) {
        bar.set_style(style);
    }
    bar
}

/// Writes calibration.toml (the rig file: `base` with the measured C1-C6, and the fit
/// statistics), the two fit plots (SVG) and the measured points (CSV) into `dir`, each
/// atomically.
pub fn write_files(
    dir: &Path,
    r: &CalibrationResult,
    m: &Measurements,
    base: &protocol::RigParameters,
    port: &str,
    size: reporting::figure::FigureSize,
) -> Result<CalibrationFiles, RigError> {
    let toml_path = dir.join("calibration.toml");
    let mut rig = RigFile::from_wire(&r.apply_to(base));
    rig.calibration.fit = Some(r.fit_section());
    rig.save_with_comment(
        &toml_path,
        &format!(
            "Vibrator calibration measured by `rig calibrate` on {port}.\n\
             `rig calibration set FILE` writes it to the device, `rig explain --model FILE` uses it."
        ),
    )?;
    let points_path = write_points(dir, m)?;
    let table2 = paper_units::table2();
    let torque_plot = dir.join("torque_current.svg");
    let torque_points: Vec<(f64, f64)> = m
        .torque
        .iter()
        .map(|p| (p.step.current_a, p.gauge_nmm))
        .collect();
    plot::draw(
        &torque_plot,
        &FitPlot {
            title: "Torque-current: |τ_cam| = C1 i_in + C2 (Eq. 15)",
            x_label: "current i_in, A",
            y_label: "gauge torque, N mm",
            points: &torque_points,
            fit: &r.torque_fit,
            reference: Some((table2[0], table2[1])),
        },
        size,
    )?;
    let no_load_plot = dir.join("no_load.svg");
    let no_load_points: Vec<(f64, f64)> = m
        .no_load
        .iter()
        .filter(|s| s.cam_speed_rad_s > 0.02)
        .map(|s| (s.cam_speed_rad_s, s.current_a))
        .collect();
    plot::draw(
        &no_load_plot,
        &FitPlot {
            title: "No-load current: |i_loss| = C5 ω_n + C6 (Eq. 17)",
            x_label: "cam speed ω_n, rad/s",
            y_label: "current, A",
            points: &no_load_points,
            fit: &r.no_load_fit,
            reference: Some((table2[4], table2[5])),
        },
        size,
    )?;
    let s = |p: &Path| p.display().to_string();
    Ok(CalibrationFiles {
        calibration: s(&toml_path),
        torque_plot: s(&torque_plot),
        no_load_plot: s(&no_load_plot),
        points: s(&points_path),
        figures: Vec::new(),
    })
}

fn print_text(
    r: &CalibrationResult,
    m: &Measurements,
    files: Option<&CalibrationFiles>,
    dry_run: bool,
) -> Result<(), RigError> {
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "no-load sweep: {} steps ({} stalled), torque steps: {}",
        m.no_load.len(),
        r.stalled_points,
        m.torque.len()
    )?;
    writeln!(
        out,
        "  torque fit:  R^2 {:.6}, residual sd {:.3} N mm (max {:.3})",
        r.torque_fit.r_squared, r.torque_fit.residual_sd, r.torque_fit.residual_max
    )?;
    writeln!(
        out,
        "  no-load fit: R^2 {:.6}, residual sd {:.2} mA (max {:.2})",
        r.no_load_fit.r_squared,
        r.no_load_fit.residual_sd * 1e3,
        r.no_load_fit.residual_max * 1e3
    )?;
    let ci = [
        r.torque_fit.slope_ci95,
        r.torque_fit.intercept_ci95,
        r.consistency.c3_derived.ci95,
        r.consistency.c4_derived.ci95,
        r.no_load_fit.slope_ci95,
        r.no_load_fit.intercept_ci95,
    ];
    writeln!(
        out,
        "  {:<3} {:>11} {:>25} {:>10} {:>8}  unit",
        "", "value", "95 % interval", "Table 2", "diff"
    )?;
    for (k, v) in r.versus_paper.iter().enumerate() {
        writeln!(
            out,
            "  C{} {:>11.5} [{:>11.5}, {:>11.5}] {:>10} {:>+7.1}%  {}{}",
            k + 1,
            v.measured,
            ci[k][0],
            ci[k][1],
            v.paper,
            v.rel_error * 100.0,
            UNITS[k],
            match k {
                2 => "  (C1 C5)",
                3 => "  (C1 C6 + C2)",
                _ => "",
            }
        )?;
    }
    writeln!(
        out,
        "  direct fit of the loss torque: C3 {:.5}, C4 {:.4}: {}",
        r.consistency.c3_direct,
        r.consistency.c4_direct,
        if r.consistency.agree {
            "agrees with C1 C5 and C1 C6 + C2"
        } else {
            "DISAGREES with C1 C5 and C1 C6 + C2"
        }
    )?;
    match files {
        Some(f) => writeln!(
            out,
            "  wrote {}, {}, {}, {}{}",
            f.calibration,
            f.torque_plot,
            f.no_load_plot,
            f.points,
            f.figures
                .iter()
                .map(|p| format!(", {p}"))
                .collect::<String>()
        )?,
        None if dry_run => writeln!(out, "  dry run: no files written, the device unchanged")?,
        None => {}
    }
    Ok(())
}

/// The firmware's plausibility rule on the fit (`model::Calibration::check`): an
/// implausible fit without `--force` (or `--dry-run`) keeps the points and writes nothing
/// else; otherwise the verdict, for the caller to act on.
fn check_plausible(
    a: &CalibrateArgs,
    result: &CalibrationResult,
    measurements: &Measurements,
    out: &Path,
) -> Result<Result<(), String>, RigError> {
    let motor = *firmware_core::CoreConfig::default().motor.constants();
    let plausible = result
        .calibration
        .check(&motor)
        .map_err(|issue| issue.to_string());
    if let Err(issue) = &plausible
        && !a.force
        && !a.dry_run
    {
        // Keep what was measured; write neither the rig file nor the device.
        write_points(out, measurements)?;
        return Err(RigError::CalibrationFit(format!(
            "the fit is implausible for the vibrator's motor: {issue} (the firmware's rule, model::Calibration::check); nothing was written to the device and no calibration.toml; the points are in {}: check the set-up and the gauge readings and measure again, or pass --force to write the rig file anyway",
            out.join("points.csv").display()
        )));
    }
    Ok(plausible)
}

/// Measuring needs a device: offline is only a dry refit of `--from-points` (an error,
/// not a panic, should that rule ever change).
fn unreachable_offline() -> Result<Measurements, RigError> {
    Err(RigError::BadValue {
        what: "--dry-run".into(),
        why: "measuring needs a device: give --from-points FILE to refit offline".into(),
    })
}

/// The gauge's unit from `--gauge` and `--arm-m` (an arm only for a force gauge).
fn gauge_unit(a: &CalibrateArgs) -> Result<GaugeUnit, RigError> {
    if a.arm_m.is_some() && a.gauge == GaugeKind::Torque {
        return Err(RigError::BadValue {
            what: "--arm-m".into(),
            why: "is the arm of a force gauge: add --gauge force (a torque gauge reads N mm)"
                .into(),
        });
    }
    Ok(match a.gauge {
        GaugeKind::Torque => GaugeUnit::Torque,
        GaugeKind::Force => GaugeUnit::Force { arm_m: a.arm_m },
    })
}

/// Prints the report as JSON, or as text (the fit when not shown before the question).
fn print(
    a: &CalibrateArgs,
    report: &CalibrateReport,
    implausible: bool,
    write: bool,
    port: &str,
) -> Result<(), RigError> {
    if a.json {
        let mut out = std::io::stdout().lock();
        serde_json::to_writer_pretty(&mut out, report)?;
        writeln!(out)?;
    } else {
        if a.dry_run || a.yes || implausible {
            print_text(
                &report.result,
                &report.measurements,
                report.files.as_ref(),
                a.dry_run,
            )?;
        }
        if write {
            println!("written to the device on {port}");
        }
    }
    Ok(())
}

/// Creates the output folder and checks it before the first measurement (minutes of gauge
/// readings must have somewhere to go): an earlier run's points are resumed with
/// `--resume` (returned), refused without it unless `--force`. Nothing for a dry run.
fn prepare_out(a: &CalibrateArgs, out: &Path) -> Result<Option<Measurements>, RigError> {
    if a.dry_run {
        return Ok(None);
    }
    // Every output is checked before the first measurement: minutes of gauge readings
    // must have somewhere to go.
    std::fs::create_dir_all(out).map_err(|source| RigError::File {
        action: "create folder",
        path: out.display().to_string(),
        source,
    })?;
    reporting::check_writable_dir(out)?;
    let points = out.join("points.csv");
    if a.resume {
        if points.exists() {
            return Ok(Some(calibrate::read_points_csv(&points)?));
        }
    } else if a.from_points.is_none() && !a.force && points.exists() {
        return Err(RigError::BadValue {
            what: format!("--out {}", out.display()),
            why: format!(
                "already holds an earlier run's {}: it was left unchanged; continue that run with --resume, give a new --out folder, or pass --force to replace it",
                points.display()
            ),
        });
    }
    Ok(None)
}

/// Whether to write the new calibration to the device: never for a dry run or an
/// implausible fit (the firmware refuses it), with `--yes`, else as the operator answers.
fn decide_write(
    a: &CalibrateArgs,
    implausible: bool,
    result: &CalibrationResult,
    measurements: &Measurements,
    files: Option<&CalibrationFiles>,
) -> Result<bool, RigError> {
    Ok(if a.dry_run || implausible {
        if implausible && !a.dry_run {
            eprintln!(
                "--force: the implausible fit is in the rig file only; the firmware refuses it, so it was not written to the device"
            );
        }
        false
    } else if a.yes {
        true
    } else {
        print_text(result, measurements, files, false)?;
        let ok = confirm("Write C1..C6 to the device?")?;
        if !ok {
            eprintln!(
                "not written to the device (without a terminal, pass --yes); `rig calibration set {}` writes it later",
                files
                    .as_ref()
                    .map_or("FILE".into(), |f| f.calibration.clone())
            );
        }
        ok
    })
}

/// Writes `new_cal` to the device and reads it back.
pub(super) fn store(
    session: &mut Connection,
    new_cal: &protocol::RigParameters,
) -> Result<(), RigError> {
    session.client.set_calibration(new_cal)?;
    let back = session.client.calibration()?;
    if back != *new_cal {
        return Err(RigError::Protocol(format!(
            "the device stored a different calibration than sent on {}: {back:?}",
            session.port()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn default_folder_is_under_report_and_named_by_utc_time() {
        let at = |secs: u64| SystemTime::UNIX_EPOCH + Duration::from_secs(secs);
        assert_eq!(utc_stamp(at(0)), "19700101T000000Z");
        // 2000-02-29 12:34:56 UTC: a leap day in a century leap year.
        assert_eq!(utc_stamp(at(951_827_696)), "20000229T123456Z");
        assert_eq!(utc_stamp(at(1_735_689_599)), "20241231T235959Z");
        assert_eq!(
            default_out_dir(at(0)),
            Path::new("report/calibrate-19700101T000000Z")
        );
    }
}
