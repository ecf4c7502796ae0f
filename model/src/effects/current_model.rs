//! The paper's steady-state vibrator current with the effects: [`CurrentModel`].

use super::evaluator::CurrentEvaluator;
use super::{
    EffectParams, OperatingPoint, PARAM_COUNT, axial_friction_speed_factor, bush_cam_torque,
    bush_holding_torque, compliant_friction_torque, drifted_torque_constant,
    load_friction_factor_ln, offset_current, rectified_inertia_torque, viscous_loss_torque,
};
use crate::{Calibration, CamDrive};

/// The paper's steady-state vibrator current (Eqs. 10, 15-17) with the effects of
/// [`EffectParams`]; every effect at zero gives the paper's model.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CurrentModel {
    /// Gear set, eccentricity and carrier mass.
    pub drive: CamDrive,
    /// Vibrator calibration C1-C6.
    pub calibration: Calibration,
    /// Friction coefficient mu of Eq. (10).
    pub mu: f64,
    /// The effects (zero: absent).
    pub effects: EffectParams,
}

/// Parts of the cam torque at one operating point, N m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueParts {
    /// Axial friction force F_ax at the teeth, N.
    pub axial_force: f64,
    /// Friction term (2/pi) F_ax (e - c F_ax).
    pub friction: f64,
    /// Inertia term (1 + kappa) M_hat w_n^2 e^2 / pi.
    pub inertia: f64,
    /// Vibrator loss C3 w_n + C4 + c_v w_n.
    pub loss: f64,
    /// Linear bush term (2/pi) F_b e.
    pub bush: f64,
}

impl TorqueParts {
    /// Gross shaft torque the motor delivers: every part.
    pub fn total(&self) -> f64 {
        self.friction + self.inertia + self.loss + self.bush
    }
}

impl CurrentModel {
    /// The paper's model around `drive` with calibration `calibration` and friction `mu`.
    pub fn paper(drive: CamDrive, calibration: Calibration, mu: f64) -> Self {
        Self {
            drive,
            calibration,
            mu,
            effects: EffectParams::default(),
        }
    }

    /// Axial friction force at the teeth F_ax, N (Eq. 8's friction part with mu_ax(w_n, tau)).
    pub fn axial_force(&self, op: &OperatingPoint) -> f64 {
        self.axial_force_with(op, self.drive.gear.axial_force_per_torque())
    }

    /// [`CurrentModel::axial_force`] with the gear's axial force per torque given
    /// ([`crate::GearSet::axial_force_per_torque`], the same at every point).
    pub fn axial_force_with(&self, op: &OperatingPoint, axial_per_torque: f64) -> f64 {
        let e = &self.effects;
        let g = axial_friction_speed_factor(op.omega_n, e.axial_corner_speed);
        let h = load_friction_factor_ln(e.load_exponent, op.ln_load);
        CamDrive::friction_force_with(self.mu * g * h, op.tau_rot, axial_per_torque)
    }

    /// The parts of the mean cam torque at `op`.
    pub fn torque_parts(&self, op: &OperatingPoint) -> TorqueParts {
        self.torque_parts_with(op, self.drive.gear.axial_force_per_torque())
    }

    /// [`CurrentModel::torque_parts`] with the gear's axial force per torque given: the same
    /// numbers, without the gear geometry's trigonometry at every point.
    pub fn torque_parts_with(&self, op: &OperatingPoint, axial_per_torque: f64) -> TorqueParts {
        let e = &self.effects;
        let ecc = self.drive.eccentricity;
        let f = self.axial_force_with(op, axial_per_torque);
        let w = op.omega_n.abs();
        TorqueParts {
            axial_force: f,
            friction: compliant_friction_torque(f, ecc, e.tooth_compliance),
            inertia: rectified_inertia_torque(&self.drive, w, e.rectification),
            loss: self.calibration.loss_torque(w) + viscous_loss_torque(e.viscous_loss, w),
            bush: bush_cam_torque(e.bush_force, ecc),
        }
    }

    /// The torque constant at `op` after thermal drift, N m/A.
    pub fn torque_constant(&self, op: &OperatingPoint) -> f64 {
        drifted_torque_constant(self.calibration.c1, self.effects.thermal_coeff, op.thermal)
    }

    /// Mean vibrator current at `op`, A: (torque - C2) / C1' + i_0.
    pub fn current(&self, op: &OperatingPoint) -> f64 {
        self.current_of(&self.torque_parts(op), op)
    }

    /// [`CurrentModel::current`] from the torque parts at `op` ([`CurrentModel::torque_parts`]).
    pub fn current_of(&self, parts: &TorqueParts, op: &OperatingPoint) -> f64 {
        offset_current(
            (parts.total() - self.calibration.c2) / self.torque_constant(op),
            self.effects.current_offset,
        )
    }

    /// The current the friction term draws, A: the part the mesh ripple scatters.
    pub fn friction_current(&self, op: &OperatingPoint) -> f64 {
        self.friction_current_of(&self.torque_parts(op), op)
    }

    /// [`CurrentModel::friction_current`] from the torque parts at `op`.
    pub fn friction_current_of(&self, parts: &TorqueParts, op: &OperatingPoint) -> f64 {
        parts.friction / self.torque_constant(op)
    }

    /// Whether the load backdrives at `op`: the linear bush holds loads below
    /// [`bush_holding_torque`]; without a bush every vibrated load backdrives (Eq. 39).
    pub fn backdrives(&self, op: &OperatingPoint) -> bool {
        let e = &self.effects;
        op.tau_rot.abs() > bush_holding_torque(e.bush_hold_torque, op.omega_n, e.bush_corner_speed)
    }

    /// The parameter vector (see [`super::Param`]; the axial corner speed enters squared).
    pub fn params(&self) -> [f64; PARAM_COUNT] {
        let e = &self.effects;
        [
            self.mu,
            e.axial_corner_speed * e.axial_corner_speed,
            e.load_exponent,
            e.tooth_compliance,
            e.rectification,
            e.viscous_loss,
            e.bush_force,
            e.thermal_coeff,
            e.current_offset,
        ]
    }

    /// Sets the parameter vector (inverse of [`CurrentModel::params`]).
    pub fn set_params(&mut self, p: &[f64; PARAM_COUNT]) {
        self.mu = p[0];
        let e = &mut self.effects;
        e.axial_corner_speed = libm::sqrt(p[1].max(0.0));
        e.load_exponent = p[2];
        e.tooth_compliance = p[3];
        e.rectification = p[4];
        e.viscous_loss = p[5];
        e.bush_force = p[6];
        e.thermal_coeff = p[7];
        e.current_offset = p[8];
    }

    /// Mean current at `op` and its gradient with respect to [`CurrentModel::params`].
    pub fn current_and_gradient(&self, op: &OperatingPoint, grad: &mut [f64; PARAM_COUNT]) -> f64 {
        self.evaluator().current_and_gradient(op, grad)
    }

    /// The model with its constants folded, for evaluating many operating points.
    pub fn evaluator(&self) -> CurrentEvaluator {
        CurrentEvaluator::new(self)
    }
}
