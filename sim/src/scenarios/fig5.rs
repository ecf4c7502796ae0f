//! Fig. 5 of the paper: (Z1, Z4) = (50, 49), m_out = 1.0 kg on r_out = 75 mm. The load stays
//! still without vibration (14.5 s in the paper) and falls once vibration starts (3.6 V,
//! about 5 Hz); with mu_d Lambda < 1 it keeps falling after the vibration stops. The
//! settings and the result `rig sim fig5` prints; `rig experiment hold-release` runs it
//! (`host::experiment::paper::fig5`). With `--model DESIGN.toml` whose `[gear]` is not the
//! paper's standard set, the scenario runs that gear (a `rig design search` design).

use model::paper;
use serde::Serialize;

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
    /// Effects switched on in the plant; by default the `paper` preset's
    /// ([`crate::Preset::paper`]), as the paper's rig measured.
    pub effects: model::plant::PlantEffects,
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
            effects: crate::Preset::paper().effects,
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
    /// The output came to rest after the cam stopped (stood still over the last 0.2 s of
    /// the record).
    pub stops_after_vibration: bool,
    /// Output travel from the cam's stop to the end of the record, rad.
    pub after_stop_travel_rad: f64,
    /// Profile shift coefficients x1..x4 of the gear set.
    pub x: [f64; 4],
}
