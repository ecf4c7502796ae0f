//! `rig demo`: the README's main job. On the virtual device it runs the whole rig: the
//! design check of the paper's Table 1, the vibrator calibration, the Fig. 5 switching,
//! the Table 1 backdrive test, the torque sweep of Figs. 8-9 and the fault drills, and
//! writes a report folder. On a real rig (`--port`) it runs only the parts that cannot
//! move a load: design check, identity, faults and the stored calibration.

use std::path::{Path, PathBuf};

use model::paper;
use serde::Serialize;

use crate::RigError;
use crate::calibrate::{
    self, CalibrationResult, CalibrationSchedule, Measurements, operator::VirtualOperator,
};
use crate::connection::{Connection, DeviceOpts};
use crate::design::{self, DesignReport, RigParams};
use sim::scenarios::{faults, fig5, sweep, table1};

/// The paper's Table 1: which gear sets had a non-backdriven point (n = 1 only).
pub const TABLE1_PAPER_HOLDS: [bool; 6] = [true, true, false, false, false, false];

/// The design check over Table 1.
#[derive(Debug, Clone, Serialize)]
pub struct DesignCheck {
    /// One evaluated gear set per Table 1 row.
    pub table1: Vec<DesignReport>,
    /// Whether every hold verdict agrees with the paper.
    pub agrees_with_paper: bool,
}

/// Runs the design check over Table 1 at the paper's rig values.
pub fn design_check() -> Result<DesignCheck, RigError> {
    let table1 = model::TABLE1
        .iter()
        .map(|&z| design::evaluate(z, &RigParams::default(), None))
        .collect::<Result<Vec<_>, _>>()?;
    let agrees_with_paper = table1
        .iter()
        .zip(TABLE1_PAPER_HOLDS)
        .all(|(r, holds)| r.holds_load == holds);
    Ok(DesignCheck {
        table1,
        agrees_with_paper,
    })
}

/// Settings of the simulated demo.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// Report folder.
    pub out: PathBuf,
    /// Fewer sweep points and repeats (for a quick look).
    pub quick: bool,
    /// Seed of the noise and the test order.
    pub seed: u64,
    /// The figures' format and printed size (every figure is also kept as SVG).
    pub figures: reporting::figure::FigureOptions,
}

/// The calibration step's outcome, paper units.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationCheck {
    /// C1..C6 measured on the virtual rig (N mm/A, N mm, N mm s/rad, N mm, A s/rad, A).
    pub measured: [f64; 6],
    /// Table 2.
    pub paper: [f64; 6],
    /// Every constant within 5 % of Table 2 (C4 within 50 %).
    pub within_tolerance: bool,
}

/// What the demo found; `summary.json` in the report folder.
#[derive(Debug, Clone, Serialize)]
pub struct DemoSummary {
    /// Where it ran: `virtual device` or the port.
    pub device: String,
    /// Design check of Table 1.
    pub design: DesignCheck,
    /// Vibrator calibration (virtual device only).
    pub calibration: Option<CalibrationCheck>,
    /// Fig. 5 switching (virtual device only).
    pub fig5: Option<fig5::Fig5Result>,
    /// Table 1 backdrive test (virtual device only).
    pub table1: Option<Vec<table1::Table1Row>>,
    /// Torque sweep summary (virtual device only).
    pub torque_sweep: Option<sweep::SweepSummary>,
    /// Fault drills (virtual device only).
    pub faults: Option<Vec<faults::FaultOutcome>>,
    /// Device identity and state (real rig only).
    pub device_state: Option<DeviceState>,
    /// Files written.
    pub files: Vec<String>,
    /// The report page (Markdown) linking every figure and table with its verdict.
    pub report_page: Option<String>,
    /// Every check agrees with the paper (or, on a real rig, the device is healthy).
    pub all_ok: bool,
}

/// What the demo reads from a real rig.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceState {
    /// Firmware version.
    pub firmware_version: String,
    /// Board name.
    pub board: String,
    /// Latched faults.
    pub latched_faults: String,
    /// Stored calibration C1..C6, paper units.
    pub calibration: [f64; 6],
}

/// Writes the calibration step's files (calibration TOML, fit plots, measured points) into
/// a folder and returns their paths: `rig calibrate`'s writer, handed in by the command
/// line (arguments: folder, fit, measurements, the device's calibration it amends, port).
pub type CalibrationWriter<'a> = &'a dyn Fn(
    &Path,
    &CalibrationResult,
    &Measurements,
    &protocol::RigParameters,
    &str,
) -> Result<Vec<String>, RigError>;

/// Writes `value` as JSON (numbers as a person writes them) to `dir/name`, atomically.
fn write_json<T: Serialize>(
    dir: &Path,
    name: &str,
    value: &T,
    files: &mut Vec<String>,
) -> Result<(), RigError> {
    let path = dir.join(name);
    let mut text = reporting::json_pretty(value)?;
    text.push('\n');
    reporting::write_atomic(&path, text.as_bytes())?;
    files.push(path.display().to_string());
    Ok(())
}

/// Creates the report folder and checks it takes files before anything runs (removing the
/// temporaries a killed run left there).
fn create_dir(dir: &Path) -> Result<(), RigError> {
    std::fs::create_dir_all(dir).map_err(|source| RigError::File {
        action: "create folder",
        path: dir.display().to_string(),
        source,
    })?;
    Ok(reporting::check_writable_dir(dir)?)
}

/// The whole simulated rig, with a report folder; `write_calibration` writes the
/// calibration step's files.
pub fn run_simulated(
    opts: &DemoOptions,
    write_calibration: CalibrationWriter<'_>,
    progress: &mut dyn FnMut(&str),
) -> Result<DemoSummary, RigError> {
    create_dir(&opts.out)?;
    let mut files = Vec::new();
    progress("design check of Table 1");
    let design = design_check()?;
    write_json(&opts.out, "design.json", &design, &mut files)?;

    progress("calibration on the virtual device (the paper's procedure)");
    let calibration = calibrate_virtual(&opts.out, write_calibration, &mut files)?;
    let calibration_figures: Vec<PathBuf> = files
        .iter()
        .filter(|f| f.ends_with(".svg"))
        .map(PathBuf::from)
        .collect();
    let mut calibration_figures_out = Vec::new();
    for svg in &calibration_figures {
        calibration_figures_out.push(figure(svg, &opts.figures, &mut files)?);
    }

    progress("fig5: 1 kg on 75 mm, held 14.5 s, then released");
    let (fig5, history) = crate::experiment::paper::fig5_history(
        &fig5::Fig5Options {
            seed: opts.seed,
            ..Default::default()
        },
        None,
    )?;
    write_json(&opts.out, "fig5.json", &fig5, &mut files)?;
    let fig5_csv = opts.out.join("fig5.csv");
    crate::experiment::hold_release::write_csv(&history, &fig5_csv)?;
    files.push(fig5_csv.display().to_string());
    let fig5_svg = opts.out.join("fig5.svg");
    crate::experiment::hold_release::write_svg(&history, &fig5_svg, opts.figures.size)?;
    let fig5_figure = figure(&fig5_svg, &opts.figures, &mut files)?;

    progress("table1: six gear sets at 3.68 N m");
    let table1 = crate::experiment::paper::table1(
        &model::TABLE1,
        10.0,
        opts.seed,
        sim::Preset::paper().effects,
    )?;
    write_json(&opts.out, "table1.json", &table1, &mut files)?;

    progress("torque sweep: 0.368-3.68 N m at 3.6, 6.2, 8.8 V");
    let sweep_opts = if opts.quick {
        sweep::SweepOptions {
            loads: vec![paper::TAU_ROT_MIN_TESTED, 1.84, paper::TAU_ROT_MAX],
            repeats: 1,
            rest_s: 5.0,
            seed: opts.seed,
            ..Default::default()
        }
    } else {
        sweep::SweepOptions {
            loads: crate::sweep_report::sweep_loads(10),
            seed: opts.seed,
            ..Default::default()
        }
    };
    let points = crate::experiment::paper::torque_sweep(&sweep_opts)?;
    let csv_path = opts.out.join("torque_sweep.csv");
    let header = crate::provenance::simulated_header(
        "rig demo torque sweep",
        &format!("preset paper, seed {}", opts.seed),
    );
    crate::sweep_report::write_csv(&points, &csv_path, &header)?;
    files.push(csv_path.display().to_string());
    let svg_path = opts.out.join("torque_sweep.svg");
    crate::sweep_report::sweep_figure(&svg_path, &points, opts.figures.size)?;
    let sweep_figure = figure(&svg_path, &opts.figures, &mut files)?;
    let torque_sweep = sweep::summarise(&points, &sweep_opts);
    write_json(&opts.out, "torque_sweep.json", &torque_sweep, &mut files)?;

    progress("fault drills");
    let faults = faults::run(&[], opts.seed)?;
    write_json(&opts.out, "faults.json", &faults, &mut files)?;

    let all_ok = design.agrees_with_paper
        && calibration.within_tolerance
        && fig5.held_without_vibration
        && fig5.release_to_motion_s.is_some()
        && table1.iter().all(|r| r.agrees_with_paper)
        && torque_sweep.current_grows_with_load
        && torque_sweep.current_grows_with_speed
        && torque_sweep.tau_cam_grows_with_load
        && torque_sweep.tau_cam_grows_with_speed
        && faults.iter().all(faults::FaultOutcome::ends_safe);
    let page_path = opts.out.join("report.md");
    files.push(page_path.display().to_string());
    let summary_path = opts.out.join("summary.json");
    files.push(summary_path.display().to_string());
    let mut summary = DemoSummary {
        device: "virtual device".into(),
        design,
        calibration: Some(calibration),
        fig5: Some(fig5),
        table1: Some(table1),
        torque_sweep: Some(torque_sweep),
        faults: Some(faults),
        device_state: None,
        files,
        report_page: Some(page_path.display().to_string()),
        all_ok,
    };
    let figures = PageFigures {
        calibration: calibration_figures_out,
        fig5: fig5_figure,
        sweep: sweep_figure,
    };
    let page = report_page(&summary, &opts.out, &figures);
    reporting::write_atomic(&page_path, page.as_bytes())?;
    summary.report_page = Some(page_path.display().to_string());
    write_json(&opts.out, "summary.json", &summary, &mut Vec::new())?;
    Ok(summary)
}

/// The paper's calibration on a virtual device over its pseudo-terminal, 20x real time.
fn calibrate_virtual(
    out: &Path,
    write_calibration: CalibrationWriter<'_>,
    files: &mut Vec<String>,
) -> Result<CalibrationCheck, RigError> {
    let dev = DeviceOpts {
        sim: true,
        speed: 20.0,
        ..DeviceOpts::default()
    };
    let mut session = dev.connect()?;
    let base = session.client.calibration()?;
    let plan = CalibrationSchedule::default();
    let Connection { client, device, .. } = &mut session;
    let device = device
        .as_ref()
        .ok_or_else(|| RigError::Protocol("the virtual device did not start".into()))?;
    let mut bench = VirtualOperator::new(device, None);
    let mut measurements = calibrate::Measurements::default();
    calibrate::measure(
        client,
        &mut bench,
        &plan,
        &mut measurements,
        &mut |_, _| {},
        &|| false,
    )?;
    let result = calibrate::analyse(&measurements)?;
    let dir = out.join("calibration");
    create_dir(&dir)?;
    files.extend(write_calibration(
        &dir,
        &result,
        &measurements,
        &base,
        "the virtual device",
    )?);
    let measured = result.constants();
    let paper = model::Calibration::PAPER.to_paper_units();
    let within_tolerance = measured.iter().zip(paper).enumerate().all(|(k, (m, p))| {
        let tol = if k == 3 { 0.5 } else { 0.05 };
        ((m - p) / p).abs() < tol
    });
    Ok(CalibrationCheck {
        measured,
        paper,
        within_tolerance,
    })
}

/// The parts that cannot move a load, on a real rig: design check, identity, faults and
/// the stored calibration.
pub fn run_on_device(dev: &DeviceOpts, out: &Path) -> Result<DemoSummary, RigError> {
    create_dir(out)?;
    let mut files = Vec::new();
    let design = design_check()?;
    write_json(out, "design.json", &design, &mut files)?;
    let mut session = dev.connect()?;
    let faults = session.client.faults()?;
    let cal = session.client.calibration()?;
    let device_state = DeviceState {
        firmware_version: session.info.firmware_version.to_string(),
        board: session.info.board.to_string(),
        latched_faults: faults.latched.to_string(),
        calibration: cal.constants(),
    };
    let all_ok = design.agrees_with_paper && faults.latched.is_empty();
    let summary = DemoSummary {
        device: session.port().to_string(),
        design,
        calibration: None,
        fig5: None,
        table1: None,
        torque_sweep: None,
        faults: None,
        device_state: Some(device_state),
        files,
        report_page: None,
        all_ok,
    };
    write_json(out, "summary.json", &summary, &mut Vec::new())?;
    Ok(summary)
}

/// Writes the SVG figure `svg` also in the asked format (when not SVG) and records the
/// files; returns the figure the report page shows.
fn figure(
    svg: &Path,
    options: &reporting::figure::FigureOptions,
    files: &mut Vec<String>,
) -> Result<PathBuf, RigError> {
    let svg_name = svg.display().to_string();
    if !files.contains(&svg_name) {
        files.push(svg_name);
    }
    let out = reporting::figure::export(svg, options)?;
    if out != svg {
        files.push(out.display().to_string());
    }
    Ok(out)
}

/// The figures the report page shows, in the asked format.
struct PageFigures {
    calibration: Vec<PathBuf>,
    fig5: PathBuf,
    sweep: PathBuf,
}

/// The report page: every table and figure of the demo with its verdict against the
/// paper, links relative to the report folder `dir`.
fn report_page(s: &DemoSummary, dir: &Path, figures: &PageFigures) -> String {
    use std::fmt::Write;
    let rel = |p: &Path| {
        p.strip_prefix(dir)
            .unwrap_or(p)
            .display()
            .to_string()
            .replace('\\', "/")
    };
    let verdict = |ok: bool| if ok { "**pass**" } else { "**FAIL**" };
    let mut out = format!(
        "# rig demo: the paper on the {}\n\nNoda et al., *Switching backdrivability of a planetary gear by vibration*, reproduced on the simulated rig (firmware control core + plant). Overall: {}.\n\n",
        s.device,
        if s.all_ok {
            "**every check agrees with the paper**"
        } else {
            "**SOME CHECKS FAILED**"
        }
    );
    let _ = writeln!(
        out,
        "| check | against the paper | verdict | files |\n|---|---|---|---|"
    );
    let _ = writeln!(
        out,
        "| design check, Table 1 | hold verdicts (mu_s Lambda > 1) of the six gear sets | {} | [design.json](design.json) |",
        verdict(s.design.agrees_with_paper)
    );
    if let Some(c) = &s.calibration {
        let figs: Vec<String> = figures
            .calibration
            .iter()
            .map(|f| format!("[{}]({})", rel(f), rel(f)))
            .collect();
        let _ = writeln!(
            out,
            "| vibrator calibration, Table 2 | C1-C6 within 5 % (C4 within 50 %) | {} | [calibration.toml](calibration/calibration.toml), {} |",
            verdict(c.within_tolerance),
            figs.join(", ")
        );
    }
    if let Some(f) = &s.fig5 {
        let _ = writeln!(
            out,
            "| Fig. 5 | 1 kg on 75 mm held {} s without vibration, falls once released | {} | [fig5.json](fig5.json), [fig5.csv](fig5.csv), [{}]({}) |",
            reporting::human(f.hold_s),
            verdict(f.held_without_vibration && f.release_to_motion_s.is_some()),
            rel(&figures.fig5),
            rel(&figures.fig5)
        );
    }
    if let Some(rows) = &s.table1 {
        let _ = writeln!(
            out,
            "| Table 1 backdrive | n = 1 holds without vibration; all backdrive with it | {} | [table1.json](table1.json) |",
            verdict(rows.iter().all(|r| r.agrees_with_paper))
        );
    }
    if let Some(t) = &s.torque_sweep {
        let ok = t.current_grows_with_load
            && t.current_grows_with_speed
            && t.tau_cam_grows_with_load
            && t.tau_cam_grows_with_speed;
        let _ = writeln!(
            out,
            "| torque sweep, Figs. 8-9 | current and tau_cam grow with load and speed (Eq. 10 drawn) | {} | [torque_sweep.csv](torque_sweep.csv), [torque_sweep.json](torque_sweep.json), [{}]({}) |",
            verdict(ok),
            rel(&figures.sweep),
            rel(&figures.sweep)
        );
    }
    if let Some(f) = &s.faults {
        let _ = writeln!(
            out,
            "| fault drills | every drill ends with the motor off and the fault latched (debug-halt: the IWDG reset), the current inside the sensor's range | {} | [faults.json](faults.json) |",
            verdict(f.iter().all(faults::FaultOutcome::ends_safe))
        );
    }
    if let Some(c) = &s.calibration {
        let _ = writeln!(
            out,
            "\n## Vibrator calibration against Table 2\n\n| constant | measured | Table 2 | difference |\n|---|---|---|---|"
        );
        for (k, (m, p)) in c.measured.iter().zip(c.paper).enumerate() {
            let _ = writeln!(
                out,
                "| C{} | {} | {} | {:+.1} % |",
                k + 1,
                reporting::human(reporting::significant(*m, 4)),
                reporting::human(p),
                (m / p - 1.0) * 100.0
            );
        }
    }
    if let Some(rows) = &s.table1 {
        let _ = writeln!(
            out,
            "\n## Table 1 on the simulated rig\n\n| Z1, Z2, Z3, Z4 | n | mu_s Lambda | without vibration | with vibration | as in the paper |\n|---|---|---|---|---|---|"
        );
        let word = |b: bool| if b { "backdriven" } else { "held" };
        for r in rows {
            let _ = writeln!(
                out,
                "| {} | {} | {:.3} | {} | {} | {} |",
                r.z.map(|v| v.to_string()).join(", "),
                r.n,
                r.mu_s_lambda,
                word(r.backdriven_without_vibration),
                word(r.backdriven_with_vibration),
                if r.agrees_with_paper { "yes" } else { "NO" }
            );
        }
    }
    let _ = writeln!(out, "\n## Figures\n");
    let mut all: Vec<&PathBuf> = figures.calibration.iter().collect();
    all.push(&figures.fig5);
    all.push(&figures.sweep);
    for f in all {
        let name = rel(f);
        if name.ends_with(".pdf") {
            let _ = writeln!(out, "- [{name}]({name})");
        } else {
            let _ = writeln!(out, "![{name}]({name})\n");
        }
    }
    out
}

/// Short human-readable summary.
pub fn render_text(s: &DemoSummary) -> String {
    use std::fmt::Write;
    let mut out = format!(
        "rig demo on the {}\n\ndesign check, paper's Table 1 (mu_s = {}, mu_d = {}):\n",
        s.device,
        paper::MU_S,
        paper::MU_D
    );
    let _ = writeln!(
        out,
        "  {:<16} {:>8} {:>12} {:>12}  verdict",
        "Z1,Z2,Z3,Z4", "rho", "mu_s*Lambda", "mu_d*Lambda"
    );
    for (r, paper) in s.design.table1.iter().zip(TABLE1_PAPER_HOLDS) {
        let z = r.z.map(|v| v.to_string()).join(",");
        let verdict = if r.holds_load { "holds" } else { "backdrives" };
        let mark = if r.holds_load == paper {
            "as in the paper"
        } else {
            "DIFFERS from the paper"
        };
        let _ = writeln!(
            out,
            "  {z:<16} {:>8.2} {:>12.3} {:>12.3}  {verdict} ({mark})",
            r.rho, r.mu_s_lambda, r.mu_d_lambda
        );
    }
    let _ = writeln!(
        out,
        "  {}",
        if s.design.agrees_with_paper {
            "every verdict agrees with the paper"
        } else {
            "some verdicts disagree with the paper"
        }
    );
    if let Some(c) = &s.calibration {
        let _ = writeln!(
            out,
            "\ncalibration (paper's procedure on the virtual rig), measured vs Table 2:"
        );
        for (k, (m, p)) in c.measured.iter().zip(c.paper).enumerate() {
            let _ = writeln!(
                out,
                "  C{} {:>10.5} {:>10.5}  ({:+.1} %)",
                k + 1,
                m,
                p,
                (m / p - 1.0) * 100.0
            );
        }
    }
    if let Some(f) = &s.fig5 {
        let _ = writeln!(
            out,
            "\nfig5: held without vibration for {:.1} s: {}; moved {} after the release; {:.3} rad/s after the cam stopped (mu_d*Lambda = {:.3})",
            f.hold_s,
            f.held_without_vibration,
            f.release_to_motion_s
                .map_or("never".into(), |t| format!("{t:.3} s")),
            f.output_speed_after_stop_rad_s,
            f.mu_d_lambda
        );
    }
    if let Some(rows) = &s.table1 {
        let agree = rows.iter().filter(|r| r.agrees_with_paper).count();
        let _ = writeln!(
            out,
            "table1: {agree} of {} gear sets as in the paper (n = 1 holds, all backdrive with vibration)",
            rows.len()
        );
    }
    if let Some(t) = &s.torque_sweep {
        let hz: Vec<String> = t
            .mean_hz_per_voltage
            .iter()
            .map(|(v, f)| format!("{v} V -> {f:.1} Hz"))
            .collect();
        let _ = writeln!(
            out,
            "torque sweep: {} points, {}; current and tau_cam grow with load: {}, with speed: {}; RMS(measured - Eq. 10) = {:.2} N mm",
            t.points,
            hz.join(", "),
            t.current_grows_with_load && t.tau_cam_grows_with_load,
            t.current_grows_with_speed && t.tau_cam_grows_with_speed,
            t.rmse_tau_cam_vs_eq10_nm * 1e3
        );
    }
    if let Some(f) = &s.faults {
        let drills: Vec<String> = f
            .iter()
            .map(|o| {
                format!(
                    "{} {}",
                    o.name,
                    o.time_to_safe_s.map_or("never safe".into(), |t| format!(
                        "safe in {:.0} ms",
                        t * 1e3
                    ))
                )
            })
            .collect();
        let _ = writeln!(out, "fault drills: {}", drills.join(", "));
    }
    if let Some(d) = &s.device_state {
        let _ = writeln!(
            out,
            "\ndevice: firmware {} on {}, latched faults: {}",
            d.firmware_version, d.board, d.latched_faults
        );
        let c: Vec<String> = d.calibration.iter().map(|&v| reporting::human(v)).collect();
        let _ = writeln!(out, "stored calibration C1..C6: {}", c.join(", "));
        let _ = writeln!(
            out,
            "(motion tests need an operator: see `rig release`, `rig calibrate`, `rig monitor`)"
        );
    }
    if !s.files.is_empty() {
        let _ = writeln!(
            out,
            "\nreport: {} files, summary in {}",
            s.files.len(),
            s.files.last().map_or("", String::as_str)
        );
    }
    let _ = writeln!(
        out,
        "result: {}",
        if s.all_ok {
            "everything agrees with the paper"
        } else {
            "SOME CHECKS FAILED (see summary.json)"
        }
    );
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn design_check_agrees_with_the_paper() {
        let s = super::design_check().unwrap();
        assert!(s.agrees_with_paper);
        assert_eq!(s.table1.len(), 6);
    }
}
