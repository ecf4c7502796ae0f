//! Buildability checks of a gear set, each with its value, limit and reason: undercut, tip
//! thickness, contact ratio and involute interference of each mesh (ISO 21771 / KHK
//! geometry, `model::involute`), tooth root stress at the rated load (ISO 6336-3 with the
//! load at the tip, against the paper's gear at its 3.68 N m limit) and the cam torque of
//! Eq. (10) against what the calibrated vibrator gives at the board's current limit.

use model::GearSet;
use model::hardware::{board, rs735};
use model::involute::{self, MeshSummary};
use serde::Serialize;

use super::{CamDrive, RigParams};

/// The checks' limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckLimits {
    /// Smallest tooth thickness at the tip, in modules (0.25 m is the usual floor for
    /// through-hardened gears; 0.4 m for case-hardened ones).
    pub min_tip_thickness_modules: f64,
    /// Smallest transverse contact ratio of each mesh.
    pub min_contact_ratio: f64,
    /// Smallest root-stress margin against the paper's gear at its limit.
    pub min_strength_margin: f64,
    /// Face width b (m) and permissible root stress sigma_FP (Pa) of the material, when
    /// known: the root stress is then also checked absolutely, sigma_F0 <= sigma_FP.
    pub material: Option<Material>,
}

/// Face width and permissible tooth-root stress (ISO 6336-5: sigma_FP = sigma_Flim Y_ST /
/// S_Fmin, e.g. about 290 MPa for through-hardened S45C with S_F 1.4 and Y_ST 2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Face width b, m.
    pub face_width: f64,
    /// Permissible root stress sigma_FP, Pa.
    pub root_stress_limit: f64,
}

/// Highest nominal root stress sigma_F0 of the four gears at `tau_out` (N m) for face width
/// `face_width` (m), Pa (ISO 6336-3 with the load at the tip).
pub fn root_stress(gear: &GearSet, tau_out: f64, face_width: f64) -> f64 {
    gear.root_stress_times_face_width(tau_out)
        .into_iter()
        .fold(0.0f64, f64::max)
        / face_width
}

impl Default for CheckLimits {
    /// Tip thickness 0.25 m, contact ratio 1.1, strength margin 1.
    fn default() -> Self {
        Self {
            min_tip_thickness_modules: 0.25,
            min_contact_ratio: 1.1,
            min_strength_margin: 1.0,
            material: None,
        }
    }
}

/// One check's verdict (JSON keys are the field names).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// What is checked, e.g. `undercut G1`, `contact ratio G3-G4`.
    pub name: String,
    /// Passed.
    pub passed: bool,
    /// The checked value.
    pub value: f64,
    /// The limit it is checked against.
    pub limit: f64,
    /// Why it matters and what to do, when it fails; what was checked when it passes.
    pub reason: String,
}

/// Cam torque the vibrator can give at cam speed `omega_n` (rad/s), N m: the calibration's
/// tau_cam = C1 i + C2 - (C3 w + C4) at the current the board allows, which is the smaller
/// of its current limit and what the bridge supply drives through the winding against the
/// back-EMF, (V_bridge - k_e w) / R. Zero when the motor cannot turn the cam that fast.
pub fn available_cam_torque(params: &RigParams, omega_n: f64) -> f64 {
    let voltage_limited = (board::BRIDGE_SUPPLY_V - rs735::KE_CAM_V_S_PER_RAD * omega_n.abs())
        / rs735::RESISTANCE_OHM;
    let current = params.max_current_a.min(voltage_limited);
    params.calibration.cam_torque(current, omega_n).max(0.0)
}

/// All checks of `gear` at `params`.
pub fn buildability(gear: &GearSet, params: &RigParams) -> Vec<Check> {
    let mut out = Vec::with_capacity(16);
    let z = gear.z();
    let x = gear.shift();
    let alpha = gear.pressure_angle();
    let lim = params.limits;
    for (mesh, s) in [
        ("G1-G2", gear.mesh12().summary()),
        ("G3-G4", gear.mesh34().summary()),
    ] {
        let first = if mesh == "G1-G2" { 0 } else { 2 };
        mesh_checks(&mut out, mesh, first, &s, z, x, alpha, &lim);
    }
    let margin = gear.strength_margin(params.tau_rot);
    out.push(Check {
        name: "root stress".into(),
        passed: margin >= lim.min_strength_margin,
        value: margin,
        limit: lim.min_strength_margin,
        reason: format!(
            "root-stress margin {margin:.3} at {:.3} N m (ISO 6336-3, load at the tip, against the paper's gear at 3.68 N m, same face width and material){}",
            params.tau_rot,
            if margin >= lim.min_strength_margin {
                ""
            } else {
                ": lower the rated load, raise the module or shift positively"
            }
        ),
    });
    if let Some(mat) = lim.material {
        let sigma = root_stress(gear, params.tau_rot, mat.face_width);
        let ok = sigma <= mat.root_stress_limit;
        out.push(Check {
            name: "root stress (material)".into(),
            passed: ok,
            value: sigma,
            limit: mat.root_stress_limit,
            reason: format!(
                "root stress {:.1} MPa at {:.3} N m on a {:.1} mm face (ISO 6336-3, load at the tip) {} the material's {:.1} MPa{}",
                sigma * 1e-6,
                params.tau_rot,
                mat.face_width * 1e3,
                if ok { "within" } else { "exceeds" },
                mat.root_stress_limit * 1e-6,
                if ok {
                    ""
                } else {
                    ": widen the face, raise the module or lower the rated load"
                }
            ),
        });
    }
    let omega_n = 2.0 * core::f64::consts::PI * params.vibration_hz;
    let drive = CamDrive {
        gear: *gear,
        eccentricity: params.eccentricity,
        carrier_mass: params.carrier_mass,
    };
    let required = drive.required_cam_torque(params.mu_s, params.tau_rot, omega_n);
    let available = available_cam_torque(params, omega_n);
    out.push(Check {
        name: "cam torque".into(),
        passed: required <= available,
        value: required,
        limit: available,
        reason: if required <= available {
            format!(
                "cam torque {:.1} N mm (Eq. 10) within the {:.1} N mm the vibrator gives at {:.2} A",
                required * 1e3,
                available * 1e3,
                params.max_current_a
            )
        } else if available <= 0.0 {
            format!(
                "cam torque {:.1} N mm (Eq. 10 at {:.3} N m, {:.1} Hz) cannot be produced: at that speed the vibrator's back-EMF and own losses leave no torque from the 12 V bridge; lower the frequency or choose a faster vibrator",
                required * 1e3,
                params.tau_rot,
                params.vibration_hz
            )
        } else {
            format!(
                "cam torque {:.1} N mm (Eq. 10 at {:.3} N m, {:.1} Hz) exceeds the {:.1} N mm the vibrator gives at the board's {:.2} A limit and 12 V: lower the frequency or load, or choose a bigger vibrator",
                required * 1e3,
                params.tau_rot,
                params.vibration_hz,
                available * 1e3,
                params.max_current_a
            )
        },
    });
    out
}

#[allow(
    clippy::too_many_arguments,
    reason = "one mesh's context, called twice"
)]
fn mesh_checks(
    out: &mut Vec<Check>,
    mesh: &str,
    first: usize,
    s: &MeshSummary,
    z: [u32; 4],
    x: [f64; 4],
    alpha: f64,
    lim: &CheckLimits,
) {
    for k in 0..2 {
        let g = first + k;
        let x_min = involute::min_shift_without_undercut(z[g], alpha);
        out.push(Check {
            name: format!("undercut G{}", g + 1),
            passed: !s.undercut[k],
            value: x[g],
            limit: x_min,
            reason: if s.undercut[k] {
                format!(
                    "G{} undercut: {} teeth need x >= {x_min:.3}, x is {:.3}; raise x{} or the tooth count",
                    g + 1,
                    z[g],
                    x[g],
                    g + 1
                )
            } else {
                format!("G{}: no undercut (x >= {x_min:.3})", g + 1)
            },
        });
        let t = s.tip_thickness_modules[k];
        let ok = t >= lim.min_tip_thickness_modules;
        out.push(Check {
            name: format!("tip thickness G{}", g + 1),
            passed: ok,
            value: t,
            limit: lim.min_tip_thickness_modules,
            reason: if ok {
                format!("G{} tip thickness {t:.3} m", g + 1)
            } else {
                format!(
                    "G{} tip thickness {t:.3} m below {:.2} m: the tip is (nearly) pointed; lower x{}",
                    g + 1,
                    lim.min_tip_thickness_modules,
                    g + 1
                )
            },
        });
        out.push(Check {
            name: format!("interference G{}", g + 1),
            passed: !s.interference[k],
            value: f64::from(u8::from(s.interference[k])),
            limit: 0.0,
            reason: if s.interference[k] {
                format!(
                    "G{} interference: the mating tip reaches below the root form circle in mesh {mesh}; raise x{}",
                    g + 1,
                    g + 1
                )
            } else {
                format!("G{}: no involute interference in mesh {mesh}", g + 1)
            },
        });
    }
    let eps = s.contact_ratio[0] + s.contact_ratio[1];
    let ok = eps >= lim.min_contact_ratio;
    out.push(Check {
        name: format!("contact ratio {mesh}"),
        passed: ok,
        value: eps,
        limit: lim.min_contact_ratio,
        reason: if ok {
            format!("mesh {mesh} contact ratio {eps:.3}")
        } else {
            format!(
                "mesh {mesh} contact ratio {eps:.3} below {:.2}: the teeth lose continuous contact; lower the shifts of this mesh or add teeth",
                lim.min_contact_ratio
            )
        },
    });
}
