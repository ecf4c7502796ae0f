//! The current model with its constants folded: [`CurrentEvaluator`], the same physics as
//! [`CurrentModel`] through the same laws, with the gradient the fit needs.

use super::{
    CurrentModel, OperatingPoint, PARAM_COUNT, Param, axial_friction_speed_factor_sq,
    bush_cam_torque, compliant_friction_torque, load_friction_factor_ln, offset_current,
    rectified_inertia, torque_constant_factor, torque_constant_factor_and_slope,
};

use core::f64::consts::PI;

/// A [`CurrentModel`] with its constants folded (see [`CurrentModel::evaluator`]): the same
/// physics, evaluated without recomputing the gear geometry at every point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentEvaluator {
    mu: f64,
    axial_per_torque: f64,
    eccentricity: f64,
    inertia_per_omega_sq: f64,
    corner_sq: f64,
    load_exponent: f64,
    compliance: f64,
    rectification: f64,
    viscous: f64,
    constant_torque: f64,
    bush_per_force: f64,
    c1: f64,
    thermal_coeff: f64,
    current_offset: f64,
}

impl CurrentEvaluator {
    /// `model` with its constants folded.
    pub(super) fn new(model: &CurrentModel) -> Self {
        let e = &model.effects;
        let ecc = model.drive.eccentricity;
        Self {
            mu: model.mu,
            axial_per_torque: model.drive.gear.axial_force_per_torque(),
            eccentricity: ecc,
            inertia_per_omega_sq: model.drive.required_inertia_torque(1.0),
            corner_sq: e.axial_corner_speed * e.axial_corner_speed,
            load_exponent: e.load_exponent,
            compliance: e.tooth_compliance,
            rectification: e.rectification,
            viscous: model.calibration.c3 + e.viscous_loss,
            constant_torque: model.calibration.c4 + bush_cam_torque(e.bush_force, ecc)
                - model.calibration.c2,
            bush_per_force: bush_cam_torque(1.0, ecc),
            c1: model.calibration.c1,
            thermal_coeff: e.thermal_coeff,
            current_offset: e.current_offset,
        }
    }

    /// Axial friction force without mu, N (speed and load factors included).
    fn axial_force_per_mu(&self, op: &OperatingPoint) -> f64 {
        let g = axial_friction_speed_factor_sq(op.omega_n, op.omega_sq, self.corner_sq);
        let h = load_friction_factor_ln(self.load_exponent, op.ln_load);
        g * h * self.axial_per_torque * op.tau_rot.abs()
    }

    /// Torque-constant factor 1 - k x (floored) at `op`.
    fn thermal_factor(&self, op: &OperatingPoint) -> f64 {
        torque_constant_factor(self.thermal_coeff, op.thermal)
    }

    /// Friction term (2/pi) F (e - c F), N m, for the axial force `f`.
    fn friction_torque(&self, f: f64) -> f64 {
        compliant_friction_torque(f, self.eccentricity, self.compliance)
    }

    /// Mean current at `op`, A (equals [`CurrentModel::current`]).
    pub fn current(&self, op: &OperatingPoint) -> f64 {
        let w = op.omega_n.abs();
        let f = self.mu * self.axial_force_per_mu(op);
        let inertia =
            rectified_inertia(self.inertia_per_omega_sq * op.omega_sq, self.rectification);
        let lifted = self.friction_torque(f) + inertia + self.viscous * w + self.constant_torque;
        offset_current(
            lifted / (self.c1 * self.thermal_factor(op)),
            self.current_offset,
        )
    }

    /// The current the friction term draws at `op`, A (equals [`CurrentModel::friction_current`]).
    pub fn friction_current(&self, op: &OperatingPoint) -> f64 {
        let f = self.mu * self.axial_force_per_mu(op);
        self.friction_torque(f) / (self.c1 * self.thermal_factor(op))
    }

    /// Mean current at `op` and its gradient with respect to [`CurrentModel::params`].
    pub fn current_and_gradient(&self, op: &OperatingPoint, grad: &mut [f64; PARAM_COUNT]) -> f64 {
        let ecc = self.eccentricity;
        let w = op.omega_n.abs();
        let w2 = op.omega_sq;
        let s = self.corner_sq;
        let a = self.axial_force_per_mu(op);
        let f = self.mu * a;
        let df_ds = if w2 + s > 0.0 {
            -0.5 * f / (w2 + s)
        } else {
            0.0
        };
        let df_db = f * op.ln_load;
        let c = self.compliance;
        let friction = self.friction_torque(f);
        // Derivatives of (2/pi) F (e - c F) while the teeth slide; zero past the limit.
        let (dfr_df, dfr_dc) = if c * f < ecc {
            (2.0 / PI * (ecc - 2.0 * c * f), -2.0 / PI * f * f)
        } else {
            (0.0, 0.0)
        };
        let inertia_unit = self.inertia_per_omega_sq * w2;
        let inertia_live = 1.0 + self.rectification > 0.0;
        let inertia = rectified_inertia(inertia_unit, self.rectification);
        let lifted = friction + inertia + self.viscous * w + self.constant_torque;
        let (factor, dfactor_dk) = torque_constant_factor_and_slope(self.thermal_coeff, op.thermal);
        let c1 = self.c1 * factor;
        let di_dt = 1.0 / c1;
        grad[Param::Mu.index()] = di_dt * dfr_df * a;
        grad[Param::AxialCornerSq.index()] = di_dt * dfr_df * df_ds;
        grad[Param::LoadExponent.index()] = di_dt * dfr_df * df_db;
        grad[Param::ToothCompliance.index()] = di_dt * dfr_dc;
        grad[Param::Rectification.index()] = if inertia_live {
            di_dt * inertia_unit
        } else {
            0.0
        };
        grad[Param::ViscousLoss.index()] = di_dt * w;
        grad[Param::BushForce.index()] = di_dt * self.bush_per_force;
        grad[Param::ThermalCoeff.index()] = -lifted * dfactor_dk / (c1 * factor);
        grad[Param::CurrentOffset.index()] = 1.0;
        offset_current(lifted * di_dt, self.current_offset)
    }
}
