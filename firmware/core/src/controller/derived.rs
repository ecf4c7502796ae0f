//! The rig parameters' checks and the quantities the control loop derives from them.

use protocol::{ParameterField, ParameterRejection, RejectReason, RigParameters};

use core::f32::consts::PI;

use crate::config::{CoreConfig, MotorRules};
use crate::estimator::Coefficients;
use crate::speed_loop::FeedForward;

/// Quantities derived from the rig parameters (recomputed when they change), in single
/// precision: the target's FPU is f32-only and the firmware carries no f64 trigonometry.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Derived {
    pub(crate) model: Coefficients,
    pub(crate) feed_forward: FeedForward,
    pub(crate) current_limit_a: f32,
    pub(crate) max_hz: f32,
    pub(crate) max_load_nm: f32,
    pub(crate) keeps_moving: bool,
    pub(crate) holds_at_rest: bool,
}

impl Derived {
    /// The derived quantities, or the first field the record's checks
    /// ([`RigParameters::validate`]) or the model (gear geometry, vibrator constants)
    /// refuse. Current and frequency limits above the board's are clamped to it here (a
    /// stored record from before keeps working), a release load above the cap is caught by
    /// `LOAD_LIMIT` at the cap; a new record asking for more is refused by
    /// [`check_board_caps`].
    pub(crate) fn new(p: &RigParameters, config: &CoreConfig) -> Result<Self, ParameterRejection> {
        p.validate()?;
        check_gear(p)?;
        let c = [p.c1_nmm_per_a, p.c2_nmm, p.c3_nmm_s_per_rad, p.c4_nmm].map(|c| c * 1e-3);
        // `model::Calibration::is_plausible`, in f32 (the tests hold the two together):
        // `validate` has checked the signs but allows a zero no-load current, which the
        // model's vibrator cannot have.
        let constants = [c[0], c[1], c[2], c[3], p.c5_a_s_per_rad, p.c6_a];
        if !(constants.iter().all(|v| v.is_finite())
            && c[0] > 0.0
            && c[2] >= 0.0
            && p.c5_a_s_per_rad >= 0.0
            && p.c6_a > 0.0)
        {
            return Err(ParameterRejection::new(
                ParameterField::C6,
                RejectReason::OutOfRange,
            ));
        }
        let factors = GearFactors::new(p.z, p.module_mm * 1e-3, p.pressure_angle_deg.to_radians());
        let e = p.eccentricity_mm * 1e-3;
        // Eq. (10): 2/pi mu_s tau_rot (axial force per torque) e + M w^2 e^2 / pi.
        let per_load = 2.0 / PI * p.mu_s * factors.axial_force_per_torque * e;
        let inertia = p.carrier_mass_kg * e * e / PI;
        let big_lambda = factors.big_lambda;
        Ok(Self {
            model: Coefficients::new(
                c,
                per_load,
                inertia,
                config.estimator.carrier_power_returned,
            ),
            feed_forward: FeedForward {
                resistance_ohm: config.motor.resistance_ohm,
                ke: config.motor.ke_cam_v_s_per_rad,
                c5: p.c5_a_s_per_rad,
                c6: p.c6_a,
                supply_v: config.supply_v,
            },
            current_limit_a: p.max_current_a.min(config.faults.overcurrent_a),
            max_hz: p.max_freq_hz.min(config.supervisor.max_freq_hz),
            max_load_nm: p.max_release_load_nm,
            keeps_moving: p.mu_d * big_lambda < 1.0,
            holds_at_rest: p.mu_s * big_lambda > 1.0,
        })
    }
}

/// The gear-set quantities the firmware needs, in f32: `model::GearSet`'s Eqs. (2)-(3)
/// (contact ratios, Lambda) and its axial force per output torque, evaluated once per
/// parameter record without f64 trigonometry. The tests hold them to the model's f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GearFactors {
    /// Lambda, Eq. (3).
    pub(crate) big_lambda: f32,
    /// 2 (1 + Z3/Z2) / (m Z4 cos a), N per N m.
    pub(crate) axial_force_per_torque: f32,
}

impl GearFactors {
    /// For tooth counts `z`, module `module` (m) and pressure angle `alpha` (rad, within
    /// 0..pi/4 as `model::GearSet::new` checks).
    pub(crate) fn new(z: [u16; 4], module: f32, alpha: f32) -> Self {
        let (c, s) = cos_sin(alpha);
        let t = s / c;
        let zf = z.map(f32::from);
        let (mut sum, mut sum_sq) = (0.0f32, 0.0f32);
        for zi in zf {
            // Eq. (2): eps = z / 2 pi (sqrt((z + 2)^2 - (z cos a)^2) / (z cos a) - tan a).
            let zc = zi * c;
            let eps = zi / (2.0 * PI) * (sqrtf((zi + 2.0) * (zi + 2.0) - zc * zc) / zc - t);
            sum += eps;
            sum_sq += eps * eps;
        }
        let n = f32::from(z[0].abs_diff(z[3]));
        Self {
            big_lambda: PI * (2.0 - sum + sum_sq) / n,
            axial_force_per_torque: 2.0 * (1.0 + zf[2] / zf[1]) / (module * zf[3] * c),
        }
    }
}

/// Square root of `x` > 0 (here (z + 2)^2 - (z cos a)^2, at least 4 z + 4): Newton's
/// iteration from the exponent-halving first guess (within 4 %; each step squares the
/// relative error, so four reach f32's rounding). libm's `sqrtf` is software on this
/// target with a 256-byte table; this runs once per parameter record. NaN for `x` <= 0 or
/// not finite (never the case for a gear set that passed validation).
fn sqrtf(x: f32) -> f32 {
    if !(x > 0.0 && x.is_finite()) {
        return f32::NAN;
    }
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1FBD_1DF5);
    for _ in 0..4 {
        y = 0.5 * (y + x / y);
    }
    y
}

/// cos and sin of `x` in 0..=pi/4 by their Taylor series to x^14 / x^15 (truncation error
/// below 1e-13 there, far under f32's rounding): no range reduction, no f64.
fn cos_sin(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let (mut c, mut s) = (1.0f32, 1.0f32);
    // Horner from the highest term: cos = 1 - x^2/2! (1 - x^2/(3*4) (1 - ...)).
    for k in (1..=7).rev() {
        let kc = (2 * k - 1) as f32 * (2 * k) as f32;
        let ks = (2 * k) as f32 * (2 * k + 1) as f32;
        c = 1.0 - x2 / kc * c;
        s = 1.0 - x2 / ks * s;
    }
    (c, x * s)
}

/// `model::GearSet::new`'s checks of a gear set, in f32 (no soft double on the target;
/// the tests hold the two together), as the record field they concern.
fn check_gear(p: &RigParameters) -> Result<(), ParameterRejection> {
    let z = p.z.map(u32::from);
    let alpha = p.pressure_angle_deg.to_radians();
    let (field, reason) = if z.contains(&0) {
        (ParameterField::Z, RejectReason::OutOfRange)
    } else if z[0] == z[3] || z[0] + z[1] != z[2] + z[3] {
        // Z1 = Z4 (no tooth difference) or unequal centre distances.
        (ParameterField::Z, RejectReason::Inconsistent)
    } else if !(p.module_mm.is_finite() && p.module_mm > 0.0) {
        (ParameterField::Module, RejectReason::OutOfRange)
    } else if !(alpha > 0.0 && alpha < PI / 4.0) {
        (ParameterField::PressureAngle, RejectReason::OutOfRange)
    } else {
        return Ok(());
    };
    Err(ParameterRejection::new(field, reason))
}

/// A new record may not ask for more than the board allows, and its vibrator constants
/// must be plausible for the board's motor: the model's two checks, the ones the host runs
/// before sending ([`model::BoardLimits::check`] against [`CoreConfig::board_limits`],
/// [`model::Calibration::check`] against [`crate::MotorConfig::constants`]). A limit above
/// its cap would be silently lowered, and a fit 36 times off Table 2 would be stored
/// without a word, so `SetParameters` refuses them naming the field.
///
/// The limits go through [`model::check_limits`] in `f32` against the config's own `f32`
/// caps: the same verdicts as [`check_rules`]' `f64` check against
/// [`CoreConfig::board_limits`] (those caps widened exactly), without double maths.
pub(crate) fn check_board_caps(
    p: &RigParameters,
    config: &CoreConfig,
) -> Result<(), ParameterRejection> {
    let limits = model::check_limits(
        [p.max_release_load_nm, p.max_current_a, p.max_freq_hz],
        [
            config.supervisor.max_release_load_nm,
            config.faults.overcurrent_a,
            config.supervisor.max_freq_hz,
        ],
    );
    rules(p, limits, &config.motor.rules())
}

/// The record's limits against `caps` and its constants against `motor`: the first field
/// refused, as the wire names it. The constants go through the model's rules in `f32`
/// ([`model::check_constants`], the rules of [`model::Calibration::check`]): the target has
/// no double-precision FPU, and host and firmware both use these rules, so they agree.
pub fn check_rules(
    p: &RigParameters,
    caps: &model::BoardLimits,
    motor: &model::hardware::MotorConstants,
) -> Result<(), ParameterRejection> {
    let requested = model::BoardLimits {
        max_release_load_nm: f64::from(p.max_release_load_nm),
        max_current_a: f64::from(p.max_current_a),
        max_freq_hz: f64::from(p.max_freq_hz),
    };
    rules(p, caps.check(&requested), &MotorRules::new(motor))
}

/// [`check_rules`] and [`check_board_caps`] after the limits' check (`limits`).
fn rules(
    p: &RigParameters,
    limits: Result<(), model::LimitIssue>,
    motor: &MotorRules,
) -> Result<(), ParameterRejection> {
    use model::{CalibrationField as C, LimitField as L, LimitIssueKind};
    if let Err(issue) = limits {
        let field = match issue.field {
            L::MaxReleaseLoad => ParameterField::MaxReleaseLoad,
            L::MaxCurrent => ParameterField::MaxCurrent,
            L::MaxFreq => ParameterField::MaxFreq,
        };
        let reason = match issue.kind {
            LimitIssueKind::NotFinite => RejectReason::NotFinite,
            LimitIssueKind::NotPositive => RejectReason::OutOfRange,
            LimitIssueKind::AboveCap => RejectReason::AboveBoardCap,
        };
        return Err(ParameterRejection::new(field, reason));
    }
    // The model's rules in f32 (no software double maths on the target).
    let si = [
        p.c1_nmm_per_a * 1e-3,
        p.c2_nmm * 1e-3,
        p.c3_nmm_s_per_rad * 1e-3,
        p.c4_nmm * 1e-3,
        p.c5_a_s_per_rad,
        p.c6_a,
    ];
    let checked = model::check_constants(si, motor.kt, motor.i0, motor.w0);
    if let Err(issue) = checked {
        let field = match issue.field {
            C::C1 => ParameterField::C1,
            C::C2 => ParameterField::C2,
            C::C3 => ParameterField::C3,
            C::C4 => ParameterField::C4,
            C::C5 => ParameterField::C5,
            C::C6 => ParameterField::C6,
        };
        let reason = match issue.kind {
            model::IssueKind::NotFinite => RejectReason::NotFinite,
            model::IssueKind::WrongSign { .. } => RejectReason::OutOfRange,
            model::IssueKind::Implausible { .. } => RejectReason::Implausible,
            model::IssueKind::Inconsistent { .. } => RejectReason::Inconsistent,
        };
        return Err(ParameterRejection::new(field, reason));
    }
    Ok(())
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests {
    use super::*;

    #[test]
    fn checks_agree_with_the_model() {
        let config = CoreConfig::default();
        let base = RigParameters::paper();
        let mut cases = Vec::new();
        for z in [
            [49, 51, 50, 50],
            [49, 51, 50, 49],
            [50, 50, 51, 50],
            [0, 51, 50, 1],
            [50, 50, 50, 50],
        ] {
            for (module_mm, alpha) in [
                (1.0, 20.0),
                (0.0, 20.0),
                (1.0, 0.0),
                (1.0, 44.9),
                (1.0, 45.0),
            ] {
                for (c1, c6) in [(62.1, 2.25), (0.0, 2.25), (62.1, 0.0), (-1.0, 2.25)] {
                    cases.push(RigParameters {
                        z,
                        module_mm,
                        pressure_angle_deg: alpha,
                        c1_nmm_per_a: c1,
                        c6_a: c6,
                        ..base
                    });
                }
            }
        }
        for p in cases {
            let model_ok = p.validate().is_ok()
                && model::GearSet::new(
                    p.z.map(u32::from),
                    f64::from(p.module_mm) * 1e-3,
                    f64::from(p.pressure_angle_deg).to_radians(),
                )
                .is_ok()
                && model::Calibration::from_paper_units(p.constants()).is_plausible();
            assert_eq!(Derived::new(&p, &config).is_ok(), model_ok, "{p:?}");
        }
    }

    #[test]
    fn sqrt_matches_libm() {
        let mut x = 1e-6f32;
        while x < 1e9 {
            let (got, want) = (sqrtf(x), libm::sqrtf(x));
            assert!(
                (got - want).abs() <= 2.0 * f32::EPSILON * want,
                "sqrt {x}: {got} vs {want}"
            );
            x *= 1.37;
        }
        for z in 4..200u16 {
            let x = f32::from((z + 2) * (z + 2)) - 0.88 * f32::from(z * z);
            assert!((sqrtf(x) - libm::sqrtf(x)).abs() <= 2.0 * f32::EPSILON * libm::sqrtf(x));
        }
        assert!(sqrtf(0.0).is_nan() && sqrtf(-1.0).is_nan() && sqrtf(f32::INFINITY).is_nan());
    }

    #[test]
    fn cos_sin_match_libm() {
        for k in 0..=90 {
            let x = k as f64 / 90.0 * core::f64::consts::FRAC_PI_4;
            let (c, s) = cos_sin(x as f32);
            assert!((f64::from(c) - x.cos()).abs() < 2e-7, "cos {x}");
            assert!((f64::from(s) - x.sin()).abs() < 2e-7, "sin {x}");
        }
    }

    #[test]
    fn gear_factors_match_the_model() {
        let mut sets: Vec<[u32; 4]> = model::TABLE1.to_vec();
        sets.extend([[20, 40, 31, 29], [100, 101, 102, 99], [30, 30, 29, 31]]);
        for z in sets {
            for (module_mm, alpha_deg) in [(1.0f32, 20.0f32), (0.5, 14.5), (2.0, 25.0)] {
                let Ok(g) = model::GearSet::new(
                    z,
                    f64::from(module_mm) * 1e-3,
                    f64::from(alpha_deg).to_radians(),
                ) else {
                    continue;
                };
                let f = GearFactors::new(
                    z.map(|v| v as u16),
                    module_mm * 1e-3,
                    alpha_deg.to_radians(),
                );
                let rel = |a: f32, b: f64| (f64::from(a) - b).abs() / b.abs();
                assert!(
                    rel(f.big_lambda, g.big_lambda()) < 1e-5,
                    "{z:?} {alpha_deg}: {} vs {}",
                    f.big_lambda,
                    g.big_lambda()
                );
                assert!(
                    rel(f.axial_force_per_torque, g.axial_force_per_torque()) < 1e-6,
                    "{z:?}"
                );
            }
        }
    }

    #[test]
    fn coefficients_match_the_f64_model() {
        let config = CoreConfig::default();
        let p = RigParameters::paper();
        let d = Derived::new(&p, &config).expect("the paper's parameters are valid");
        let gear = model::GearSet::new(
            p.z.map(u32::from),
            f64::from(p.module_mm) * 1e-3,
            f64::from(p.pressure_angle_deg).to_radians(),
        )
        .unwrap();
        for returned in [true, false] {
            let m = crate::estimator::EstimatorModel {
                drive: model::CamDrive {
                    gear,
                    eccentricity: f64::from(p.eccentricity_mm) * 1e-3,
                    carrier_mass: f64::from(p.carrier_mass_kg),
                },
                vibrator: model::Calibration::from_paper_units(p.constants()),
                mu: f64::from(p.mu_s),
                carrier_power_returned: returned,
            };
            let mut config = CoreConfig::default();
            config.estimator.carrier_power_returned = returned;
            let f = Derived::new(&p, &config).unwrap().model;
            for (i, w, tau_rot) in [(2.8, 31.4, 0.0), (3.2, 62.8, 1.5), (1.0, 94.2, 3.68)] {
                let close = |a: f32, b: f64| (f64::from(a) - b).abs() <= 1e-5 * (1.0 + b.abs());
                assert!(close(f.cam_torque(i as f32, w as f32), m.cam_torque(i, w)));
                assert!(close(
                    f.required(tau_rot as f32, w as f32),
                    m.required(tau_rot, w)
                ));
                let tau = m.required(tau_rot, w);
                assert!(close(f.load(tau as f32, w as f32), m.load(tau, w)));
                let h = m.coefficients();
                assert!(close(
                    h.required(tau_rot as f32, w as f32),
                    m.required(tau_rot, w)
                ));
            }
        }
        assert!(d.holds_at_rest && d.keeps_moving);
    }

    #[test]
    fn the_cores_f32_check_is_the_hosts() {
        // `SetParameters` (f32 limits, motor constants converted once) refuses exactly what
        // `check_rules` (the host's, f64 limits against `board_limits`) refuses.
        let config = CoreConfig::default();
        let motor = config.motor.rules();
        assert_eq!(motor, MotorRules::new(config.motor.constants()));
        let paper = RigParameters::paper();
        let caps = [
            config.supervisor.max_release_load_nm,
            config.faults.overcurrent_a,
            config.supervisor.max_freq_hz,
        ];
        let mut cases = vec![paper];
        for (i, &cap) in caps.iter().enumerate() {
            for v in [
                cap,
                f32::from_bits(cap.to_bits() - 1),
                f32::from_bits(cap.to_bits() + 1),
                f32::NAN,
                f32::INFINITY,
                0.0,
                -1.0,
            ] {
                let mut p = paper;
                match i {
                    0 => p.max_release_load_nm = v,
                    1 => p.max_current_a = v,
                    _ => p.max_freq_hz = v,
                }
                cases.push(p);
            }
        }
        for c1 in [0.0, 20.0, 62.1, 2258.0, f32::NAN] {
            cases.push(RigParameters {
                c1_nmm_per_a: c1,
                ..paper
            });
        }
        for c3 in [0.235, 0.5, -1.0] {
            cases.push(RigParameters {
                c3_nmm_s_per_rad: c3,
                ..paper
            });
        }
        let mut refused = 0;
        for p in cases {
            let host = check_rules(&p, &config.board_limits(), config.motor.constants());
            let core = check_board_caps(&p, &config);
            assert_eq!(core, host, "{p:?}");
            refused += usize::from(core.is_err());
        }
        assert!(refused >= 20, "{refused}");
    }
}
