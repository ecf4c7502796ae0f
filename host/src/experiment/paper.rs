//! The paper's experiments on the in-process virtual rig, in virtual time, run by the
//! procedures ([`super::sweep`], [`super::backdrive`], [`super::hold_release`]) through
//! [`InProcessBench`]: one implementation behind `rig sim torque-sweep|table1|fig5`, `rig demo`
//! and the software-in-the-loop tests, with their results in the shapes those print
//! ([`sim::scenarios`]' `MeasuredRow`, `Table1Row`, `Fig5Result`).

use model::plant::Load;
use sim::scenarios::{fig5, sweep, table1};

use super::{InProcessBench, Operator, Plan, backdrive, hold_release};
use crate::RigError;

/// The virtual rig with gear set `z` and `load` hung, the sensor-noise `seed` and the
/// ACS714 on `sensor_supply_v`.
fn config(
    z: [u32; 4],
    load: Load,
    seed: u64,
    sensor_supply_v: f64,
) -> Result<sim::SimConfig, RigError> {
    let mut config =
        sim::SimConfig::for_gear(z, load).map_err(|source| sim::SimError::Gear { z, source })?;
    config.seed = seed;
    config.plant.sensors.acs_supply = sensor_supply_v;
    Ok(config)
}

/// The required-torque test (Figs. 8-9) as `rig experiment torque-sweep` runs it, with
/// `opts`' gear set, loads, voltages, repeats, window, rest, seed, effects and sensor
/// supply; its rows with the simulator's extra columns (the torque measured by Eqs.
/// (15)-(17) and Eq. (10) at the mean cam speed).
pub fn torque_sweep(opts: &sweep::SweepOptions) -> Result<Vec<sweep::MeasuredRow>, RigError> {
    Ok(torque_sweep_with_error(opts, None)?.0)
}

/// [`torque_sweep`], and the RMS over all points of the firmware's per-revolution tau_cam
/// estimate (the row's `tau_cam_est_nm`) minus the plant's true mean cam torque over the
/// revolutions of the same window, N m, with the PWM ripple, the sensor chain at its
/// tolerances ([`toleranced_sensors`]) and the noise modelled (NaN when a point has no
/// whole revolution to compare with). With `fitted` (a rig file with a fitted `[model]`)
/// the plant runs with its mu and effects ([`sim::preset::apply_model`]).
pub fn torque_sweep_with_error(
    opts: &sweep::SweepOptions,
    fitted: Option<&rigfile::RigFile>,
) -> Result<(Vec<sweep::MeasuredRow>, f64), RigError> {
    use super::sweep as procedure;
    let mut config = config(opts.z, Load::Torque(0.0), opts.seed, opts.sensor_supply_v)?;
    config.plant.effects = opts.effects;
    if let Some(rig) = fitted {
        sim::preset::apply_model(rig, &mut config)?;
    }
    toleranced_sensors(&mut config.plant.sensors);
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
    let window_s = plan.window_s;
    let mut bench = InProcessBench::new(config)?;
    let mut operator = Operator::scripted(b"", false);
    let setup = procedure::SweepSetup {
        plan,
        window: procedure::Window::Start,
        resume: false,
        force: false,
        command: "rig sim torque-sweep".into(),
    };
    let outcome = procedure::run_to(&mut bench, &mut operator, &setup, None, &mut |_| {})?;
    let calibration = model::paper::CALIBRATION;
    // The window ends at the telemetry sample that completes it: one sample of slack.
    let slack = 1.0 / f64::from(procedure::TELEMETRY_HZ);
    let errors: Vec<f64> = outcome
        .rows
        .iter()
        .filter_map(|r| {
            let t_s = r.t_s?;
            let truth = bench.true_cam_torque_nm(t_s, t_s + window_s + slack)?;
            Some(r.tau_cam_est? - truth)
        })
        .collect();
    let estimate_rms_error_nm = if errors.len() == outcome.rows.len() && !errors.is_empty() {
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
    } else {
        f64::NAN
    };
    let points = outcome
        .rows
        .into_iter()
        .map(|r| sweep::MeasuredRow {
            tau_cam_meas: r.i_in.map(|i| calibration.cam_torque(i, r.omega_n)),
            tau_cam_eq10: Some(drive.required_cam_torque(mu, r.tau_rot, r.omega_n)),
            ..r
        })
        .collect();
    Ok((points, estimate_rms_error_nm))
}

/// The board's sensor chain at the ends of its tolerances, for the sweep's estimate
/// error: the current divider at its highest ratio (1 % resistors) and VDDA 1.5 % low
/// (the firmware measures it through VREFINT). The ACS714's own sensitivity and offset
/// errors are not added: the rig's calibration (Eqs. 15-17) is measured through the same
/// sensor and absorbs them, whereas the simulated rig boots with Table 2 as its truth.
pub fn toleranced_sensors(sensors: &mut model::plant::SensorParams) {
    sensors.divider = model::hardware::divider::ratio_bounds().1;
    sensors.adc_reference *= 0.985;
}

/// Table 1 as `rig experiment backdrive` runs it, once per gear set of `sets` on a fresh
/// virtual rig with that set and `effects` in its plant (a preset's: [`sim::Preset`]), at
/// [`table1::TAU_ROT`], released at `hz`.
pub fn table1(
    sets: &[[u32; 4]],
    hz: f64,
    seed: u64,
    effects: model::plant::PlantEffects,
) -> Result<Vec<table1::Table1Row>, RigError> {
    table1_fitted(sets, hz, seed, effects, None)
}

/// [`table1()`], the plant running with `fitted`'s mu and effects when given (a rig file with
/// a fitted `[model]`, [`sim::preset::apply_model`]).
pub fn table1_fitted(
    sets: &[[u32; 4]],
    hz: f64,
    seed: u64,
    effects: model::plant::PlantEffects,
    fitted: Option<&rigfile::RigFile>,
) -> Result<Vec<table1::Table1Row>, RigError> {
    let opts = backdrive::Backdrive {
        load_nm: table1::TAU_ROT,
        hz,
        ..Default::default()
    };
    let mut rows = Vec::new();
    // A designed gear (`--model DESIGN.toml`) is the one row.
    let design = designed_gear(fitted)?;
    let design_z = design.map(|g| [g.z()]);
    let sets = design_z.as_ref().map_or(sets, |z| z.as_slice());
    for &z in sets {
        let mut config = config(
            if design.is_some() {
                model::paper::RIG_Z
            } else {
                z
            },
            Load::Torque(0.0),
            seed,
            model::hardware::acs714::SUPPLY_NOMINAL_V,
        )?;
        if let Some(gear) = design {
            use_gear(&mut config, gear);
        }
        config.plant.effects = effects;
        if let Some(rig) = fitted {
            sim::preset::apply_model(rig, &mut config)?;
        }
        let gear = config.plant.drive.gear;
        let mut bench = InProcessBench::new(config)?;
        let mut operator = Operator::scripted(b"", false);
        let Some(v) = backdrive::run(&mut bench, &mut operator, &opts, Some(z))? else {
            continue;
        };
        // Eq. (4) with the paper's mu_s: n = 1 for the Table 1 rows, as the paper found.
        let paper_non_backdriven_point = gear.holds(model::paper::MU_S);
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

/// Fig. 5 as `rig experiment hold-release` runs it, on a virtual rig with Fig. 5's gear set
/// and its 1.0 kg mass on 75 mm.
pub fn fig5(opts: &fig5::Fig5Options) -> Result<fig5::Fig5Result, RigError> {
    fig5_fitted(opts, None)
}

/// [`fig5()`], the plant running with `fitted`'s mu and effects when given (a rig file with a
/// fitted `[model]`, [`sim::preset::apply_model`]).
pub fn fig5_fitted(
    opts: &fig5::Fig5Options,
    fitted: Option<&rigfile::RigFile>,
) -> Result<fig5::Fig5Result, RigError> {
    fig5_history(opts, fitted).map(|(result, _)| result)
}

/// [`fig5_fitted`] with its time history (for the Fig. 5 plot).
pub fn fig5_history(
    opts: &fig5::Fig5Options,
    fitted: Option<&rigfile::RigFile>,
) -> Result<(fig5::Fig5Result, Vec<hold_release::Sample>), RigError> {
    let z = model::paper::FIG5_Z;
    let mut config = config(z, model::paper::FIG5_LOAD, opts.seed, opts.sensor_supply_v)?;
    config.plant.effects = opts.effects;
    if let Some(gear) = designed_gear(fitted)? {
        use_gear(&mut config, gear);
    }
    if let Some(rig) = fitted {
        sim::preset::apply_model(rig, &mut config)?;
    }
    let z = config.plant.drive.gear.z();
    let x = config.plant.drive.gear.shift();
    let mu_d_lambda = config.plant.mu_d * config.plant.drive.gear.big_lambda();
    let mut bench = InProcessBench::new(config)?;
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
    let result = fig5::Fig5Result {
        z,
        held_without_vibration: n.held_without_vibration,
        hold_s: opts.hold_s,
        release_to_motion_s: n.release_to_motion_s,
        output_speed_after_stop_rad_s: n.output_speed_after_stop_rad_s,
        output_speed_at_stop_rad_s: n.output_speed_at_stop_rad_s,
        load_drop_m: n.load_drop_m,
        mu_d_lambda,
        stops_after_vibration: n.stops_after_vibration,
        after_stop_travel_rad: n.after_stop_travel_rad,
        x,
    };
    Ok((result, samples))
}

/// The gear set a rig file designs: its `[gear]` when that is not the paper's standard
/// (49, 51, 50, 50) set every rig file carries by default (a `rig design search --write`
/// file); `None` otherwise, and the scenario keeps its own gear.
fn designed_gear(fitted: Option<&rigfile::RigFile>) -> Result<Option<model::GearSet>, RigError> {
    let Some(rig) = fitted else {
        return Ok(None);
    };
    let gear = rig.gear_set()?;
    Ok((gear != model::paper::RIG_GEARS).then_some(gear))
}

/// Builds the virtual rig around `gear`: the plant's gear and the stored record's tooth
/// counts, module, pressure angle and profile shifts (protocol v7), so the firmware's
/// Lambda is the shifted gear's.
fn use_gear(config: &mut sim::SimConfig, gear: model::GearSet) {
    config.plant.drive.gear = gear;
    config.calibration.z = gear.z().map(|v| u16::try_from(v).unwrap_or(u16::MAX));
    #[allow(clippy::cast_possible_truncation, reason = "mm and degrees fit f32")]
    {
        config.calibration.module_mm = (gear.module() * 1e3) as f32;
        config.calibration.pressure_angle_deg = gear.pressure_angle().to_degrees() as f32;
        config.calibration.profile_shift = gear.shift().map(|x| x as f32);
    }
}
