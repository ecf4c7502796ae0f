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

/// A synthetic sweep of `truth` (the model with its hidden effects) under `plan`, with the
/// random test order and noise fixed by `seed`.
pub fn generate(truth: &CurrentModel, plan: &SweepPlan, seed: u64) -> Vec<MeasuredRow> {
    let mut rng = NoiseSource::new(seed);
    let mut tests: Vec<(f64, f64)> = Vec::new();
    for _ in 0..plan.repeats {
        for &v in &plan.voltages_v {
            for &tau in &plan.loads_nm {
                tests.push((tau, v));
            }
        }
    }
    for i in (1..tests.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        tests.swap(i, j);
    }
    let tau_max = plan
        .loads_nm
        .iter()
        .fold(0.0f64, |m, t| m.max(t.abs()))
        .max(1e-9);
    let gear = &truth.drive.gear;
    let contact_ratio = gear.contact_ratio(3) + gear.contact_ratio(4);
    let mut t = 0.0;
    let mut rows = Vec::with_capacity(tests.len());
    for (tau, v) in tests {
        t += uniform(&mut rng, plan.test_seconds.0, plan.test_seconds.1);
        let temp = plan.ambient_c
            + plan.temp_rise_c * (1.0 - (-t / plan.temp_time_constant_s).exp())
            + 0.1 * rng.normal();
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
        rows.push(MeasuredRow {
            omega_n: omega,
            tau_rot: tau,
            i_in: Some(i),
            t_s: plan.with_time.then_some(t),
            v_in: plan.with_voltage.then_some(v),
            temp_c: plan.with_temperature.then_some(temp),
            backdriven: plan.with_backdriven.then(|| truth.backdrives(&op)),
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
