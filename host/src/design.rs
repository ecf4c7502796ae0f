//! `rig design`: the design calculator over the paper's model (Eqs. 1-4, 6, 7, 10, 12, 41),
//! for standard and profile-shifted gears, with the buildability checks of [`checks`] and
//! the design search of [`search`].

use model::{Calibration, CamDrive, GearSet, Inertias, OutputShaft, friction, paper};
use serde::Serialize;

use crate::RigError;

pub mod checks;
pub mod search;

pub use checks::{Check, CheckLimits, Material};

/// The rig values a design is evaluated at (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigParams {
    /// Module, m.
    pub module: f64,
    /// Pressure angle, rad.
    pub pressure_angle: f64,
    /// Static friction coefficient.
    pub mu_s: f64,
    /// Dynamic friction coefficient.
    pub mu_d: f64,
    /// Cam eccentricity, m.
    pub eccentricity: f64,
    /// Carrier mass M_hat, kg.
    pub carrier_mass: f64,
    /// Load torque on the output, N m.
    pub tau_rot: f64,
    /// Vibration frequency, Hz.
    pub vibration_hz: f64,
    /// Inertias for Eq. (7), when known.
    pub inertias: Option<Inertias>,
    /// Vibrator calibration (C1-C6) the available cam torque is computed from.
    pub calibration: Calibration,
    /// The board's current limit for the vibrator, A.
    pub max_current_a: f64,
    /// Limits of the buildability checks.
    pub limits: CheckLimits,
}

impl Default for RigParams {
    /// The paper's rig: m 1 mm, 20 deg, mu_s 0.271, mu_d 0.174, e 1 mm, M_hat 3.82 kg,
    /// tau_rot 3.68 N m, 10 Hz.
    fn default() -> Self {
        Self {
            module: GearSet::MODULE_PAPER,
            pressure_angle: GearSet::PRESSURE_ANGLE_STANDARD,
            mu_s: paper::MU_S,
            mu_d: paper::MU_D,
            eccentricity: paper::ECCENTRICITY,
            carrier_mass: paper::CARRIER_MASS,
            tau_rot: paper::TAU_ROT_MAX,
            vibration_hz: paper::VIBRATION_HZ[1],
            inertias: None,
            calibration: paper::CALIBRATION,
            max_current_a: f64::from(protocol::RigParameters::paper().max_current_a),
            limits: CheckLimits::default(),
        }
    }
}

/// One evaluated gear set, as printed by `rig design` (JSON keys are the field names).
#[derive(Debug, Clone, Serialize)]
pub struct DesignReport {
    /// Tooth counts [Z1, Z2, Z3, Z4].
    pub z: [u32; 4],
    /// Tooth difference n = |Z1 - Z4|.
    pub n: u32,
    /// Reduction ratio rho (Eq. 1).
    pub rho: f64,
    /// Contact ratios epsilon_1..4 (Eq. 2).
    pub contact_ratios: [f64; 4],
    /// Lambda (Eq. 3).
    pub big_lambda: f64,
    /// lambda (Eq. 41) for the cam's eccentricity.
    pub small_lambda: f64,
    /// mu_s Lambda.
    pub mu_s_lambda: f64,
    /// mu_d Lambda.
    pub mu_d_lambda: f64,
    /// Hold verdict of Eq. (4): mu_s Lambda > 1.
    pub holds_load: bool,
    /// mu_d Lambda < 1: once moving, the output keeps moving after vibration stops.
    pub keeps_moving_after_stop: bool,
    /// Vibration (cam) speed, rad/s.
    pub omega_n_rad_s: f64,
    /// Load torque the requirement is evaluated at, N m.
    pub tau_rot_nm: f64,
    /// Required cam torque (Eq. 10, mu = mu_s), N m.
    pub tau_cam_hat_nm: f64,
    /// Equivalent output inertia (Eq. 7), kg m^2, when the masses were given.
    pub i_hat_kg_m2: Option<f64>,
    /// Friction coefficient from the given gross efficiency (Eqs. 12-13).
    pub mu_from_eta: Option<f64>,
    /// Warnings for the designer.
    pub warnings: Vec<String>,
    /// Profile shift coefficients x1..x4.
    pub x: [f64; 4],
    /// Working pressure angles of the G1-G2 and G3-G4 meshes, degrees.
    pub working_pressure_angles_deg: [f64; 2],
    /// Working centre distance (planet axis to central axis), mm.
    pub centre_distance_mm: f64,
    /// Transverse contact ratio of each mesh [eps_12, eps_34].
    pub mesh_contact_ratios: [f64; 2],
    /// Lambda from Willis' equation and Eq. (19) (see `model::gear`).
    pub big_lambda_willis: f64,
    /// mu_s times the smaller of the two Lambdas: the search's hold value.
    pub mu_s_lambda_conservative: f64,
    /// mu_d times the smaller of the two Lambdas: the search's stop value.
    pub mu_d_lambda_conservative: f64,
    /// Cam torque the vibrator can give at the board's current limit and this speed, N m.
    pub tau_cam_available_nm: f64,
    /// Root-stress margin against the paper's gear at 3.68 N m (ISO 6336-3, tip load).
    pub strength_margin: f64,
    /// The buildability checks, each with its value, limit and reason.
    pub checks: Vec<Check>,
}

/// Evaluates standard gears `z` at `params`; `eta_gross` adds the friction coefficient it
/// implies.
pub fn evaluate(
    z: [u32; 4],
    params: &RigParams,
    eta_gross: Option<f64>,
) -> Result<DesignReport, RigError> {
    evaluate_shifted(z, [0.0; 4], params, eta_gross)
}

/// Evaluates tooth counts `z` with profile shifts `x` at `params`.
pub fn evaluate_shifted(
    z: [u32; 4],
    x: [f64; 4],
    params: &RigParams,
    eta_gross: Option<f64>,
) -> Result<DesignReport, RigError> {
    let gear = GearSet::shifted(z, x, params.module, params.pressure_angle)
        .map_err(|source| RigError::Gear { z, source })?;
    Ok(report(&gear, params, eta_gross))
}

/// The report of a validated gear set.
pub fn report(gear: &GearSet, params: &RigParams, eta_gross: Option<f64>) -> DesignReport {
    let gear = *gear;
    let z = gear.z();
    let drive = CamDrive {
        gear,
        eccentricity: params.eccentricity,
        carrier_mass: params.carrier_mass,
    };
    let omega_n = 2.0 * core::f64::consts::PI * params.vibration_hz;
    let big_lambda = gear.big_lambda();
    let shaft = OutputShaft::new(&gear, params.eccentricity, 1.0, params.mu_s, params.mu_d);
    let mut warnings = Vec::new();
    if shaft.keeps_moving_after_stop() {
        warnings.push(format!(
            "mu_d*Lambda = {:.3} < 1: once backdriven, the output keeps moving after vibration stops",
            params.mu_d * big_lambda
        ));
    }
    if !shaft.holds_at_rest() {
        warnings.push(format!(
            "mu_s*Lambda = {:.3} <= 1: the gear does not hold its load without vibration",
            params.mu_s * big_lambda
        ));
    }
    if params.eccentricity < 0.3e-3 {
        warnings.push(
            "eccentricity below 0.3 mm: the paper needs at least 0.3 mm to clear the backlash"
                .into(),
        );
    }
    let checks = checks::buildability(&gear, params);
    warnings.extend(
        checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.reason.clone()),
    );
    let [eps12, eps34] = [gear.mesh12().summary(), gear.mesh34().summary()]
        .map(|m| m.contact_ratio[0] + m.contact_ratio[1]);
    let required = drive.required_cam_torque(params.mu_s, params.tau_rot, omega_n);
    DesignReport {
        z,
        n: gear.n(),
        rho: gear.rho(),
        contact_ratios: gear.contact_ratios(),
        big_lambda,
        small_lambda: gear.small_lambda(params.eccentricity),
        mu_s_lambda: params.mu_s * big_lambda,
        mu_d_lambda: params.mu_d * big_lambda,
        holds_load: shaft.holds_at_rest(),
        keeps_moving_after_stop: shaft.keeps_moving_after_stop(),
        omega_n_rad_s: omega_n,
        tau_rot_nm: params.tau_rot,
        tau_cam_hat_nm: required,
        i_hat_kg_m2: params.inertias.map(|i| gear.equivalent_inertia(&i)),
        mu_from_eta: eta_gross.map(|eta| friction::mu_from_eta_gross(&gear, eta)),
        warnings,
        x: gear.shift(),
        working_pressure_angles_deg: gear.working_pressure_angles().map(f64::to_degrees),
        centre_distance_mm: gear.centre_distance() * 1e3,
        mesh_contact_ratios: [eps12, eps34],
        big_lambda_willis: gear.big_lambda_willis(),
        mu_s_lambda_conservative: params.mu_s * gear.big_lambda_conservative(),
        mu_d_lambda_conservative: params.mu_d * gear.big_lambda_conservative(),
        tau_cam_available_nm: checks::available_cam_torque(params, omega_n),
        strength_margin: gear.strength_margin(params.tau_rot),
        checks,
    }
}

/// Human-readable form of one report.
pub fn render_text(r: &DesignReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let [z1, z2, z3, z4] = r.z;
    let e = r.contact_ratios;
    let _ = writeln!(s, "gear set Z1..Z4 = {z1}, {z2}, {z3}, {z4} (n = {})", r.n);
    if r.x != [0.0; 4] {
        let [x1, x2, x3, x4] = r.x;
        let [w12, w34] = r.working_pressure_angles_deg;
        let _ = writeln!(
            s,
            "  profile shift x1..x4       {x1:.4} {x2:.4} {x3:.4} {x4:.4}"
        );
        let _ = writeln!(s, "  working pressure angles    {w12:.4} {w34:.4} deg");
        let _ = writeln!(
            s,
            "  Lambda_W (Willis, Eq. 19)  {:>10.3}",
            r.big_lambda_willis
        );
    }
    let _ = writeln!(
        s,
        "  centre distance            {:>10.4} mm",
        r.centre_distance_mm
    );
    let _ = writeln!(s, "  rho (Eq. 1)                {:>10.3}", r.rho);
    let _ = writeln!(
        s,
        "  contact ratios (Eq. 2)     {:.3} {:.3} {:.3} {:.3}",
        e[0], e[1], e[2], e[3]
    );
    if r.x == [0.0; 4] {
        let _ = writeln!(s, "  Lambda (Eq. 3)             {:>10.3}", r.big_lambda);
    } else {
        let _ = writeln!(s, "  Lambda (Eq. 3 generalised) {:>10.3}", r.big_lambda);
    }
    let _ = writeln!(s, "  lambda (Eq. 41)            {:>10.4}", r.small_lambda);
    let _ = writeln!(s, "  mu_s*Lambda                {:>10.3}", r.mu_s_lambda);
    let _ = writeln!(s, "  mu_d*Lambda                {:>10.3}", r.mu_d_lambda);
    let verdict = if r.holds_load {
        "holds its load without vibration"
    } else {
        "backdrives without vibration"
    };
    let _ = writeln!(s, "  hold verdict (Eq. 4)       {verdict}");
    let _ = writeln!(
        s,
        "  tau_cam_hat (Eq. 10)       {:>10.2} N mm at tau_rot {:.3} N m, {:.1} Hz",
        r.tau_cam_hat_nm * 1e3,
        r.tau_rot_nm,
        r.omega_n_rad_s / (2.0 * core::f64::consts::PI)
    );
    let _ = writeln!(
        s,
        "  cam torque available       {:>10.2} N mm at the current limit",
        r.tau_cam_available_nm * 1e3
    );
    let _ = writeln!(
        s,
        "  strength margin (ISO 6336) {:>10.3}",
        r.strength_margin
    );
    if let Some(i) = r.i_hat_kg_m2 {
        let _ = writeln!(s, "  I_hat (Eq. 7)              {i:>10.4} kg m^2");
    }
    if let Some(mu) = r.mu_from_eta {
        let _ = writeln!(s, "  mu from eta_gross (Eq. 12) {mu:>10.4}");
    }
    for w in &r.warnings {
        let _ = writeln!(s, "  warning: {w}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1_verdicts_and_warnings() {
        for z in model::TABLE1 {
            let r = evaluate(z, &RigParams::default(), None).unwrap();
            assert_eq!(r.holds_load, r.n == 1);
            // mu_d Lambda < 1 for every Table 1 set: all keep moving after vibration stops.
            assert!(r.keeps_moving_after_stop);
            assert!(r.warnings.iter().any(|w| w.contains("mu_d*Lambda")));
        }
    }

    #[test]
    fn zero_shift_gives_the_standard_numbers_and_no_new_warning() {
        let std = evaluate(paper::RIG_Z, &RigParams::default(), None).unwrap();
        let shifted =
            evaluate_shifted(paper::RIG_Z, [0.0; 4], &RigParams::default(), None).unwrap();
        assert_eq!(std.big_lambda, shifted.big_lambda);
        assert_eq!(std.contact_ratios, shifted.contact_ratios);
        assert_eq!(std.tau_cam_hat_nm, shifted.tau_cam_hat_nm);
        assert!((std.big_lambda * paper::MU_S - 1.336).abs() < 1e-3);
        // The paper's gear passes every buildability check at its own limit.
        assert!(std.checks.iter().all(|c| c.passed), "{:?}", std.checks);
        assert_eq!(std.warnings.len(), 1, "{:?}", std.warnings); // mu_d Lambda < 1 only
        assert!((std.centre_distance_mm - 50.0).abs() < 1e-12);
    }

    #[test]
    fn undercut_and_unreachable_cam_torque_are_warned() {
        let r = evaluate([10, 12, 11, 11], &RigParams::default(), None).unwrap();
        assert!(
            r.warnings.iter().any(|w| w.contains("undercut")),
            "{:?}",
            r.warnings
        );
        let fast = RigParams {
            vibration_hz: 100.0,
            ..RigParams::default()
        };
        let r = evaluate(paper::RIG_Z, &fast, None).unwrap();
        assert!(r.tau_cam_available_nm < r.tau_cam_hat_nm);
        assert!(
            r.warnings.iter().any(|w| w.contains("cam torque")),
            "{:?}",
            r.warnings
        );
    }

    #[test]
    fn root_stress_is_checked_against_the_material_when_given() {
        // The paper's gear at 3.68 N m on a 10 mm face: F_t = 2 tau / (m Z4) = 147 N, times
        // Y_Fa Y_Sa Y_eps ~ 2.32 * 1.70 * 0.68 over b m: about 39 MPa.
        let with = |limit_mpa: f64| RigParams {
            limits: CheckLimits {
                material: Some(Material {
                    face_width: 10e-3,
                    root_stress_limit: limit_mpa * 1e6,
                }),
                ..CheckLimits::default()
            },
            ..RigParams::default()
        };
        let r = evaluate(paper::RIG_Z, &with(100.0), None).unwrap();
        let c = r
            .checks
            .iter()
            .find(|c| c.name == "root stress (material)")
            .unwrap();
        assert!(c.passed && (c.value * 1e-6 - 39.0).abs() < 3.0, "{c:?}");
        let r = evaluate(paper::RIG_Z, &with(30.0), None).unwrap();
        assert!(
            r.warnings
                .iter()
                .any(|w| w.contains("exceeds the material")),
            "{:?}",
            r.warnings
        );
    }

    #[test]
    fn bad_gear_set_is_an_error_not_a_panic() {
        let err = evaluate([49, 51, 50, 51], &RigParams::default(), None).unwrap_err();
        assert!(
            err.to_string().contains("unequal centre distances"),
            "{err}"
        );
    }

    #[test]
    fn mu_from_eta_matches_the_paper() {
        let r = evaluate(
            paper::FIG5_Z,
            &RigParams::default(),
            Some(paper::ETA_GROSS_STATIC),
        )
        .unwrap();
        assert!((r.mu_from_eta.unwrap() - 0.271).abs() < 0.001);
        assert!(render_text(&r).contains("mu from eta_gross"));
    }
}
