//! Table 1 of the paper: the six gear sets at tau_rot = 3.68 N m. Without vibration only
//! n = 1 holds; with vibration every set backdrives.

use model::plant::Load;
use serde::Serialize;

use super::{hello, lock, output_moved, release};
use crate::SimError;
use crate::{SimConfig, SimLink, SimRig};

/// Load torque of the test, N m (the teeth's limit).
pub const TAU_ROT: f64 = model::paper::TAU_ROT_MAX;

/// One row of `rig sim table1 --json`.
#[derive(Debug, Clone, Serialize)]
pub struct Table1Row {
    /// Gear set.
    pub z: [u32; 4],
    /// Tooth difference.
    pub n: u32,
    /// mu_s Lambda.
    pub mu_s_lambda: f64,
    /// The output turned under the load with the vibrator off.
    pub backdriven_without_vibration: bool,
    /// The output turned once the vibrator ran.
    pub backdriven_with_vibration: bool,
    /// The paper's verdict: a non-backdriven point exists (n = 1).
    pub paper_non_backdriven_point: bool,
    /// Simulation and paper agree.
    pub agrees_with_paper: bool,
}

/// Runs the six sets: 1 s without vibration, then 1 s of vibration at `hz`.
pub fn run(sets: &[[u32; 4]], hz: f32, seed: u64) -> Result<Vec<Table1Row>, SimError> {
    sets.iter().map(|&z| run_one(z, hz, seed)).collect()
}

fn run_one(z: [u32; 4], hz: f32, seed: u64) -> Result<Table1Row, SimError> {
    let mut config = SimConfig::for_gear(z, Load::Torque(TAU_ROT))
        .map_err(|source| SimError::Gear { z, source })?;
    config.seed = seed;
    let gear = config.plant.drive.gear;
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link)?;
    link.wait(1.0);
    let backdriven_without_vibration = output_moved(&link);
    link.rig.plant_mut().reset_output();
    release(&mut link, hz)?;
    let backdriven_with_vibration = link.wait_until(1.5, 0.005, output_moved).is_some();
    lock(&mut link)?;
    let paper_non_backdriven_point = gear.n() == 1;
    Ok(Table1Row {
        z,
        n: gear.n(),
        mu_s_lambda: model::paper::MU_S * gear.big_lambda(),
        backdriven_without_vibration,
        backdriven_with_vibration,
        paper_non_backdriven_point,
        agrees_with_paper: backdriven_without_vibration != paper_non_backdriven_point
            && backdriven_with_vibration,
    })
}
