//! Synthetic torque sweeps like the paper's (loads 0.368-3.68 N m, 3.6 / 6.2 / 8.8 V, five
//! repeats) from the current model with one hidden effect, for tests, the benchmark and
//! `rig explain --synthetic`.
//!
//! A bench session: the tests run in random order, 15-25 s each (about 50 minutes for 150
//! tests); the motor warms from ambient towards ambient + 20 C with a 20-minute time
//! constant; the cam slows a little under load; the current is the 0.5 s mean with
//! ACS714-like noise (10-30 mA). Non-backdriven rows (the linear bush) keep their current:
//! the cam still shakes the carrier against the loaded teeth.

use std::f64::consts::PI;

use model::effects::{self, CurrentModel, Effect, EffectParams, ISO_LOAD_EXPONENT, OperatingPoint};
use model::plant::NoiseSource;

use super::data::MeasuredRow;

/// How a synthetic sweep is run.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepPlan {
    /// Load torques, N m.
    pub loads_nm: Vec<f64>,
    /// Vibrator voltages, V.
    pub voltages_v: Vec<f64>,
    /// Repeats of every (load, voltage) test.
    pub repeats: usize,
    /// Standard deviation of the current noise, A.
    pub noise_a: f64,
    /// Shortest and longest duration of one test, s.
    pub test_seconds: (f64, f64),
    /// Ambient temperature, deg C.
    pub ambient_c: f64,
    /// Temperature rise of the motor over a long session, K.
    pub temp_rise_c: f64,
    /// Thermal time constant of the motor, s.
    pub temp_time_constant_s: f64,
    /// Relative drop of the cam speed at the largest load.
    pub speed_droop: f64,
    /// Write the `t_s` column.
    pub with_time: bool,
    /// Write the `temp_c` column.
    pub with_temperature: bool,
    /// Write the `v_in_v` column.
    pub with_voltage: bool,
    /// Write the `backdriven` column.
    pub with_backdriven: bool,
}

impl Default for SweepPlan {
    /// The paper's sweep: ten loads 0.368..3.68 N m, 3.6 / 6.2 / 8.8 V, five repeats, 20 mA
    /// noise, every optional column.
    fn default() -> Self {
        Self {
            loads_nm: (1..=10)
                .map(|k| model::paper::TAU_ROT_MIN_TESTED * k as f64)
                .collect(),
            voltages_v: model::paper::SUPPLY_VOLTAGES.to_vec(),
            repeats: model::paper::REQUIRED_TORQUE_REPEATS as usize,
            noise_a: 0.020,
            test_seconds: (15.0, 25.0),
            ambient_c: 25.0,
            temp_rise_c: 20.0,
            temp_time_constant_s: 1200.0,
            speed_droop: 0.04,
            with_time: true,
            with_temperature: true,
            with_voltage: true,
            with_backdriven: true,
        }
    }
}

/// Nominal cam speed at vibrator voltage `v_in`, rad/s: 3.6 / 6.2 / 8.8 V give about
/// 5 / 10 / 15 Hz (the paper), linear in between.
pub fn nominal_cam_speed(v_in: f64) -> f64 {
    2.0 * PI * (5.0 + (v_in - 3.6) * 5.0 / 2.6).max(0.5)
}

fn uniform(rng: &mut NoiseSource, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.uniform()
}

fn signed(rng: &mut NoiseSource, lo: f64, hi: f64) -> f64 {
    let v = uniform(rng, lo, hi);
    if rng.uniform() < 0.5 { -v } else { v }
}

/// Parameters of `effect` drawn over a plausible range for the rig of `model` under `plan`
/// (the other effects zero). The ranges:
/// - speed-dependent-axial-friction: w_c 12-30 rad/s (mu_ax / mu 0.72-0.93 at 5 Hz);
/// - load-dependent-friction: exponent +-(0.12-0.3) (seed 003's average friction: +0.2);
/// - current-sensor-offset: +-(30-80) mA (an ACS714 zero error of 6-15 mV);
/// - thermal-drift: k 1.5-4 per mille per K (ferrite magnets lose about 2 per mille per K);
/// - vibrator-viscous-loss: c_v 0.06-0.25 N mm s/rad (25-100 % of C3);
/// - inertia-rectification: kappa -1..-0.4 (regenerating drive) or 0.4..1 (rectified);
/// - linear-bush-friction: F_b 2-8 N, holding 0.42-0.7 N m at the lowest speed;
/// - tooth-compliance: a 6-15 % shorter stroke at the largest load;
/// - mesh-load-sharing-ripple: 5-10 % rms scatter of the friction term.
pub fn plausible_effect(
    effect: Effect,
    model: &CurrentModel,
    plan: &SweepPlan,
    rng: &mut NoiseSource,
) -> EffectParams {
    let mut p = EffectParams::default();
    match effect {
        Effect::SpeedDependentAxialFriction => p.axial_corner_speed = uniform(rng, 12.0, 30.0),
        Effect::LoadDependentFriction => p.load_exponent = signed(rng, 0.12, 0.3),
        Effect::CurrentSensorOffset => p.current_offset = signed(rng, 0.03, 0.08),
        Effect::ThermalDrift => p.thermal_coeff = uniform(rng, 1.5e-3, 4e-3),
        Effect::VibratorViscousLoss => p.viscous_loss = uniform(rng, 0.06e-3, 0.25e-3),
        Effect::InertiaRectification => {
            p.rectification = if rng.uniform() < 0.5 {
                uniform(rng, -1.0, -0.4)
            } else {
                uniform(rng, 0.4, 1.0)
            }
        }
        Effect::LinearBushFriction => {
            p.bush_force = uniform(rng, 2.0, 8.0);
            p.bush_corner_speed = uniform(rng, 30.0, 80.0);
            let w_lo = plan
                .voltages_v
                .iter()
                .map(|&v| nominal_cam_speed(v))
                .fold(f64::INFINITY, f64::min);
            let at_lowest = uniform(rng, 0.42, 0.7);
            p.bush_hold_torque = at_lowest * (1.0 + w_lo / p.bush_corner_speed);
        }
        Effect::ToothCompliance => {
            let tau_max = plan.loads_nm.iter().fold(0.0f64, |m, t| m.max(t.abs()));
            let f_max = model.drive.friction_force(model.mu, tau_max).max(1e-9);
            p.tooth_compliance = uniform(rng, 0.06, 0.15) * model.drive.eccentricity / f_max;
        }
        Effect::MeshLoadSharingRipple => p.mesh_ripple_rms = uniform(rng, 0.05, 0.10),
    }
    p
}

/// The order of the tests in a bench session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TestOrder {
    /// Every test of every repeat in random order (the paper's advice).
    #[default]
    Shuffled,
    /// As a sweep is often run by hand: voltage after voltage, loads rising, the whole sweep
    /// repeated (time, and so the motor's warm-up, runs with load and speed).
    Ascending,
    /// Voltage after voltage, the loads of each voltage in random order, repeated.
    ShuffledWithinVoltage,
}

/// How a bench session runs its tests: their order and the rests between them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BenchSchedule {
    /// Order of the tests.
    pub order: TestOrder,
    /// A rest after every this many tests (0: none).
    pub rest_every: usize,
    /// Length of a rest, s (the motor cools towards ambient).
    pub rest_s: f64,
}

/// The conditions of one synthetic test, for a current law other than the library's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conditions {
    /// The operating point (its thermal driver is the motor temperature above ambient).
    pub op: OperatingPoint,
    /// Time of the test since the session began, s.
    pub t_s: f64,
    /// Motor temperature, deg C.
    pub temp_c: f64,
    /// Vibrator voltage, V.
    pub v_in: f64,
}

/// A current (A) added to the model's at each test: an effect in a form the library does not
/// have. It sees the true model and the test's conditions.
pub type ExtraCurrent<'a> = &'a (dyn Fn(&CurrentModel, &Conditions) -> f64 + Sync);

/// A synthetic sweep of `truth` (the model with its hidden effects) under `plan`, with the
/// random test order and noise fixed by `seed`.
pub fn generate(truth: &CurrentModel, plan: &SweepPlan, seed: u64) -> Vec<MeasuredRow> {
    generate_session(truth, plan, &BenchSchedule::default(), seed, None)
}

/// A synthetic bench session of `truth` under `plan`, its tests ordered and rested as
/// `session` says, with `extra` current (an effect in another form) added when given. The
/// test order, noise and rests are fixed by `seed`; with the default session this is
/// [`generate`].
pub fn generate_session(
    truth: &CurrentModel,
    plan: &SweepPlan,
    session: &BenchSchedule,
    seed: u64,
    extra: Option<ExtraCurrent>,
) -> Vec<MeasuredRow> {
    let mut rng = NoiseSource::new(seed);
    let mut tests: Vec<(f64, f64)> = Vec::new();
    for _ in 0..plan.repeats {
        for &v in &plan.voltages_v {
            let first = tests.len();
            for &tau in &plan.loads_nm {
                tests.push((tau, v));
            }
            if session.order == TestOrder::ShuffledWithinVoltage {
                let part = &mut tests[first..];
                for i in (1..part.len()).rev() {
                    let j = (rng.next_u64() % (i as u64 + 1)) as usize;
                    part.swap(i, j);
                }
            }
        }
    }
    if session.order == TestOrder::Shuffled {
        for i in (1..tests.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            tests.swap(i, j);
        }
    }
    let tau_max = plan
        .loads_nm
        .iter()
        .fold(0.0f64, |m, t| m.max(t.abs()))
        .max(1e-9);
    let gear = &truth.drive.gear;
    let contact_ratio = gear.contact_ratio(3) + gear.contact_ratio(4);
    let tc = plan.temp_time_constant_s;
    let mut t = 0.0;
    // Share of the full temperature rise reached (with rests: heating and cooling).
    let mut heat = 0.0f64;
    let mut rows = Vec::with_capacity(tests.len());
    for (k, (tau, v)) in tests.into_iter().enumerate() {
        if session.rest_every > 0 && k > 0 && k % session.rest_every == 0 {
            t += session.rest_s;
            heat *= (-session.rest_s / tc).exp();
        }
        let d = uniform(&mut rng, plan.test_seconds.0, plan.test_seconds.1);
        t += d;
        heat = if session.rest_every == 0 {
            1.0 - (-t / tc).exp()
        } else {
            1.0 - (1.0 - heat) * (-d / tc).exp()
        };
        let temp = plan.ambient_c + plan.temp_rise_c * heat + 0.1 * rng.normal();
        let omega = nominal_cam_speed(v)
            * (1.0 - plan.speed_droop * tau.abs() / tau_max)
            * (1.0 + 0.005 * rng.normal());
        // The physics sees the motor temperature against the calibration at ambient.
        let op = OperatingPoint::new(omega, tau, temp - plan.ambient_c);
        let mut i = truth.current(&op) + plan.noise_a * rng.normal();
        let ripple = truth.effects.mesh_ripple_rms;
        if ripple > 0.0 {
            let phase = rng.uniform();
            let m = effects::mesh_friction_modulation(phase, contact_ratio, ISO_LOAD_EXPONENT);
            i += ripple * m * truth.friction_current(&op);
        }
        if let Some(f) = extra {
            i += f(
                truth,
                &Conditions {
                    op,
                    t_s: t,
                    temp_c: temp,
                    v_in: v,
                },
            );
        }
        rows.push(MeasuredRow {
            omega_n: omega,
            tau_rot: tau,
            i_in: Some(i),
            t_s: plan.with_time.then_some(t),
            v_in: plan.with_voltage.then_some(v),
            temp_c: plan.with_temperature.then_some(temp),
            backdriven: plan.with_backdriven.then(|| truth.backdrives(&op)),
            ..MeasuredRow::default()
        });
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::CamDrive;

    fn paper() -> CurrentModel {
        let drive = CamDrive::paper(model::paper::RIG_GEARS);
        CurrentModel::paper(drive, model::paper::CALIBRATION, model::paper::MU_S)
    }

    #[test]
    fn sweep_looks_like_the_paper() {
        let rows = generate(&paper(), &SweepPlan::default(), 3);
        assert_eq!(rows.len(), 150);
        let i: Vec<f64> = rows.iter().map(|r| r.i_in.unwrap()).collect();
        let lo = i.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let hi = i.iter().fold(0.0f64, |a, &b| a.max(b));
        assert!(lo > 2.2 && hi < 3.8, "{lo} {hi}");
        let t_end = rows.iter().filter_map(|r| r.t_s).fold(0.0, f64::max);
        assert!(t_end > 1800.0 && t_end < 4200.0, "{t_end}");
        let temp_end = rows.last().unwrap().temp_c.unwrap();
        assert!(temp_end > 35.0 && temp_end < 46.0, "{temp_end}");
        // Random order: the first tests are not the first loads.
        assert!(rows.iter().take(10).any(|r| r.tau_rot > 1.0));
        assert!(rows.iter().all(|r| r.backdriven == Some(true)));
        assert_eq!(generate(&paper(), &SweepPlan::default(), 3), rows);
    }

    #[test]
    fn bench_orders_and_rests() {
        let plan = SweepPlan::default();
        let asc = BenchSchedule {
            order: TestOrder::Ascending,
            rest_every: 30,
            rest_s: 1800.0,
        };
        let rows = generate_session(&paper(), &plan, &asc, 3, None);
        assert_eq!(rows.len(), 150);
        // Voltage after voltage, loads rising.
        assert!(rows[..10].windows(2).all(|w| w[0].tau_rot < w[1].tau_rot));
        assert_eq!(rows[0].v_in, Some(3.6));
        assert_eq!(rows[10].v_in, Some(6.2));
        // The motor cools over a 30-minute rest.
        let before = rows[29].temp_c.unwrap();
        let after = rows[30].temp_c.unwrap();
        assert!(after < before - 3.0, "{before} -> {after}");
        assert!(rows[30].t_s.unwrap() - rows[29].t_s.unwrap() > 1800.0);
        // An extra current in another form is added.
        let extra = |_: &CurrentModel, c: &Conditions| 0.1 * c.op.tau_rot;
        let plain = generate(&paper(), &plan, 4);
        let more = generate_session(&paper(), &plan, &BenchSchedule::default(), 4, Some(&extra));
        for (a, b) in plain.iter().zip(&more) {
            let d = b.i_in.unwrap() - a.i_in.unwrap();
            assert!((d - 0.1 * a.tau_rot).abs() < 1e-12);
        }
    }

    #[test]
    fn bush_holds_light_loads_at_low_speed() {
        let plan = SweepPlan::default();
        let mut m = paper();
        let mut rng = NoiseSource::new(5);
        m.effects = plausible_effect(Effect::LinearBushFriction, &m, &plan, &mut rng);
        let rows = generate(&m, &plan, 5);
        let held: Vec<&MeasuredRow> = rows
            .iter()
            .filter(|r| r.backdriven == Some(false))
            .collect();
        assert!(!held.is_empty());
        assert!(
            held.iter()
                .all(|r| r.tau_rot < 0.75 && r.v_in.unwrap() < 7.0)
        );
    }
}
