//! The library of candidate effects, as `rig explain` uses it: a thin layer over the model's
//! one table of effects ([`model::effects::EFFECTS`]: name, law, parameters with units and
//! bounds, the data each needs, how the plant takes it) that adds what only a data set
//! knows, its thermal driver, and the one-sentence descriptions of the report. The laws
//! themselves are the model's ([`model::effects`]); adding an effect is a row of that table.
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
//!
//! (This table is the model table's summary; a test checks their names and keys agree.)

use std::collections::BTreeMap;

use model::effects::{
    DataSummary, Effect, EffectParam, EffectParams, KAPPA_EQ10, KAPPA_POWER_NOT_RETURNED, Param,
    ParamValue, ReportMap, kappa_returns_power,
};
use model::paper;

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

impl DataTraits {
    /// The summary the model's table judges ([`model::effects::DataNeeds::unmet`]).
    pub fn summary(&self) -> DataSummary {
        DataSummary {
            speed_levels: self.speed_levels,
            load_levels: self.load_levels,
            rows: self.rows,
            thermal_driver: self.thermal != ThermalDriver::Unavailable,
            held_rows: self.held_rows,
        }
    }
}

/// Why an effect cannot show in the data, or `None` when it can.
pub fn not_applicable(effect: Effect, data: &DataTraits) -> Option<&'static str> {
    effect.info().needs.unmet(&data.summary())
}

/// Bounds of a parameter in the fit (the model table's, [`Param::bounds`]).
pub fn bounds(param: Param) -> (f64, f64) {
    param.bounds()
}

/// Whether the effect's null value (zero) sits on the bound of its parameter, so the data
/// can only push it one way (a one-sided test).
pub fn one_sided(effect: Effect) -> bool {
    effect.info().one_sided
}

/// Parameters the effect adds to the model's likelihood (mean, noise and hold parameters).
pub fn parameter_count(effect: Effect) -> usize {
    effect.info().likelihood_params
}

/// Whether the reported parameter `key` belongs to a data set with thermal driver
/// `thermal`: the drift's coefficient is per kelvin against a temperature (with its
/// reference), per second against the time.
fn shown_with(key: &str, thermal: ThermalDriver) -> bool {
    let temperature = matches!(thermal, ThermalDriver::Temperature { .. });
    match key {
        "k_per_c" | "reference_c" => temperature,
        "k_per_s" => !temperature,
        _ => true,
    }
}

/// The value of a reported parameter in `p` for a data set with thermal driver `thermal`.
fn reported_value(param: &EffectParam, p: &EffectParams, thermal: ThermalDriver) -> Option<f64> {
    match (param.value, thermal) {
        (ParamValue::DataProperty, ThermalDriver::Temperature { reference_c }) => Some(reference_c),
        _ => param.report(p),
    }
}

/// The effect's parameters as reported and stored in rig files (SI with the unit in the name,
/// the viscous loss in C3's N mm s/rad; the model table's names and units).
pub fn report_params(
    effect: Effect,
    p: &EffectParams,
    thermal: ThermalDriver,
) -> BTreeMap<String, f64> {
    effect
        .info()
        .params
        .iter()
        .filter(|q| shown_with(q.key, thermal))
        .filter_map(|q| Some((q.key.to_string(), reported_value(q, p, thermal)?)))
        .collect()
}

/// Scale from the fitted parameter (see [`Param`]) to the reported one, for intervals;
/// `None` when the reported value is not a linear image (the corner speed is reported as the
/// square root of the fitted w_c^2).
pub fn report_scale(param: Param) -> Option<f64> {
    match param.report_map() {
        ReportMap::Scale(s) => Some(s),
        ReportMap::SquareRoot => None,
    }
}

/// The reported name of the effect's main parameter.
pub fn main_param_name(effect: Effect, thermal: ThermalDriver) -> &'static str {
    let info = effect.info();
    let main = info.mean.map_or(info.params[0].key, |m| m.key);
    if shown_with(main, thermal) {
        return main;
    }
    // The thermal drift against time: its coefficient per second.
    info.keys()
        .find(|k| *k != main && shown_with(k, thermal))
        .unwrap_or(main)
}

pub use rigfile::apply_params;

/// Clears the effect's parameters in `p` (back to the paper's model for this effect).
pub fn clear_params(effect: Effect, p: &mut EffectParams) {
    effect.info().clear(p);
}

/// One sentence on what the effect means physically at the fitted values.
pub fn describe(effect: Effect, p: &EffectParams, thermal: ThermalDriver) -> String {
    // The paper's slowest and fastest vibration, 5 and 15 Hz.
    let [slow, _, fast] = paper::VIBRATION_HZ.map(|hz| 2.0 * std::f64::consts::PI * hz);
    match effect {
        Effect::SpeedDependentAxialFriction => format!(
            "the axial friction coefficient falls at low cam speed (Eq. 40 with w_c = {:.1} rad/s: mu_ax/mu = {:.2} at 5 Hz, {:.2} at 15 Hz), the paper's own explanation of the low torque at 3.6 V",
            p.axial_corner_speed,
            model::effects::axial_friction_speed_factor(slow, p.axial_corner_speed),
            model::effects::axial_friction_speed_factor(fast, p.axial_corner_speed)
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
            if kappa_returns_power(p.rectification) {
                "the drive takes the carrier's inertial power back (a braking drive returns it through the gearhead, kappa -(1 + eta_f eta_b) / 2: -0.82 at 80 % each way; -1 returns all of it)"
            } else if p.rectification < 0.5 * (KAPPA_POWER_NOT_RETURNED + KAPPA_EQ10) {
                "only the positive half of the inertial power is paid (the drive cannot take power back)"
            } else if p.rectification < 0.0 {
                "a little less than Eq. (10) assumes"
            } else {
                "the motor cannot take the inertial power back, so it does not average out"
            }
        ),
        Effect::LinearBushFriction => format!(
            "the carrier's linear bush rubs with {:.1} N (adding {:.2} N mm of cam torque at e = {} mm) and holds loads below {} from backdriving",
            p.bush_force,
            model::effects::bush_cam_torque(p.bush_force, paper::ECCENTRICITY) * 1e3,
            paper::ECCENTRICITY * 1e3,
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

    #[test]
    fn the_docs_table_is_the_models() {
        let docs = include_str!("library.rs");
        for info in model::effects::EFFECTS {
            let row = docs
                .lines()
                .find(|l| l.starts_with(&format!("//! | `{}` |", info.name)))
                .unwrap_or_else(|| panic!("no docs row for {}", info.name));
            for key in info.keys() {
                let in_row = row.contains(&format!("`{key}`"));
                assert!(in_row || key == "reference_c", "{}: {key}", info.name);
            }
        }
        // The reported names per driver, as rig files have always had them.
        let temp = ThermalDriver::Temperature { reference_c: 25.0 };
        assert_eq!(main_param_name(Effect::ThermalDrift, temp), "k_per_c");
        assert_eq!(
            main_param_name(Effect::ThermalDrift, ThermalDriver::Time),
            "k_per_s"
        );
        assert_eq!(
            main_param_name(Effect::MeshLoadSharingRipple, temp),
            "ripple_rms"
        );
        assert_eq!(
            main_param_name(Effect::SpeedDependentAxialFriction, temp),
            "omega_c_rad_s"
        );
        let keys = |e, t| {
            report_params(e, &EffectParams::default(), t)
                .into_keys()
                .collect::<Vec<_>>()
        };
        assert_eq!(keys(Effect::ThermalDrift, temp), ["k_per_c", "reference_c"]);
        assert_eq!(
            keys(Effect::ThermalDrift, ThermalDriver::Unavailable),
            ["k_per_s"]
        );
        assert_eq!(
            keys(Effect::LoadDependentFriction, temp),
            ["exponent", "tau_ref_nm"]
        );
        assert_eq!(report_scale(Param::ViscousLoss), Some(1e3));
        assert_eq!(report_scale(Param::AxialCornerSq), None);
        assert_eq!(bounds(Param::ToothCompliance), (0.0, 1.0e-3));
    }
}
