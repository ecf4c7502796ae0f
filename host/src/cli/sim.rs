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
    /// Fault drills: overcurrent (jammed cam), encoder-loss, comms-loss, bad-calibration.
    Faults(FaultArgs),
    /// Serve the virtual rig on a pseudo-terminal any serial client can open, until Ctrl-C.
    Serve(super::serve::ServeArgs),
}

/// Arguments of `rig sim fig5`.
#[derive(Debug, Args)]
pub struct Fig5Args {
    /// Hold phase without vibration, s (the paper held 14.5 s).
    #[arg(long, default_value_t = 14.5, value_parser = crate::args::positive)]
    pub hold: f64,
    /// Vibration frequency of the release, Hz (3.6 V gave about 5 Hz; 1 to 15).
    #[arg(long, default_value_t = 5.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The current sensor's (ACS714) supply, V: 4.5 to 5.5 (the sensor is ratiometric).
    #[arg(long, default_value_t = 5.0, value_parser = sensor_supply)]
    pub sensor_supply_v: f64,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig sim table1`.
#[derive(Debug, Args)]
pub struct Table1Args {
    /// Vibration frequency of the release, Hz (1 to 15).
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig sim torque-sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
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

/// The torque sweep as `rig experiment torque-sweep` runs it (one implementation), on the
/// in-process virtual rig in virtual time, its rows with the simulator's extra columns
/// (the torque measured by Eqs. (15)-(17) and Eq. (10) at the mean cam speed).
fn sweep_procedure(opts: &sweep::SweepOptions) -> Result<Vec<sweep::SweepPoint>, RigError> {
    use crate::experiment::{Operator, Plan, SimBench, sweep as procedure};
    let z = opts.z;
    let mut config = sim::SimConfig::for_gear(z, model::plant::Load::Torque(0.0))
        .map_err(|source| sim::SimError::Gear { z, source })?;
    config.seed = opts.seed;
    config.plant.effects = opts.effects;
    let drive = config.plant.drive;
    let mu = config.plant.mu_s;
    let mut plan = Plan::grid(
        "rig sim torque-sweep",
        &opts.loads,
        &opts.voltages,
        opts.repeats,
        opts.rest_s,
    );
    plan.seed = opts.seed;
    plan.window_s = opts.window_s;
    let mut bench = SimBench::new(config)?;
    let mut operator = Operator::scripted(b"", false);
    let setup = procedure::SweepSetup {
        plan,
        window: procedure::Window::Start,
        resume: false,
        command: "rig sim torque-sweep".into(),
    };
    let outcome = procedure::run_to(&mut bench, &mut operator, &setup, None, &mut |_| {})?;
    let calibration = model::paper::CALIBRATION;
    Ok(outcome
        .rows
        .into_iter()
        .map(|r| sweep::SweepPoint {
            t_s: r.t_s,
            v_in_v: r.v_in_v.unwrap_or(0.0),
            omega_n_rad_s: r.omega_n_rad_s,
            tau_rot_nm: r.tau_rot_nm,
            i_in_a: r.i_in_a,
            temp_c: r.temp_c.unwrap_or(f64::NAN),
            repeat: r.repeat,
            tau_cam_est_nm: r.tau_cam_est_nm,
            tau_cam_meas_nm: calibration.cam_torque(r.i_in_a, r.omega_n_rad_s),
            tau_cam_eq10_nm: drive.required_cam_torque(mu, r.tau_rot_nm, r.omega_n_rad_s),
            backdriven: r.backdriven.unwrap_or(1),
        })
        .collect())
}

/// Table 1 as `rig experiment backdrive` runs it (one implementation), once per gear set
/// on a fresh in-process virtual rig with that set.
fn table1_procedure(
    sets: &[[u32; 4]],
    hz: f64,
    seed: u64,
) -> Result<Vec<table1::Table1Row>, RigError> {
    use crate::experiment::{Operator, SimBench, backdrive};
    let opts = backdrive::Backdrive {
        load_nm: table1::TAU_ROT,
        hz,
        ..Default::default()
    };
    let mut rows = Vec::new();
    for &z in sets {
        let mut config = sim::SimConfig::for_gear(z, model::plant::Load::Torque(0.0))
            .map_err(|source| sim::SimError::Gear { z, source })?;
        config.seed = seed;
        let gear = config.plant.drive.gear;
        let mut bench = SimBench::new(config)?;
        let mut operator = Operator::scripted(b"", false);
        let Some(v) = backdrive::run(&mut bench, &mut operator, &opts, Some(z))? else {
            continue;
        };
        let paper_non_backdriven_point = gear.n() == 1;
        rows.push(table1::Table1Row {
            z,
            n: gear.n(),
            mu_s_lambda: model::paper::MU_S * gear.big_lambda(),
            backdriven_without_vibration: v.backdriven_without_vibration,
            backdriven_with_vibration: v.backdriven_with_vibration,
            paper_non_backdriven_point,
            agrees_with_paper: v.backdriven_without_vibration != paper_non_backdriven_point
                && v.backdriven_with_vibration,
        });
    }
    Ok(rows)
}

/// Fig. 5 as `rig experiment hold-release` runs it (one implementation), on the
/// in-process virtual rig with Fig. 5's gear set and its 1.0 kg mass on 75 mm.
fn fig5_procedure(opts: &fig5::Fig5Options) -> Result<fig5::Fig5Result, RigError> {
    use crate::experiment::{Operator, SimBench, hold_release};
    let z = model::paper::FIG5_Z;
    let mut config = sim::SimConfig::for_gear(z, model::paper::FIG5_LOAD)
        .map_err(|source| sim::SimError::Gear { z, source })?;
    config.seed = opts.seed;
    let mu_d_lambda = config.plant.mu_d * config.plant.drive.gear.big_lambda();
    let mut bench = SimBench::new(config)?;
    let mut operator = Operator::scripted(b"", false);
    let procedure = hold_release::HoldRelease {
        load_nm: None,
        hold_s: opts.hold_s,
        hz: f64::from(opts.vibration_hz),
        release_s: opts.release_s,
        // The cam brakes to rest (well under a second), then `after_stop_s`.
        after_s: 1.0 + opts.after_stop_s,
    };
    let samples = hold_release::run(&mut bench, &mut operator, &procedure, &mut |_| {})?;
    let n = hold_release::fig5_numbers(&samples, model::paper::R_OUT);
    Ok(fig5::Fig5Result {
        z,
        held_without_vibration: n.held_without_vibration,
        hold_s: opts.hold_s,
        release_to_motion_s: n.release_to_motion_s,
        output_speed_after_stop_rad_s: n.output_speed_after_stop_rad_s,
        output_speed_at_stop_rad_s: n.output_speed_at_stop_rad_s,
        load_drop_m: n.load_drop_m,
        mu_d_lambda,
    })
}

/// Runs `rig sim`.
pub fn run(a: SimArgs) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    match a.scenario {
        Scenario::Fig5(a) => {
            let opts = fig5::Fig5Options {
                hold_s: a.hold,
                vibration_hz: check_freq(a.freq)?,
                seed: a.seed,
                sensor_supply_v: a.sensor_supply_v,
                ..Default::default()
            };
            let r = fig5_procedure(&opts)?;
            if a.json {
                super::print_json(&mut out, &r)?;
            } else {
                writeln!(out, "fig5, (Z1, Z4) = (50, 49), 1.0 kg on 75 mm:")?;
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
            }
            Ok(ExitCode::SUCCESS)
        }
        Scenario::Table1(a) => {
            let rows = table1_procedure(&model::TABLE1, f64::from(check_freq(a.freq)?), a.seed)?;
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
        Scenario::TorqueSweep(a) => {
            let opts = sweep::SweepOptions {
                loads: crate::sweep_report::sweep_loads(a.levels),
                repeats: a.repeats,
                rest_s: a.rest,
                seed: a.seed,
                sensor_supply_v: a.sensor_supply_v,
                effects: sim::Preset::by_name(&a.preset)?.effects,
                ..Default::default()
            };
            let points = sweep_procedure(&opts)?;
            if let Some(path) = &a.csv {
                crate::sweep_report::write_csv(&points, path)?;
            }
            let summary = sweep::summarise(&points, &opts);
            if a.json {
                super::print_json(&mut out, &summary)?;
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
            }
            Ok(ExitCode::SUCCESS)
        }
        Scenario::Serve(a) => super::serve::run(a),
        Scenario::Faults(a) => {
            let outcomes = faults::run(&a.drills, a.seed)?;
            if a.json {
                super::print_json(&mut out, &outcomes)?;
            } else {
                for o in &outcomes {
                    writeln!(
                        out,
                        "  {:<16} motor off: {:<5} latched: {:<5} safe after {} faults: {}",
                        o.name,
                        o.motor_off,
                        o.fault_latched,
                        o.time_to_safe_s
                            .map(|t| format!("{t:.3} s"))
                            .unwrap_or_else(|| "never".into()),
                        o.faults.join(",")
                    )?;
                }
            }
            let all_safe = outcomes.iter().all(|o| o.motor_off && o.fault_latched);
            Ok(if all_safe {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
    }
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
