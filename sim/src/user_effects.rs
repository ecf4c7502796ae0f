//! A rig file's user effects (`[[user_effects]]` carried by `[[model.terms]]`) in the virtual
//! rig's plant: each law is evaluated at the plant's operating point as it changes and the
//! plant runs the sum as a drag drawing that extra current
//! ([`model::plant::Plant::set_user_current`]).
//!
//! The law reads what `rig explain` fitted it on: the cam speed as a test window's mean sees
//! it (the plant's speed low-passed over [`SPEED_FILTER_S`], so the law does not ripple with
//! the cam's angle), the hung load, the session time, the motor temperature, and the model's
//! current, friction current, inertia current and axial force at that speed and load (the
//! rig file's own model, as explain evaluates the term).

use model::effects::CurrentModel;
use model::plant::Plant;
use rigfile::{RigFile, UserTerm};

use crate::SimError;

/// Time constant of the cam speed the laws read, s: a few revolutions at the slowest
/// release, short against a sweep point's settling.
pub const SPEED_FILTER_S: f64 = 0.05;

/// The user effects a plant runs, with the model whose quantities they read.
#[derive(Debug, Clone, PartialEq)]
pub struct UserEffects {
    /// The laws with their parameter values.
    pub terms: Vec<UserTerm>,
    /// The rig file's current model (`i`, `i_f`, `i_m`, `f_ax`).
    pub model: CurrentModel,
    /// The calibration temperature the model's thermal driver counts from, deg C.
    pub reference_c: f64,
}

impl UserEffects {
    /// The user effects `terms` of `rig`'s `[model]` (its `plant_effects().user_terms`),
    /// reading `rig`'s current model; `None` when there are none.
    pub fn of(rig: &RigFile, terms: Vec<UserTerm>) -> Result<Option<Self>, SimError> {
        if terms.is_empty() {
            return Ok(None);
        }
        let model = rig.current_model().map_err(|e| SimError::BadValue {
            what: "the rig file's [model]".into(),
            why: e.to_string(),
        })?;
        Ok(Some(Self {
            terms,
            model,
            reference_c: rig.calibration.temperature_c,
        }))
    }
}

/// The laws at work in one plant: the filtered speed and a scratch buffer.
#[derive(Debug, Clone)]
pub struct UserDrive {
    effects: UserEffects,
    speed: f64,
    scratch: Vec<f64>,
}

impl UserDrive {
    /// Starts `effects` on a plant at rest.
    pub fn new(effects: UserEffects) -> Self {
        Self {
            effects,
            speed: 0.0,
            scratch: Vec::with_capacity(16),
        }
    }

    /// After `dt` seconds of `plant` at session time `t_s`: filters the speed, evaluates
    /// every law there and sets their sum on the plant. A cam at rest draws nothing.
    pub fn update(&mut self, plant: &mut Plant, dt: f64, t_s: f64) {
        let state = plant.state();
        let w_now = state.cam_speed.abs();
        let alpha = (dt / SPEED_FILTER_S).min(1.0);
        self.speed += (w_now - self.speed) * alpha;
        let amps = if w_now == 0.0 {
            0.0
        } else {
            let temp = state.temperature;
            let tau = plant.params().load.torque();
            let at = [self.speed, tau, t_s, temp];
            let thermal = temp - self.effects.reference_c;
            let e = &self.effects;
            e.terms
                .iter()
                .map(|u| u.current(&e.model, at, thermal, &mut self.scratch))
                .sum()
        };
        plant.set_user_current(amps);
    }
}
