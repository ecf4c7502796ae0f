//! The paper's required-torque test (Figs. 8-9): (Z1, Z4) = (49, 50), tau_rot from 0.368 to
//! 3.68 N m at V_in = 3.6, 6.2 and 8.8 V, five repeats, in random order as on a bench. Per
//! point: the mean current over 0.5 s from the start of constant cam speed (as the paper),
//! the cam speed, the firmware's tau_cam estimate and Eq. (10).

use model::paper;
use model::plant::{Load, NoiseSource, PlantEffects};
use protocol::Request;
use serde::Serialize;

use super::{HEARTBEAT_S, expect_ack, hello, output_moved};
use crate::SimError;
use crate::{SimConfig, SimLink, SimRig};

/// The sweep's settings.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// Gear set.
    pub z: [u32; 4],
    /// Load torques, N m.
    pub loads: Vec<f64>,
    /// Supply voltages, V.
    pub voltages: Vec<f64>,
    /// Repeats per point.
    pub repeats: u32,
    /// Averaging window from the start of constant cam speed, s.
    pub window_s: f64,
    /// Rest between test points (the motor cools), s.
    pub rest_s: f64,
    /// Seed of the sensor noise and of the test order.
    pub seed: u64,
    /// Effects switched on in the plant (for the discrepancy workflow); by default the
    /// `paper` preset's ([`crate::Preset::paper`]), as the paper's rig measured.
    pub effects: PlantEffects,
    /// The ACS714's supply, V (ratiometric zero and sensitivity; the board allows
    /// 4.5-5.5 V).
    pub sensor_supply_v: f64,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self {
            z: paper::RIG_Z,
            loads: (1..=10)
                .map(|k| paper::TAU_ROT_MIN_TESTED * k as f64)
                .collect(),
            voltages: paper::SUPPLY_VOLTAGES.to_vec(),
            repeats: paper::REQUIRED_TORQUE_REPEATS,
            window_s: paper::CURRENT_AVERAGING_S,
            rest_s: 10.0,
            seed: 1,
            effects: crate::Preset::paper().effects,
            sensor_supply_v: model::hardware::acs714::SUPPLY_NOMINAL_V,
        }
    }
}

/// One test point (one CSV row).
#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    /// Start of the averaging window since the session began, s.
    pub t_s: f64,
    /// Supply voltage, V.
    pub v_in_v: f64,
    /// Mean cam speed over the window, rad/s.
    pub omega_n_rad_s: f64,
    /// Load torque, N m.
    pub tau_rot_nm: f64,
    /// Mean current over the window, A (logged on the sensor, as the paper's logger).
    pub i_in_a: f64,
    /// Motor temperature at the window's start, deg C.
    pub temp_c: f64,
    /// Repeat index, 0-based.
    pub repeat: u32,
    /// The firmware's tau_cam estimate at the window's end, N m.
    pub tau_cam_est_nm: f64,
    /// Torque from the mean current by Eqs. (15)-(17), N m.
    pub tau_cam_meas_nm: f64,
    /// Eq. (10) at the mean cam speed, N m.
    pub tau_cam_eq10_nm: f64,
    /// The output moved during the test (1) or stayed held (0).
    pub backdriven: u8,
}

/// What `rig sim torque-sweep --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct SweepSummary {
    /// Test points run.
    pub points: usize,
    /// Mean cam frequency per supply voltage, Hz, in `voltages` order.
    pub mean_hz_per_voltage: Vec<(f64, f64)>,
    /// The mean current grows with the load at every voltage.
    pub current_grows_with_load: bool,
    /// The mean current grows with the voltage (cam speed) at every load.
    pub current_grows_with_speed: bool,
    /// The firmware's tau_cam estimate grows with the load at every voltage.
    pub tau_cam_grows_with_load: bool,
    /// The firmware's tau_cam estimate grows with the cam speed at every load.
    pub tau_cam_grows_with_speed: bool,
    /// RMS difference of the measured tau_cam from Eq. (10), N m.
    pub rmse_tau_cam_vs_eq10_nm: f64,
    /// RMS difference of the firmware's estimate from the measured tau_cam, N m.
    pub rmse_estimate_vs_measured_nm: f64,
    /// Points where the output did not backdrive.
    pub not_backdriven: usize,
}

/// Runs the sweep.
pub fn run(opts: &SweepOptions) -> Result<Vec<SweepPoint>, SimError> {
    let z = opts.z;
    let mut config =
        SimConfig::for_gear(z, Load::Torque(0.0)).map_err(|source| SimError::Gear { z, source })?;
    config.seed = opts.seed;
    config.plant.effects = opts.effects;
    config.plant.sensors.acs_supply = opts.sensor_supply_v;
    // The bench tests up to the largest load: the release limit sits above it so estimate
    // noise at the top load does not trip OVERLOAD.
    let top = opts.loads.iter().copied().fold(0.0, f64::max);
    config.calibration.max_release_load_nm = config
        .calibration
        .max_release_load_nm
        .max((1.25 * top) as f32);
    let drive = config.plant.drive;
    let calibration = paper::CALIBRATION;
    let mu = config.plant.mu_s;
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link)?;

    let mut order: Vec<(f64, f64, u32)> = Vec::new();
    for r in 0..opts.repeats {
        for &v in &opts.voltages {
            for &tau in &opts.loads {
                order.push((v, tau, r));
            }
        }
    }
    let mut rng = NoiseSource::new(opts.seed ^ 0x5eed);
    for i in (1..order.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }

    let mut points = Vec::with_capacity(order.len());
    for (v, tau, repeat) in order {
        link.rig.plant_mut().set_load(Load::Torque(tau));
        link.rig.plant_mut().reset_output();
        expect_ack(&mut link, &Request::OpenLoop { volts: v as f32 })?;
        link.keep_alive(Some(HEARTBEAT_S));
        wait_for_constant_speed(&mut link).map_err(|e| {
            SimError::Protocol(format!(
                "{e} at {v} V, {tau} N m, t = {:.1} s",
                link.rig.time()
            ))
        })?;
        let t_s = link.rig.time();
        let temp_c = link.rig.plant().state().temperature;
        let angle0 = link.rig.plant().state().cam_angle;
        let samples = (opts.window_s * 1000.0).round() as usize;
        let (mut current, mut estimates) = (0.0, Vec::new());
        let mut revolutions = link.rig.core().status().revolutions;
        for _ in 0..samples {
            link.wait(0.001);
            current += link.rig.plant_mut().logged_current();
            let s = link.rig.core().status();
            if s.revolutions != revolutions && s.estimate_valid {
                revolutions = s.revolutions;
                estimates.push(f64::from(s.tau_cam_nm));
            }
        }
        let i_in = current / samples as f64;
        let omega = (link.rig.plant().state().cam_angle - angle0) / (samples as f64 * 0.001);
        // The firmware's per-revolution estimates over the window, averaged.
        let tau_cam_est = estimates.iter().sum::<f64>() / estimates.len().max(1) as f64;
        let backdriven = output_moved(&link);
        let latched = link.rig.core().status().latched_faults;
        if !latched.is_empty() {
            return Err(SimError::Protocol(format!(
                "the firmware faulted ({latched}) at {v} V, {tau} N m, t = {:.1} s",
                link.rig.time()
            )));
        }
        expect_ack(&mut link, &Request::OpenLoop { volts: 0.0 })?;
        link.keep_alive(None);
        link.wait(opts.rest_s);
        points.push(SweepPoint {
            t_s,
            v_in_v: v,
            omega_n_rad_s: omega,
            tau_rot_nm: tau,
            i_in_a: i_in,
            temp_c,
            repeat,
            tau_cam_est_nm: tau_cam_est,
            tau_cam_meas_nm: calibration.cam_torque(i_in, omega),
            tau_cam_eq10_nm: drive.required_cam_torque(mu, tau, omega),
            backdriven: backdriven as u8,
        });
    }
    Ok(points)
}

/// Waits for the start of constant cam speed as the firmware judges it: its voltage ramp
/// is done and the speed has settled, so it reports `Vibrating`.
fn wait_for_constant_speed(link: &mut SimLink) -> Result<(), SimError> {
    let done = |l: &SimLink| l.rig.core().status().state == protocol::SupervisorState::Vibrating;
    if link.wait_until(8.0, 0.001, done).is_some() {
        return Ok(());
    }
    let s = link.rig.core().status();
    Err(SimError::Protocol(format!(
        "the cam did not reach a constant speed within 8 s (firmware state {}, faults {}, cam {:.1} rad/s)",
        s.state.name(),
        s.latched_faults,
        s.cam_speed_rad_s
    )))
}

/// Summarises the points (means over repeats) and checks the paper's trends.
pub fn summarise(points: &[SweepPoint], opts: &SweepOptions) -> SweepSummary {
    let mean = |v: f64, tau: f64, f: &dyn Fn(&SweepPoint) -> f64| {
        let sel: Vec<f64> = points
            .iter()
            .filter(|p| p.v_in_v == v && p.tau_rot_nm == tau)
            .map(f)
            .collect();
        sel.iter().sum::<f64>() / sel.len().max(1) as f64
    };
    let grows = |f: &dyn Fn(&SweepPoint) -> f64| {
        let by_load = opts.voltages.iter().all(|&v| {
            opts.loads
                .windows(2)
                .all(|w| mean(v, w[1], f) > mean(v, w[0], f))
        });
        let by_speed = opts.loads.iter().all(|&tau| {
            opts.voltages
                .windows(2)
                .all(|w| mean(w[1], tau, f) > mean(w[0], tau, f))
        });
        (by_load, by_speed)
    };
    let (current_grows_with_load, current_grows_with_speed) = grows(&|p| p.i_in_a);
    let (tau_cam_grows_with_load, tau_cam_grows_with_speed) = grows(&|p| p.tau_cam_est_nm);
    let rms = |f: &dyn Fn(&SweepPoint) -> f64| {
        (points.iter().map(|p| f(p).powi(2)).sum::<f64>() / points.len().max(1) as f64).sqrt()
    };
    SweepSummary {
        points: points.len(),
        mean_hz_per_voltage: opts
            .voltages
            .iter()
            .map(|&v| {
                let sel: Vec<f64> = points
                    .iter()
                    .filter(|p| p.v_in_v == v)
                    .map(|p| p.omega_n_rad_s)
                    .collect();
                (
                    v,
                    sel.iter().sum::<f64>()
                        / sel.len().max(1) as f64
                        / (2.0 * std::f64::consts::PI),
                )
            })
            .collect(),
        current_grows_with_load,
        current_grows_with_speed,
        tau_cam_grows_with_load,
        tau_cam_grows_with_speed,
        rmse_tau_cam_vs_eq10_nm: rms(&|p| p.tau_cam_meas_nm - p.tau_cam_eq10_nm),
        rmse_estimate_vs_measured_nm: rms(&|p| p.tau_cam_est_nm - p.tau_cam_meas_nm),
        not_backdriven: points.iter().filter(|p| p.backdriven == 0).count(),
    }
}

/// Writes the points as CSV (header: `t_s,v_in_v,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c,...`)
/// to `out`; callers that write a file do so atomically (`reporting::write_atomic_with`).
pub fn write_csv<W: std::io::Write>(points: &[SweepPoint], out: W) -> Result<(), csv::Error> {
    let mut w = csv::Writer::from_writer(out);
    for p in points {
        w.serialize(p)?;
    }
    w.flush()?;
    Ok(())
}
