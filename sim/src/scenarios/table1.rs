//! Table 1 of the paper: the six gear sets at tau_rot = 3.68 N m. Without vibration only
//! n = 1 holds; with vibration every set backdrives. The rows `rig sim table1` prints;
//! `rig experiment backdrive` runs it (`host::experiment::paper::table1`). With `--model
//! DESIGN.toml` whose `[gear]` is not the paper's standard set, the one row is that gear.

use serde::Serialize;

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
    /// The paper's verdict: a non-backdriven point exists (Eq. 4, mu_s Lambda > 1 with
    /// mu_s = 0.271; n = 1 for the Table 1 rows).
    pub paper_non_backdriven_point: bool,
    /// Simulation and paper agree.
    pub agrees_with_paper: bool,
}
