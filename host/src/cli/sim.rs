//! `rig sim <scenario>`: the paper's experiments and the fault drills on the simulated rig
//! (firmware core + plant in closed loop, virtual time).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};

use crate::RigError;
use sim::scenarios::{faults, fig5, sweep, table1};

/// Arguments of `rig sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// The scenario.
    #[command(subcommand)]
    pub scenario: Scenario,
}

/// The scenarios.
#[derive(Debug, Subcommand)]
pub enum Scenario {
    /// Fig. 5: (50, 49) with 1 kg on 75 mm, held without vibration, falls once released.
    Fig5(Fig5Args),
    /// Table 1: the six gear sets at 3.68 N m, with and without vibration.
    Table1(Table1Args),
    /// Figs. 8-9: current and cam torque over load (0.368-3.68 N m) at 3.6, 6.2, 8.8 V.
    TorqueSweep(SweepArgs),
    /// Fault drills: overcurrent (jammed cam), encoder-loss, comms-loss, bad-calibration,
    /// reversed-encoder, load-limit, overvoltage (the bridge's bus above its limit).
    Faults(FaultArgs),
    /// Serve the virtual rig on a pseudo-terminal any serial client can open, until Ctrl-C.
    Serve(super::serve::ServeArgs),
}

/// Arguments of `rig sim fig5`.
#[derive(Debug, Args)]
pub struct Fig5Args {
    /// A rig file with a fitted [model] (`rig explain --write-model`): the plant runs with
    /// its mu and effects instead of the preset's.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Hold phase without vibration, s (the paper held 14.5 s).
    #[arg(long, default_value_t = 14.5, value_parser = crate::args::positive)]
    pub hold: f64,
    /// Vibration frequency of the release, Hz (3.6 V gave about 5 Hz; 1 to 15).
    #[arg(long, default_value_t = 5.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// How long the record runs after the cam has stopped, s. Default 0.5 s for the
    /// paper's gear, 20 s with a designed gear from --model (with mu_d*Lambda just above 1
    /// friction needs seconds to bring the 2.79 kg m^2 output to rest).
    #[arg(long, value_parser = crate::args::positive)]
    pub after_stop: Option<f64>,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The current sensor's (ACS714) supply, V: 4.5 to 5.5 (the sensor is ratiometric).
    #[arg(long, default_value_t = 5.0, value_parser = sensor_supply)]
    pub sensor_supply_v: f64,
    /// The plant: `paper` behaves as the paper's rig measured (docs/presets.md), `ideal` is
    /// the paper's equations alone.
    #[arg(long, default_value = "paper", value_parser = clap::builder::PossibleValuesParser::new(sim::preset::PRESETS))]
    pub preset: String,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig sim table1`.
#[derive(Debug, Args)]
pub struct Table1Args {
    /// A rig file with a fitted [model] (`rig explain --write-model`): the plant runs with
    /// its mu and effects instead of the preset's.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Vibration frequency of the release, Hz (1 to 15).
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The plant: `paper` behaves as the paper's rig measured (docs/presets.md), `ideal` is
    /// the paper's equations alone.
    #[arg(long, default_value = "paper", value_parser = clap::builder::PossibleValuesParser::new(sim::preset::PRESETS))]
    pub preset: String,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig sim torque-sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// A rig file with a fitted [model] (`rig explain --write-model`): the plant runs with
    /// its mu and effects instead of the preset's.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Number of load levels from 0.368 to 3.68 N m (at least 2).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(2..=100))]
    pub levels: u32,
    /// Repeats per point.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,
    /// Rest between points, s (the motor cools).
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::non_negative)]
    pub rest: f64,
    /// Seed of the noise and the test order.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The current sensor's (ACS714) supply, V: 4.5 to 5.5 (the sensor is ratiometric).
    #[arg(long, default_value_t = 5.0, value_parser = sensor_supply)]
    pub sensor_supply_v: f64,
    /// The plant: `paper` behaves as the paper's rig measured (docs/presets.md), `ideal` is
    /// the paper's equations alone.
    #[arg(long, default_value = "paper", value_parser = clap::builder::PossibleValuesParser::new(sim::preset::PRESETS))]
    pub preset: String,
    /// Write one row per test point to this CSV file.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig sim faults`.
#[derive(Debug, Args)]
pub struct FaultArgs {
    /// Drills to run (default: all).
    #[arg(value_parser = clap::builder::PossibleValuesParser::new(faults::DRILLS))]
    pub drills: Vec<String>,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// A release frequency the simulated rig drives as asked: its calibration is the paper's
/// (at most 15 Hz); above that the firmware would silently drive at 15 Hz.
fn check_freq(hz: f64) -> Result<f32, RigError> {
    let paper = protocol::RigParameters::paper();
    crate::limits::check_release_freq("--freq", hz, &paper).map_err(|_| {
        let (lo, hi) = crate::limits::release_freq_range(&paper);
        RigError::BadValue {
            what: format!("--freq {hz}"),
            why: format!(
                "the simulated rig drives {lo} to {hi} Hz (the paper's calibration, max_freq_hz = {hi}): give a frequency in that range"
            ),
        }
    })
}

/// What `rig sim torque-sweep --json` prints: the sweep's summary and how far the
/// firmware's estimate is from the plant's truth.
#[derive(Debug, serde::Serialize)]
struct SweepJson {
    #[serde(flatten)]
    summary: sweep::SweepSummary,
    /// RMS over all points of the firmware's per-revolution tau_cam estimate (the row's
    /// `tau_cam_est_nm`) minus the plant's true mean cam torque over the revolutions of
    /// the same window, N m (PWM ripple, sensor tolerances and noise modelled).
    estimate_rms_error_nm: f64,
}

/// Runs `rig sim`.
pub fn run(a: SimArgs) -> Result<ExitCode, RigError> {
    match a.scenario {
        Scenario::Fig5(a) => fig5(a),
        Scenario::Table1(a) => table1(a),
        Scenario::TorqueSweep(a) => torque_sweep(a),
        Scenario::Serve(a) => super::serve::run(a),
        Scenario::Faults(a) => fault_drills(a),
    }
}

/// Runs `rig sim` with Fig. 5 on the virtual rig.
fn fig5(a: Fig5Args) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    let opts = fig5::Fig5Options {
        hold_s: a.hold,
        vibration_hz: check_freq(a.freq)?,
        after_stop_s: a
            .after_stop
            .unwrap_or(if designs_a_gear(a.model.as_deref())? {
                DESIGN_AFTER_STOP_S
            } else {
                fig5::Fig5Options::default().after_stop_s
            }),
        seed: a.seed,
        sensor_supply_v: a.sensor_supply_v,
        effects: sim::Preset::by_name(&a.preset)?.effects,
        ..Default::default()
    };
    let fitted = model_or_design(a.model.as_deref())?;
    let r = crate::experiment::paper::fig5_fitted(&opts, fitted.as_ref())?;
    if a.json {
        super::print_json(&mut out, &r)?;
    } else {
        let [z1, z2, z3, z4] = r.z;
        writeln!(
            out,
            "fig5, Z1..Z4 = {z1}, {z2}, {z3}, {z4}, 1.0 kg on 75 mm:"
        )?;
        writeln!(
            out,
            "  held without vibration for {:.1} s: {}",
            r.hold_s, r.held_without_vibration
        )?;
        match r.release_to_motion_s {
            Some(t) => writeln!(out, "  load moved {:.3} s after the release request", t)?,
            None => writeln!(out, "  load did not move after the release request")?,
        }
        writeln!(
            out,
            "  output speed after the cam stopped: {:.3} rad/s (mu_d*Lambda = {:.3})",
            r.output_speed_after_stop_rad_s, r.mu_d_lambda
        )?;
        writeln!(
            out,
            "  after the cam stopped: {} ({:.4} rad of travel)",
            if r.stops_after_vibration {
                "the output came to rest"
            } else {
                "the output kept moving"
            },
            r.after_stop_travel_rad
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `rig sim` with Table 1 on the virtual rig.
fn table1(a: Table1Args) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    let fitted = model_or_design(a.model.as_deref())?;
    let rows = crate::experiment::paper::table1_fitted(
        &model::TABLE1,
        f64::from(check_freq(a.freq)?),
        a.seed,
        sim::Preset::by_name(&a.preset)?.effects,
        fitted.as_ref(),
    )?;
    if a.json {
        super::print_json(&mut out, &rows)?;
    } else {
        writeln!(
            out,
            "table1 at tau_rot = {} N m, Z1,Z2,Z3,Z4:",
            reporting::human(table1::TAU_ROT)
        )?;
        for r in &rows {
            writeln!(
                out,
                "  {:<12} n={} without vibration: {:<11} with vibration: {:<11} {}",
                r.z.map(|v| v.to_string()).join(","),
                r.n,
                if r.backdriven_without_vibration {
                    "backdriven"
                } else {
                    "held"
                },
                if r.backdriven_with_vibration {
                    "backdriven"
                } else {
                    "held"
                },
                if r.agrees_with_paper {
                    "as in the paper"
                } else {
                    "DIFFERS from the paper"
                }
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `rig sim` with the torque sweep of Figs. 8-9 on the virtual rig.
fn torque_sweep(a: SweepArgs) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    let opts = sweep::SweepOptions {
        loads: crate::sweep_report::sweep_loads(a.levels),
        repeats: a.repeats,
        rest_s: a.rest,
        seed: a.seed,
        sensor_supply_v: a.sensor_supply_v,
        effects: sim::Preset::by_name(&a.preset)?.effects,
        ..Default::default()
    };
    let fitted = fitted_model(a.model.as_deref())?;
    let (points, estimate_rms_error_nm) =
        crate::experiment::paper::torque_sweep_with_error(&opts, fitted.as_ref())?;
    if let Some(path) = &a.csv {
        let details = format!(
            "preset {}, {}seed {}",
            a.preset,
            a.model
                .as_ref()
                .map_or(String::new(), |m| format!("model {}, ", m.display())),
            a.seed
        );
        let header = crate::provenance::simulated_header("rig sim torque-sweep", &details);
        crate::sweep_report::write_csv(&points, path, &header)?;
    }
    let summary = sweep::summarise(&points, &opts);
    if a.json {
        let json = SweepJson {
            summary,
            estimate_rms_error_nm,
        };
        super::print_json(&mut out, &json)?;
    } else {
        writeln!(out, "torque sweep: {} points", summary.points)?;
        for (v, hz) in &summary.mean_hz_per_voltage {
            writeln!(out, "  {v:.1} V: {hz:.2} Hz mean cam frequency")?;
        }
        writeln!(
            out,
            "  current grows with load: {}, with speed: {}",
            summary.current_grows_with_load, summary.current_grows_with_speed
        )?;
        writeln!(
            out,
            "  tau_cam estimate grows with load: {}, with speed: {}",
            summary.tau_cam_grows_with_load, summary.tau_cam_grows_with_speed
        )?;
        writeln!(
            out,
            "  RMS(tau_cam measured - Eq. 10) = {:.2} N mm",
            summary.rmse_tau_cam_vs_eq10_nm * 1e3
        )?;
        writeln!(
            out,
            "  RMS(firmware's tau_cam estimate - plant's true cam torque) = {:.2} N mm",
            estimate_rms_error_nm * 1e3
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `rig sim` with the fault drills.
fn fault_drills(a: FaultArgs) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    let outcomes = faults::run(&a.drills, a.seed)?;
    if a.json {
        super::print_json(&mut out, &outcomes)?;
    } else {
        for o in &outcomes {
            writeln!(
                out,
                "  {:<16} motor off: {:<5} latched: {:<5} safe after {} peak {:.2} A{} faults: {}",
                o.name,
                o.motor_off,
                o.fault_latched,
                o.time_to_safe_s
                    .map(|t| format!("{t:.3} s"))
                    .unwrap_or_else(|| "never".into()),
                o.peak_current_a,
                if o.peak_within_sensor_range {
                    ""
                } else {
                    " (beyond the sensor's range)"
                },
                o.faults.join(",")
            )?;
        }
    }
    let all_safe = outcomes.iter().all(faults::FaultOutcome::ends_safe);
    Ok(if all_safe {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// The rig file of `--model`, which must have a fitted `[model]`.
fn fitted_model(path: Option<&std::path::Path>) -> Result<Option<rigfile::RigFile>, RigError> {
    let Some(path) = path else {
        return Ok(None);
    };
    let rig = rigfile::RigFile::load(path)?;
    if rig.model.is_none() {
        return Err(RigError::BadValue {
            what: format!("--model {}", path.display()),
            why: "the rig file has no fitted [model]: write one with `rig explain --measured X --write-model FILE`".into(),
        });
    }
    Ok(Some(rig))
}

/// `rig sim fig5`'s record after the cam stop with a designed gear, s.
pub const DESIGN_AFTER_STOP_S: f64 = 20.0;

/// Whether the `--model` file designs a gear (its `[gear]` is not the paper's standard set).
fn designs_a_gear(path: Option<&std::path::Path>) -> Result<bool, RigError> {
    match path {
        Some(p) => Ok(rigfile::RigFile::load(p)?.gear_set()? != model::paper::RIG_GEARS),
        None => Ok(false),
    }
}

/// The rig file of `rig sim fig5|table1 --model`: a fitted `[model]` (its mu and effects
/// run in the plant), a designed `[gear]` (`rig design search --write`: the scenario runs
/// that gear), or both.
fn model_or_design(path: Option<&std::path::Path>) -> Result<Option<rigfile::RigFile>, RigError> {
    let Some(path) = path else {
        return Ok(None);
    };
    let rig = rigfile::RigFile::load(path)?;
    if rig.model.is_none() && rig.gear_set()? == model::paper::RIG_GEARS {
        return Err(RigError::BadValue {
            what: format!("--model {}", path.display()),
            why: "the rig file has neither a fitted [model] nor a designed [gear]: write one with `rig explain --measured X --write-model FILE` or `rig design search --write DIR`".into(),
        });
    }
    Ok(Some(rig))
}

/// `--sensor-supply-v`: the ACS714's specified supply range, 4.5 to 5.5 V.
fn sensor_supply(text: &str) -> Result<f64, String> {
    let v: f64 = text
        .parse()
        .map_err(|_| format!("'{text}' is not a number of volts"))?;
    let (low, high) = (
        model::hardware::acs714::SUPPLY_MIN_V,
        model::hardware::acs714::SUPPLY_MAX_V,
    );
    if (low..=high).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{v} V is outside the ACS714's supply range {low} to {high} V"
        ))
    }
}
