//! The library of candidate effects: for each [`Effect`] of `model::effects`, the parameters
//! as reports and rig files name them, the bounds the fit keeps them in, and what the data
//! must contain for the effect to show.
//!
//! | effect | parameters (report and rig-file names) | enters |
//! |---|---|---|
//! | `speed-dependent-axial-friction` | `omega_c_rad_s` | mu_ax = mu w_n / sqrt(w_n^2 + w_c^2) in Eq. (10)'s friction term (Eq. 40) |
//! | `load-dependent-friction` | `exponent` (`tau_ref_nm` = 1) | mu (tau_rot / tau_ref)^b in the friction term (seed 003, Eq. 12) |
//! | `current-sensor-offset` | `offset_a` | a constant added to the measured current |
//! | `thermal-drift` | `k_per_c` (with `temp_c`, `reference_c`) or `k_per_s` (with `t_s` only) | C1 -> C1 (1 - k x) |
//! | `vibrator-viscous-loss` | `c_v_n_mm_s_per_rad` | extra vibrator loss c_v w_n next to C3 |
//! | `inertia-rectification` | `kappa` | inertia term (1 + kappa) M_hat w_n^2 e^2 / pi |
//! | `linear-bush-friction` | `force_n`, `hold_nm`, `omega_b_rad_s` | cam torque (2/pi) F_b e; the load holds while tau_rot <= hold / (1 + w_n / w_b) |
//! | `tooth-compliance` | `compliance_um_per_n` | sliding stroke e - c F_ax in the friction term (seed 004) |
//! | `mesh-load-sharing-ripple` | `ripple_rms` | scatter of the friction term, rms ripple x friction current (seed 003, Eq. 11) |

use std::collections::BTreeMap;

use model::effects::{Effect, EffectParams, Param};

/// What drives the thermal drift in a data set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ThermalDriver {
    /// The motor temperature is measured: x = T - T0 with T0 the calibration temperature.
    Temperature {
        /// T0, deg C.
        reference_c: f64,
    },
    /// Only the time is known: x = t - t_first, s.
    Time,
    /// Neither: the thermal drift cannot show.
    Unavailable,
}

/// What the data offers, for deciding which effects can show in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataTraits {
    /// Distinct cam speeds (clusters).
    pub speed_levels: usize,
    /// Distinct loads (clusters).
    pub load_levels: usize,
    /// Rows with a current.
    pub rows: usize,
    /// The thermal driver.
    pub thermal: ThermalDriver,
    /// Rows whose output was not backdriven.
    pub held_rows: usize,
}

/// Why an effect cannot show in the data, or `None` when it can.
pub fn not_applicable(effect: Effect, data: &DataTraits) -> Option<&'static str> {
    match effect {
        Effect::SpeedDependentAxialFriction
        | Effect::VibratorViscousLoss
        | Effect::InertiaRectification
            if data.speed_levels < 2 =>
        {
            Some("needs tests at two or more cam speeds")
        }
        Effect::LoadDependentFriction | Effect::ToothCompliance if data.load_levels < 3 => {
            Some("needs tests at three or more loads")
        }
        Effect::MeshLoadSharingRipple if data.load_levels < 3 || data.rows < 20 => {
            Some("needs repeated tests at three or more loads")
        }
        Effect::ThermalDrift if data.thermal == ThermalDriver::Unavailable => {
            Some("needs a temp_c or t_s column")
        }
        Effect::LinearBushFriction if data.held_rows == 0 => Some(
            "needs non-backdriven points (backdriven = 0); without them its constant torque cannot be told from a current offset",
        ),
        _ => None,
    }
}

/// Bounds of a parameter in the fit.
pub fn bounds(param: Param) -> (f64, f64) {
    match param {
        Param::Mu => (0.0, 3.0),
        Param::AxialCornerSq => (0.0, 1.0e6),
        Param::LoadExponent => (-0.9, 0.9),
        Param::ToothCompliance => (0.0, 1.0e-3),
        Param::Rectification => (-1.0, 20.0),
        Param::ViscousLoss => (-1.0, 1.0),
        Param::BushForce => (0.0, 1.0e4),
        Param::ThermalCoeff => (-1.0, 1.0),
        Param::CurrentOffset => (-100.0, 100.0),
    }
}

/// Whether the effect's null value (zero) sits on the bound of its parameter, so the data
/// can only push it one way (a one-sided test).
pub fn one_sided(effect: Effect) -> bool {
    matches!(
        effect,
        Effect::SpeedDependentAxialFriction
            | Effect::LinearBushFriction
            | Effect::ToothCompliance
            | Effect::MeshLoadSharingRipple
    )
}

/// Parameters the effect adds to the model's likelihood (mean, noise and hold parameters).
pub fn parameter_count(effect: Effect) -> usize {
    match effect {
        Effect::LinearBushFriction => 3,
        _ => 1,
    }
}

/// The effect's parameters as reported and stored in rig files (SI with the unit in the name,
/// the viscous loss in C3's N mm s/rad).
pub fn report_params(
    effect: Effect,
    p: &EffectParams,
    thermal: ThermalDriver,
) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    let mut put = |k: &str, v: f64| {
        m.insert(k.to_string(), v);
    };
    match effect {
        Effect::SpeedDependentAxialFriction => put("omega_c_rad_s", p.axial_corner_speed),
        Effect::LoadDependentFriction => {
            put("exponent", p.load_exponent);
            put("tau_ref_nm", model::effects::LOAD_FRICTION_REFERENCE_NM);
        }
        Effect::CurrentSensorOffset => put("offset_a", p.current_offset),
        Effect::ThermalDrift => match thermal {
            ThermalDriver::Temperature { reference_c } => {
                put("k_per_c", p.thermal_coeff);
                put("reference_c", reference_c);
            }
            _ => put("k_per_s", p.thermal_coeff),
        },
        Effect::VibratorViscousLoss => put("c_v_n_mm_s_per_rad", p.viscous_loss * 1e3),
        Effect::InertiaRectification => put("kappa", p.rectification),
        Effect::LinearBushFriction => {
            put("force_n", p.bush_force);
            put("hold_nm", p.bush_hold_torque);
            put("omega_b_rad_s", p.bush_corner_speed);
        }
        Effect::ToothCompliance => put("compliance_um_per_n", p.tooth_compliance * 1e6),
        Effect::MeshLoadSharingRipple => put("ripple_rms", p.mesh_ripple_rms),
    }
    m
}

/// Scale from the fitted parameter (see [`Param`]) to the reported one, for intervals;
/// `None` when the reported value is not a linear image (the corner speed is reported as the
/// square root of the fitted w_c^2).
pub fn report_scale(param: Param) -> Option<f64> {
    match param {
        Param::ViscousLoss => Some(1e3),
        Param::ToothCompliance => Some(1e6),
        Param::AxialCornerSq => None,
        _ => Some(1.0),
    }
}

/// The reported name of the effect's main parameter.
pub fn main_param_name(effect: Effect, thermal: ThermalDriver) -> &'static str {
    match effect {
        Effect::SpeedDependentAxialFriction => "omega_c_rad_s",
        Effect::LoadDependentFriction => "exponent",
        Effect::CurrentSensorOffset => "offset_a",
        Effect::ThermalDrift => match thermal {
            ThermalDriver::Temperature { .. } => "k_per_c",
            _ => "k_per_s",
        },
        Effect::VibratorViscousLoss => "c_v_n_mm_s_per_rad",
        Effect::InertiaRectification => "kappa",
        Effect::LinearBushFriction => "force_n",
        Effect::ToothCompliance => "compliance_um_per_n",
        Effect::MeshLoadSharingRipple => "ripple_rms",
    }
}

pub use rigfile::apply_params;

/// Clears the effect's parameters in `p` (back to the paper's model for this effect).
pub fn clear_params(effect: Effect, p: &mut EffectParams) {
    match effect {
        Effect::SpeedDependentAxialFriction => p.axial_corner_speed = 0.0,
        Effect::LoadDependentFriction => p.load_exponent = 0.0,
        Effect::CurrentSensorOffset => p.current_offset = 0.0,
        Effect::ThermalDrift => p.thermal_coeff = 0.0,
        Effect::VibratorViscousLoss => p.viscous_loss = 0.0,
        Effect::InertiaRectification => p.rectification = 0.0,
        Effect::LinearBushFriction => {
            p.bush_force = 0.0;
            p.bush_hold_torque = 0.0;
            p.bush_corner_speed = 0.0;
        }
        Effect::ToothCompliance => p.tooth_compliance = 0.0,
        Effect::MeshLoadSharingRipple => p.mesh_ripple_rms = 0.0,
    }
}

/// One sentence on what the effect means physically at the fitted values.
pub fn describe(effect: Effect, p: &EffectParams, thermal: ThermalDriver) -> String {
    let w5 = 2.0 * std::f64::consts::PI * 5.0;
    match effect {
        Effect::SpeedDependentAxialFriction => format!(
            "the axial friction coefficient falls at low cam speed (Eq. 40 with w_c = {:.1} rad/s: mu_ax/mu = {:.2} at 5 Hz, {:.2} at 15 Hz), the paper's own explanation of the low torque at 3.6 V",
            p.axial_corner_speed,
            model::effects::axial_friction_speed_factor(w5, p.axial_corner_speed),
            model::effects::axial_friction_speed_factor(3.0 * w5, p.axial_corner_speed)
        ),
        Effect::LoadDependentFriction => format!(
            "the tooth friction coefficient changes with load as (tau_rot / 1 N m)^{:.3} ({} with load, as seed 003's average friction coefficient with exponent 0.2)",
            p.load_exponent,
            if p.load_exponent >= 0.0 {
                "rising"
            } else {
                "falling"
            }
        ),
        Effect::CurrentSensorOffset => format!(
            "the current sensor reads {:+.1} mA off (its zero is not at Vcc/2)",
            p.current_offset * 1e3
        ),
        Effect::ThermalDrift => match thermal {
            ThermalDriver::Temperature { reference_c } => format!(
                "the torque constant falls by {:.3} %/K as the motor warms above {reference_c:.1} C, so the same torque takes more current",
                p.thermal_coeff * 100.0
            ),
            _ => format!(
                "the torque constant drifts by {:.3} % per minute of testing (no temperature column: time stands in for the motor temperature)",
                p.thermal_coeff * 6000.0
            ),
        },
        Effect::VibratorViscousLoss => format!(
            "the vibrator loses {:.3} N mm s/rad more than C3 = its calibrated viscous loss",
            p.viscous_loss * 1e3
        ),
        Effect::InertiaRectification => format!(
            "the inertia term is (1 {:+.2}) M w^2 e^2 / pi: {}",
            p.rectification,
            if p.rectification < -0.75 {
                "the drive takes the carrier's inertial power back, the term averages out over a turn"
            } else if p.rectification < -0.25 {
                "only the positive half of the inertial power is paid (the drive cannot take power back)"
            } else if p.rectification < 0.0 {
                "a little less than Eq. (10) assumes"
            } else {
                "the motor cannot take the inertial power back, so it does not average out"
            }
        ),
        Effect::LinearBushFriction => format!(
            "the carrier's linear bush rubs with {:.1} N (adding {:.2} N mm of cam torque at e = 1 mm) and holds loads below {} from backdriving",
            p.bush_force,
            model::effects::bush_cam_torque(p.bush_force, 1e-3) * 1e3,
            if p.bush_corner_speed >= 2999.0 {
                format!("{:.2} N m at every tested cam speed", p.bush_hold_torque)
            } else {
                format!(
                    "{:.2} N m / (1 + w_n / {:.0} rad/s)",
                    p.bush_hold_torque, p.bush_corner_speed
                )
            }
        ),
        Effect::ToothCompliance => format!(
            "the tooth contacts yield {:.2} um per N axially before they slide (stiffness {:.2} N/um), shortening the sliding stroke under load",
            p.tooth_compliance * 1e6,
            if p.tooth_compliance > 0.0 {
                1e-6 / p.tooth_compliance
            } else {
                f64::INFINITY
            }
        ),
        Effect::MeshLoadSharingRipple => format!(
            "the friction term scatters by {:.1} % rms from test to test: the current window sees the mesh at a random phase of its load sharing",
            p.mesh_ripple_rms * 100.0
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_and_apply_round_trip() {
        let p = EffectParams {
            axial_corner_speed: 20.0,
            load_exponent: 0.2,
            tooth_compliance: 1e-6,
            rectification: -1.0,
            viscous_loss: 1e-4,
            bush_force: 3.0,
            bush_hold_torque: 0.5,
            bush_corner_speed: 40.0,
            thermal_coeff: 2e-3,
            current_offset: 0.03,
            mesh_ripple_rms: 0.05,
        };
        let driver = ThermalDriver::Temperature { reference_c: 25.0 };
        let mut back = EffectParams::default();
        for e in Effect::ALL {
            apply_params(e, &report_params(e, &p, driver), &mut back).unwrap();
            assert!(!describe(e, &p, driver).is_empty());
        }
        assert_eq!(back, p);
        let mut bad = BTreeMap::new();
        bad.insert("omega_c".to_string(), 1.0);
        let e = apply_params(Effect::SpeedDependentAxialFriction, &bad, &mut back).unwrap_err();
        assert!(e.contains("omega_c_rad_s"), "{e}");
    }

    #[test]
    fn applicability_follows_the_columns() {
        let mut d = DataTraits {
            speed_levels: 3,
            load_levels: 10,
            rows: 150,
            thermal: ThermalDriver::Unavailable,
            held_rows: 0,
        };
        assert!(not_applicable(Effect::ThermalDrift, &d).is_some());
        assert!(not_applicable(Effect::LinearBushFriction, &d).is_some());
        assert!(not_applicable(Effect::CurrentSensorOffset, &d).is_none());
        d.thermal = ThermalDriver::Time;
        d.held_rows = 4;
        assert!(not_applicable(Effect::ThermalDrift, &d).is_none());
        assert!(not_applicable(Effect::LinearBushFriction, &d).is_none());
        d.speed_levels = 1;
        assert!(not_applicable(Effect::InertiaRectification, &d).is_some());
    }
}
