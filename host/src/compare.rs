//! The simulation-versus-measurement gap behind `rig compare`, before and after a fitted
//! effect. Replays a measured sweep's test plan (its rows in the order they were run: loads,
//! supply voltages or vibration frequencies, the motor temperatures as logged) on the
//! in-process virtual rig, once with the base model (the rig file's rig, the paper's
//! equations) and once with a fitted `[model]` (`rig explain --write-model`), through the
//! same torque-sweep procedure as `rig experiment`, and reports the gap, measured minus
//! simulated mean current per test point, with a plot of both.
//!
//! Cost: each tested cell (load and drive: supply voltage, or frequency) is replayed once,
//! however many rows repeat it and whatever motor temperatures they logged, so the replay
//! grows with the cells, not the rows. The temperature enters the model through the torque
//! constant alone (a fitted `thermal-drift`: k_t (1 - k (T - T_cal))); the mean current
//! carries the mean torque, so a row logged at T has the cell's replayed current times
//! k_t(T_replay) / k_t(T). The winding's resistance, which the temperature also changes,
//! sets the open-loop speed rather than the mean current (to first order) and is the
//! replay's own. The base model has no thermal drift: its currents do not depend on T.

use std::path::Path;

use serde::Serialize;

use crate::RigError;
use crate::experiment::plan::{DriveMode, Order, Plan, PlanPoint};
use crate::experiment::sweep::{SweepSetup, Window};
use crate::experiment::{InProcessBench, Operator, sweep};
use explain::data::Dataset;
use rigfile::RigFile;

/// What `rig compare` calls the gap.
pub const GAP_DEFINITION: &str = "measured minus simulated mean current per test point, the measured plan replayed on the virtual rig as a prediction (over whole cam revolutions, its current zero measured over 10 s) (base: the rig file's own mu and calibration, nothing fitted); rig explain's rmse_before_a is the residual of the paper's model with mu fitted to the same data, so it is smaller";

/// One test point of the comparison.
#[derive(Debug, Clone, Serialize)]
pub struct GapRow {
    /// Data row (1-based, as the file's data rows are counted).
    pub row: usize,
    /// Load, N m.
    pub tau_rot_nm: f64,
    /// Supply voltage (open loop), V.
    pub v_in_v: Option<f64>,
    /// Vibration frequency (closed loop, from the measured cam speed), Hz.
    pub hz: Option<f64>,
    /// Logged motor temperature, deg C (the simulated currents are at it: see the module's
    /// documentation).
    pub temp_c: Option<f64>,
    /// Measured mean current, A.
    pub measured_a: f64,
    /// Simulated with the base model, A.
    pub base_a: f64,
    /// Simulated with the fitted model, A (null without --model).
    pub model_a: Option<f64>,
    /// Measured minus base, A.
    pub gap_base_a: f64,
    /// Measured minus fitted model, A.
    pub gap_model_a: Option<f64>,
}

/// What `rig compare --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// The measured file.
    pub measured: String,
    /// The fitted model file.
    pub model: Option<String>,
    /// Effects of the fitted model, then its `[[model.terms]]` as `name (form)`.
    pub model_effects: Vec<String>,
    /// Test points replayed (rows with a current that the virtual rig could run).
    pub points: usize,
    /// Data rows (1-based) the virtual rig could not run (a load above the rig file's
    /// `max_release_load_nm`, a point its protections skipped): left out of every gap.
    pub skipped_rows: Vec<usize>,
    /// Which gap this is, in words: `rig explain`'s `rmse_before_a` is another one (the
    /// residual of the paper's model with mu fitted to the data, not replayed).
    pub gap_definition: &'static str,
    /// RMS of measured minus base-model current, A.
    pub gap_rmse_base_a: f64,
    /// RMS of measured minus fitted-model current, A (null without --model).
    pub gap_rmse_model_a: Option<f64>,
    /// gap_rmse_model_a / gap_rmse_base_a.
    pub gap_ratio: Option<f64>,
    /// Mean gap with the base model, A.
    pub gap_mean_base_a: f64,
    /// Mean gap with the fitted model, A.
    pub gap_mean_model_a: Option<f64>,
    /// The plot, when written.
    pub svg: Option<String>,
    /// The plot in `--format` (PNG or PDF beside the SVG), when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub figure: Option<String>,
    /// Per test point.
    pub rows: Vec<GapRow>,
    /// Test points the virtual rigs ran, both models together: the replay's cost (each
    /// tested cell once per model, whatever the rows).
    #[serde(skip)]
    pub replays: usize,
}

/// The replayed plan of `data`: each tested cell (load and drive) once, in the order first
/// run, so the replay's cost grows with the cells, not the rows (a 2,000-row file of
/// repeats, or of rows each at its own temperature, replays its grid once); then the rows
/// with a current in the order they were run, and each one's cell (its plan point). The
/// cells set no temperature: the replay runs at its winding's own and each row's logged
/// temperature is applied afterwards ([`at_temperature`]).
#[allow(clippy::type_complexity, reason = "a private helper's three results")]
fn replay_plan(
    data: &Dataset,
    header: &HeaderPlan,
) -> Result<(Plan, Vec<usize>, Vec<usize>), RigError> {
    let mut order: Vec<usize> = (0..data.len())
        .filter(|&k| data.i_in()[k].is_finite())
        .collect();
    if let Some(t) = data.t_s() {
        order.sort_by(|&a, &b| t[a].total_cmp(&t[b]));
    }
    if order.is_empty() {
        return Err(RigError::BadValue {
            what: format!("--measured {}", data.name),
            why: "no row has a current (i_in_a): nothing to compare".into(),
        });
    }
    let volts = data.v_in();
    let mode = if volts.is_some() {
        DriveMode::OpenLoop
    } else {
        DriveMode::ClosedLoop
    };
    let point = |k: usize| PlanPoint {
        load_nm: data.tau_rot()[k].abs(),
        volts: volts.map(|v| v[k]),
        hz: volts
            .is_none()
            .then(|| data.omega_n()[k] / (2.0 * std::f64::consts::PI)),
        repeats: None,
        duration_s: None,
        temp_c: None,
    };
    let mut points: Vec<PlanPoint> = Vec::new();
    let mut cell_of = std::collections::HashMap::new();
    let cells: Vec<usize> = order
        .iter()
        .map(|&k| {
            let p = point(k);
            let key = (
                p.load_nm.to_bits(),
                p.volts.map(f64::to_bits),
                p.hz.map(f64::to_bits),
            );
            *cell_of.entry(key).or_insert_with(|| {
                points.push(p);
                points.len() - 1
            })
        })
        .collect();
    let plan = Plan {
        name: format!("replay of {}", data.name),
        mode,
        repeats: 1,
        order: Order::AsListed,
        seed: 1,
        rest_s: header.rest_s.unwrap_or(2.0),
        window_s: header.window_s.unwrap_or(model::paper::CURRENT_AVERAGING_S),
        reason: String::new(),
        points,
    };
    plan.check("replay")?;
    Ok((plan, order, cells))
}

/// What the measured file's provenance says about its plan.
#[derive(Debug, Default)]
struct HeaderPlan {
    rest_s: Option<f64>,
    window_s: Option<f64>,
}

fn header_plan(path: &Path) -> HeaderPlan {
    let plan = crate::provenance::Header::read(path).plan();
    HeaderPlan {
        rest_s: plan.as_ref().map(|p| p.rest_s),
        window_s: plan.as_ref().map(|p| p.window_s),
    }
}

/// Mean currents of `plan` run on the in-process virtual rig of `config`, one per plan
/// point in plan order: `None` for a point the virtual rig did not measure (a load above
/// the rig's `max_release_load_nm`, a point its protections skipped), as the measuring
/// sensor reads them (with the plant's `current_offset`).
pub fn simulate(config: sim::SimConfig, plan: &Plan) -> Result<Vec<Option<f64>>, RigError> {
    Ok(replay(config, plan)?
        .points
        .into_iter()
        .map(|p| p.map(|p| p.current_a))
        .collect())
}

/// One plan point as the virtual rig ran it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Replayed {
    /// Mean current as the measuring sensor reads it, A.
    pub current_a: f64,
    /// The replay's winding temperature over the point, deg C.
    pub temp_c: Option<f64>,
    /// The sensor offset included in `current_a`, A.
    sensor_offset_a: f64,
}

/// What one virtual rig made of a replayed plan.
#[derive(Debug, Clone)]
pub struct Replay {
    /// Per plan point, in plan order (`None`: not measured, as [`simulate`]).
    pub points: Vec<Option<Replayed>>,
    /// Test points the virtual rig ran (the plan's runs).
    pub runs: usize,
    /// The plant's thermal law: its effects and the calibration temperature.
    thermal: (model::plant::PlantEffects, f64),
}

impl Replay {
    /// The current of `point` at winding temperature `temp_c` ([`at_temperature`]).
    fn current_at(&self, point: &Replayed, temp_c: Option<f64>) -> f64 {
        at_temperature(point, temp_c, &self.thermal.0, self.thermal.1)
    }
}

/// The replayed current of `point` for a row logged at `temp_c`: the torque constant's
/// factor at the replay's temperature over the one at the row's (1 for a plant without
/// thermal drift, or when either temperature is unknown); the sensor offset is not scaled.
pub fn at_temperature(
    point: &Replayed,
    temp_c: Option<f64>,
    effects: &model::plant::PlantEffects,
    ambient_c: f64,
) -> f64 {
    let (Some(row), Some(ran)) = (temp_c.filter(|t| t.is_finite()), point.temp_c) else {
        return point.current_a;
    };
    let factor = effects.torque_constant_factor(ran, ambient_c)
        / effects.torque_constant_factor(row, ambient_c);
    (point.current_a - point.sensor_offset_a) * factor + point.sensor_offset_a
}

/// [`simulate`], with each point's winding temperature and the count of runs.
pub fn replay(config: sim::SimConfig, plan: &Plan) -> Result<Replay, RigError> {
    // The replay reads the board's current (telemetry); a fitted `current-sensor-offset` is
    // the measuring sensor's (the plant adds it to the logger only), so it is added here.
    let sensor_offset = config.plant.effects.current_offset;
    let thermal = (config.plant.effects, config.plant.motor.ambient_c);
    // The board measures its current zero first (ADC samples at ADC_HZ, motor off); the
    // plan starts once it has (a long zero, as `virtual_rig`'s, outlasts the sweep's
    // spin-up limit).
    let zero_s = f64::from(config.core.current.zero_samples) / f64::from(sim::ADC_HZ);
    let mut bench = InProcessBench::new(config)?;
    sim::RigLink::wait(&mut bench, zero_s)?;
    let mut operator = Operator::scripted(b"", false);
    let setup = SweepSetup {
        plan: plan.clone(),
        // Whole revolutions: a window that ends within a cam turn weights the turn's
        // friction ripple by where it ends, a scatter of several mA at 3.6 V and heavy
        // loads that differs from run to run. The measured rows carry their own draw of
        // it; the replay, a prediction, takes its mean.
        window: Window::Revolutions,
        resume: false,
        force: false,
        command: "rig compare".into(),
    };
    let outcome = sweep::run_to(&mut bench, &mut operator, &setup, None, &mut |_| {})?;
    let mut points = vec![None; plan.points.len()];
    for r in &outcome.rows {
        if let (Some(slot), Some(i)) = (r.point.and_then(|p| points.get_mut(p)), r.i_in) {
            *slot = Some(Replayed {
                current_a: i + sensor_offset,
                temp_c: r.temp_c.filter(|t| t.is_finite()),
                sensor_offset_a: sensor_offset,
            });
        }
    }
    Ok(Replay {
        points,
        runs: outcome.planned,
        thermal,
    })
}

/// The virtual rig of `rig` with its fitted `[model]` running in the plant (or none).
pub fn virtual_rig(rig: &RigFile, with_model: bool, seed: u64) -> Result<sim::SimConfig, RigError> {
    let mut base = rig.clone();
    if !with_model {
        base.model = None;
    }
    let mut config = sim::SimConfig::from_rig_file(&base)?.virtual_board();
    // A prediction, not a second measurement: the firmware zeroes the current sensor over
    // 1,000 samples at boot, which leaves a zero error of about 1 mA (the sensor's noise)
    // that shifts every replayed point alike and differs with the seed. The replay's board
    // zeroes over a hundred times as many (10 s of virtual time): 0.1 mA.
    config.core.current.zero_samples = config.core.current.zero_samples.saturating_mul(100);
    if with_model {
        sim::preset::apply_model(&base, &mut config)?;
    }
    config.seed = seed;
    Ok(config)
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x * x;
        n += 1;
    }
    (s / n.max(1) as f64).sqrt()
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in v {
        s += x;
        n += 1;
    }
    s / n.max(1) as f64
}

/// Compares `measured` with the base model of `base_rig` and, when given, the fitted
/// `model_rig`.
pub fn compare(
    measured: &Path,
    base_rig: &RigFile,
    model_rig: Option<&RigFile>,
    seed: u64,
) -> Result<Comparison, RigError> {
    let data = Dataset::read_csv(measured)?;
    let (plan, order, cells) = replay_plan(&data, &header_plan(measured))?;
    let base = replay(virtual_rig(base_rig, false, seed)?, &plan)?;
    let fitted = match model_rig {
        Some(m) => Some(replay(virtual_rig(m, true, seed)?, &plan)?),
        None => None,
    };
    let replays = base.runs + fitted.as_ref().map_or(0, |f| f.runs);
    let (rows, skipped_rows) = gap_rows(&data, &order, &cells, &plan, &base, fitted.as_ref());
    if rows.is_empty() {
        return Err(RigError::BadValue {
            what: format!("--measured {}", measured.display()),
            why: format!(
                "the virtual rig could run none of its {} test points (every load above the rig file's max_release_load_nm, or beyond the board's limits): compare with a rig file whose limits cover the measured loads (--rig)",
                order.len()
            ),
        });
    }
    let gap_rmse_base_a = rms(rows.iter().map(|r| r.gap_base_a));
    let gap_rmse_model_a = fitted
        .as_ref()
        .map(|_| rms(rows.iter().filter_map(|r| r.gap_model_a)));
    Ok(Comparison {
        measured: measured.display().to_string(),
        model: None,
        model_effects: model_rig
            .and_then(|m| m.model.as_ref())
            .map(|m| {
                // Its effects, then its `[[model.terms]]` as `name (form)`: the plant runs both.
                let terms = m.terms.iter().map(|t| match &t.form {
                    Some(f) => format!("{} ({f})", t.name),
                    None => t.name.clone(),
                });
                m.effects
                    .iter()
                    .map(|e| e.name.clone())
                    .chain(terms)
                    .collect()
            })
            .unwrap_or_default(),
        points: rows.len(),
        skipped_rows,
        gap_definition: GAP_DEFINITION,
        gap_rmse_base_a,
        gap_rmse_model_a,
        gap_ratio: gap_rmse_model_a.map(|m| m / gap_rmse_base_a.max(1e-12)),
        gap_mean_base_a: mean(rows.iter().map(|r| r.gap_base_a)),
        gap_mean_model_a: fitted
            .as_ref()
            .map(|_| mean(rows.iter().filter_map(|r| r.gap_model_a))),
        svg: None,
        figure: None,
        rows,
        replays,
    })
}

/// The gap per replayed point (`base`, `fitted`: the replays, `None` points where the
/// virtual rig did not run them), each simulated current at the row's logged temperature,
/// and the data rows (1-based) left out because either virtual rig could not run them.
fn gap_rows(
    data: &Dataset,
    order: &[usize],
    cells: &[usize],
    plan: &Plan,
    base: &Replay,
    fitted: Option<&Replay>,
) -> (Vec<GapRow>, Vec<usize>) {
    let mut skipped_rows = Vec::new();
    let temps = data.temp_c();
    let rows = order
        .iter()
        .enumerate()
        .filter_map(|(n, &k)| {
            let j = cells[n];
            let measured_a = data.i_in()[k];
            let temp_c = temps.map(|t| t[k]).filter(|t| t.is_finite());
            let at = |r: &Replay| {
                r.points
                    .get(j)
                    .copied()
                    .flatten()
                    .map(|p| r.current_at(&p, temp_c))
            };
            let base_a = at(base);
            let model_a = fitted.map(at);
            let (Some(base_a), None | Some(Some(_))) = (base_a, model_a) else {
                skipped_rows.push(k + 1);
                return None;
            };
            let model_a = model_a.flatten();
            let p = &plan.points[j];
            Some(GapRow {
                row: k + 1,
                tau_rot_nm: data.tau_rot()[k],
                v_in_v: p.volts,
                hz: p.hz,
                temp_c,
                measured_a,
                base_a,
                model_a,
                gap_base_a: measured_a - base_a,
                gap_model_a: model_a.map(|m| measured_a - m),
            })
        })
        .collect();
    (rows, skipped_rows)
}

/// Plots both gaps per test point (in run order) to `path`, printed at `size`.
pub fn gap_figure(
    path: &Path,
    c: &Comparison,
    size: reporting::figure::FigureSize,
) -> Result<(), RigError> {
    use reporting::plot::{Legend, PALETTE, Series, XyPanel, axis_label, columns_figure};
    let mut series = vec![
        Series::points(
            PALETTE[0],
            3,
            c.rows
                .iter()
                .enumerate()
                .map(|(j, r)| ((j + 1) as f64, r.gap_base_a * 1e3))
                .collect(),
        )
        .labelled("base model"),
    ];
    // Short legend entries beside the plot; the numbers and the effects in the caption.
    let mut caption = format!(
        "measured − simulated mean current: rms {:.1} mA with the base model",
        c.gap_rmse_base_a * 1e3
    );
    if let Some(m) = c.gap_rmse_model_a {
        series.push(
            Series::points(
                PALETTE[1],
                3,
                c.rows
                    .iter()
                    .enumerate()
                    .filter_map(|(j, r)| Some(((j + 1) as f64, r.gap_model_a? * 1e3)))
                    .collect(),
            )
            .labelled("fitted model"),
        );
        caption += &format!(
            ", {:.1} mA with {}",
            m * 1e3,
            if c.model_effects.is_empty() {
                "the fitted model".to_string()
            } else {
                c.model_effects.join(", ")
            }
        );
    }
    let panel = XyPanel {
        caption: Some(caption),
        x_label: axis_label("test point (run order)", ""),
        y_label: axis_label("measured − simulated", "mA"),
        series,
        include_zero_y: true,
        // Below the plot: inside it covered points.
        legend: Some(Legend::Below),
        whole_x: true,
        ..XyPanel::default()
    };
    // The title promises the fitted model's gaps only when they are drawn.
    let title = if c.gap_rmse_model_a.is_some() {
        "Simulation versus measurement, before and after the fitted effect"
    } else {
        "Simulation versus measurement: the base model"
    };
    columns_figure(path, size, (900, 480), Some(title), &[panel])?;
    Ok(())
}

#[cfg(test)]
mod gap_tests {
    use super::*;

    /// A replay of these currents (A, per plan point) at `temp_c`, on a plant with thermal
    /// drift `k` (1/K) calibrated at 25 deg C.
    fn replay_of(currents: &[Option<f64>], temp_c: f64, k: Option<f64>) -> Replay {
        Replay {
            points: currents
                .iter()
                .map(|c| {
                    c.map(|current_a| Replayed {
                        current_a,
                        temp_c: Some(temp_c),
                        sensor_offset_a: 0.0,
                    })
                })
                .collect(),
            runs: currents.len(),
            thermal: (
                model::plant::PlantEffects {
                    thermal_drift: k,
                    ..Default::default()
                },
                25.0,
            ),
        }
    }

    /// A point the virtual rig skipped (a load above its `max_release_load_nm`: the sweep
    /// writes no row for it) is left out of both gaps and listed, where the replay used to
    /// index past the simulated rows and panic.
    #[test]
    fn a_point_the_virtual_rig_skipped_is_listed_not_indexed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.csv");
        let mut text = String::from("omega_n_rad_s,tau_rot_nm,i_in_a\n");
        for (k, load) in [0.4, 0.8, 5.0, 1.2, 1.6, 2.0, 2.4, 2.8, 3.2, 3.6]
            .iter()
            .enumerate()
        {
            text.push_str(&format!("62.8,{load},{}\n", 2.6 + 0.01 * k as f64));
        }
        std::fs::write(&path, text).unwrap();
        let data = Dataset::read_csv(&path).unwrap();
        let (plan, order, cells) = replay_plan(&data, &HeaderPlan::default()).unwrap();
        // The sweep ran every point but the third.
        let base: Vec<Option<f64>> = (0..plan.points.len())
            .map(|j| (j != 2).then_some(2.5))
            .collect();
        let base = replay_of(&base, 25.0, None);
        let (rows, skipped) = gap_rows(&data, &order, &cells, &plan, &base, None);
        assert_eq!(skipped, [3]);
        assert_eq!(rows.len(), 9);
        assert!(rows.iter().all(|r| r.row != 3));
        // The fitted model's skips count too.
        let fitted: Vec<Option<f64>> = (0..plan.points.len())
            .map(|j| (j != 5).then_some(2.55))
            .collect();
        let fitted = replay_of(&fitted, 25.0, None);
        let (rows, skipped) = gap_rows(&data, &order, &cells, &plan, &base, Some(&fitted));
        assert_eq!(skipped, [3, 6]);
        assert_eq!(rows.len(), 8);
        assert!(rows.iter().all(|r| r.gap_model_a.is_some()));
    }

    /// Issue 33: the replay grew faster than the rows (1,000 rows 21 s, 2,000 rows 59 s),
    /// and rows each at its own temperature made a cell each (2,000 rows, ~150 cells,
    /// 148 s): each (load, drive) cell is replayed once, whatever the temperatures, and a
    /// fitted thermal drift is applied at each row's logged temperature.
    #[test]
    fn repeats_of_a_cell_are_replayed_once_at_any_temperature() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.csv");
        let mut text = String::from("t_s,v_in_v,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c\n");
        for k in 0..2000 {
            let load = [0.368, 0.736, 1.104][k % 3];
            // Every row its own temperature: 25.00 to 74.975 deg C.
            let temp = 25.0 + 0.025 * k as f64;
            text.push_str(&format!(
                "{k},3.6,30.0,{load},{},{temp}\n",
                2.6 + 1e-4 * k as f64
            ));
        }
        std::fs::write(&path, text).unwrap();
        let data = Dataset::read_csv(&path).unwrap();
        let (plan, order, cells) = replay_plan(&data, &HeaderPlan::default()).unwrap();
        assert_eq!(plan.points.len(), 3, "three (load, drive) cells");
        assert!(plan.points.iter().all(|p| p.temp_c.is_none()));
        assert_eq!((order.len(), cells.len()), (2000, 2000));
        assert!(cells.iter().enumerate().all(|(n, &c)| c == n % 3));
        let base = replay_of(&[Some(2.5); 3], 25.0, None);
        let (rows, skipped) = gap_rows(&data, &order, &cells, &plan, &base, None);
        assert!(skipped.is_empty());
        assert_eq!(rows.len(), 2000);
        // Without thermal drift the current does not depend on the temperature.
        assert!((rows[1999].gap_base_a - (2.6 + 0.1999 - 2.5)).abs() < 1e-9);
        assert!((rows[1999].temp_c.unwrap() - 74.975).abs() < 1e-9);
        // With k = 0.004/K, a row 50 K above the replay's 25 deg C needs 1 / (1 - 0.2) of
        // the current for the same torque.
        let fitted = replay_of(&[Some(2.5); 3], 25.0, Some(0.004));
        let (rows, _) = gap_rows(&data, &order, &cells, &plan, &base, Some(&fitted));
        let want = 2.5 / (1.0 - 0.004 * (74.975 - 25.0));
        assert!(
            (rows[1999].model_a.unwrap() - want).abs() < 1e-9,
            "{rows:?}"
        );
        assert!((rows[0].model_a.unwrap() - 2.5).abs() < 1e-12);
    }

    /// The whole replay on 2,000 rows each at its own temperature: the virtual rigs run
    /// each (load, drive) cell once per model, counted by the comparison's `replays`.
    #[test]
    fn a_compare_of_2000_rows_at_distinct_temperatures_replays_each_cell_once() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.csv");
        let mut text = String::from("t_s,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c\n");
        for k in 0..2000 {
            let load = [0.368, 0.736][k % 2];
            let temp = 25.0 + 0.0173 * k as f64;
            text.push_str(&format!("{k},62.83185307179586,{load},2.6,{temp}\n"));
        }
        std::fs::write(&path, text).unwrap();
        let base = RigFile::paper();
        let fitted = base.with_model(
            0.2,
            vec![rigfile::EffectEntry {
                name: "thermal-drift".into(),
                params: [("k_per_c".to_string(), 0.004)].into(),
            }],
        );
        let c = compare(&path, &base, Some(&fitted), 1).unwrap();
        assert_eq!(c.points, 2000, "{:?}", c.skipped_rows);
        assert_eq!(c.replays, 4, "two cells, once per model");
        // The fitted drift at each row's temperature: warmer rows need more current.
        let (cool, warm) = (&c.rows[0], &c.rows[1998]);
        assert_eq!(cool.tau_rot_nm, warm.tau_rot_nm);
        assert!(warm.model_a.unwrap() > cool.model_a.unwrap());
        assert!(
            (warm.base_a - cool.base_a).abs() < 1e-12,
            "no drift in the base model"
        );
    }

    /// Absurd loads are refused by the plan's range before anything runs.
    #[test]
    fn absurd_loads_are_refused_before_replaying() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.csv");
        let mut text = String::from("omega_n_rad_s,tau_rot_nm,i_in_a\n");
        for k in 0..12 {
            let load = if k == 4 { -1e300 } else { 0.4 };
            text.push_str(&format!("62.8,{load},2.6\n"));
        }
        std::fs::write(&path, text).unwrap();
        let data = Dataset::read_csv(&path).unwrap();
        let e = replay_plan(&data, &HeaderPlan::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("load_nm"), "{e}");
    }
}
