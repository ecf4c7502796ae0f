//! Fig. 5 of the paper: (Z1, Z4) = (50, 49), m_out = 1.0 kg on r_out = 75 mm. The load stays
//! still without vibration (14.5 s in the paper) and falls once vibration starts (3.6 V,
//! about 5 Hz); with mu_d Lambda < 1 it keeps falling after the vibration stops.

use model::paper;
use serde::Serialize;

use super::{hello, lock, output_moved, release};
use crate::SimError;
use crate::{SimConfig, SimLink, SimRig};

/// The scenario's settings.
#[derive(Debug, Clone, Copy)]
pub struct Fig5Options {
    /// Hold phase without vibration, s.
    pub hold_s: f64,
    /// Vibration frequency of the release, Hz.
    pub vibration_hz: f32,
    /// How long the release lasts, s.
    pub release_s: f64,
    /// When the output speed is read after the cam has stopped, s.
    pub after_stop_s: f64,
    /// Sensor-noise seed.
    pub seed: u64,
    /// The ACS714's supply, V (ratiometric zero and sensitivity; the board allows
    /// 4.5-5.5 V).
    pub sensor_supply_v: f64,
}

impl Default for Fig5Options {
    fn default() -> Self {
        Self {
            hold_s: paper::FIG5_HOLD_S,
            vibration_hz: paper::VIBRATION_HZ[0] as f32,
            release_s: 2.0,
            after_stop_s: 0.5,
            seed: 1,
            sensor_supply_v: model::hardware::acs714::SUPPLY_NOMINAL_V,
        }
    }
}

/// What `rig sim fig5 --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Fig5Result {
    /// Gear set.
    pub z: [u32; 4],
    /// The load did not move during the hold phase.
    pub held_without_vibration: bool,
    /// Length of the hold phase, s.
    pub hold_s: f64,
    /// From the release request to the first motion of the load, s.
    pub release_to_motion_s: Option<f64>,
    /// Output speed after the cam has stopped, rad/s (positive: the load keeps falling).
    pub output_speed_after_stop_rad_s: f64,
    /// Output speed when the vibration was switched off, rad/s.
    pub output_speed_at_stop_rad_s: f64,
    /// Rope paid out while released and after, m.
    pub load_drop_m: f64,
    /// mu_d Lambda of the gear set (below 1: motion continues after vibration stops).
    pub mu_d_lambda: f64,
}

/// Runs the scenario.
pub fn run(opts: &Fig5Options) -> Result<Fig5Result, SimError> {
    let z = paper::FIG5_Z;
    let radius = paper::R_OUT;
    let mut config =
        SimConfig::for_gear(z, paper::FIG5_LOAD).map_err(|source| SimError::Gear { z, source })?;
    config.seed = opts.seed;
    config.plant.sensors.acs_supply = opts.sensor_supply_v;
    let mu_d_lambda = config.plant.mu_d * config.plant.drive.gear.big_lambda();
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link)?;

    link.wait(opts.hold_s);
    let held_without_vibration =
        !output_moved(&link) && link.rig.plant().state().output_speed == 0.0;

    release(&mut link, opts.vibration_hz)?;
    let release_to_motion_s = link.wait_until(opts.release_s, 0.001, output_moved);
    link.wait((opts.release_s - release_to_motion_s.unwrap_or(opts.release_s)).max(0.0));
    let output_speed_at_stop_rad_s = link.rig.plant().state().output_speed;
    lock(&mut link)?;
    link.wait_until(2.0, 0.005, |l| l.rig.plant().state().cam_speed == 0.0);
    link.wait(opts.after_stop_s);
    let state = link.rig.plant().state();
    Ok(Fig5Result {
        z,
        held_without_vibration,
        hold_s: opts.hold_s,
        release_to_motion_s,
        output_speed_after_stop_rad_s: state.output_speed,
        output_speed_at_stop_rad_s,
        load_drop_m: state.output_angle * radius,
        mu_d_lambda,
    })
}
