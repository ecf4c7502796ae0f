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
        Self::check(p)?;
        let alpha = p.pressure_angle_deg.to_radians();
        let x = p.profile_shift;
        let meshes = (x != [0.0; 4]).then(|| shifted_meshes(p.z, x, alpha));
        let c = [p.c1_nmm_per_a, p.c2_nmm, p.c3_nmm_s_per_rad, p.c4_nmm].map(|c| c * 1e-3);
        let factors = GearFactors::with_meshes(p.z, p.module_mm * 1e-3, alpha, meshes.as_ref());
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

    /// [`Derived::new`]'s checks alone (`SetParameters` checks under the core lock; the
    /// factors are computed once, when the stored record becomes active).
    /// A shifted gear's check solves only the two working centre distances.
    pub(crate) fn check(p: &RigParameters) -> Result<(), ParameterRejection> {
        p.validate()?;
        check_gear(p)?;
        // `model::Calibration::is_plausible`, in f32 (the tests hold the two together):
        // `validate` has checked the signs but allows a zero no-load current, which the
        // model's vibrator cannot have.
        let c = [p.c1_nmm_per_a, p.c2_nmm, p.c3_nmm_s_per_rad, p.c4_nmm].map(|c| c * 1e-3);
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
        Ok(())
    }
}

/// The gear-set quantities the firmware needs, in f32: `model::GearSet`'s Eqs. (2)-(3)
/// (contact ratios, Lambda; for profile-shifted gears their generalisation, the smaller of
/// the static-balance and Willis' Lambda as [`model::GearSet::big_lambda`] takes) and its
/// axial force per output torque, evaluated once per parameter record without f64
/// trigonometry. The tests hold them to the model's f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GearFactors {
    /// Lambda, Eq. (3) (generalised for shifted gears).
    pub(crate) big_lambda: f32,
    /// 2 (1 + Z3/Z2) / (m Z4 cos a), N per N m (the shift leaves it unchanged: R'_4 cos
    /// alpha_w34 is G4's base radius).
    pub(crate) axial_force_per_torque: f32,
}

impl GearFactors {
    /// For tooth counts `z`, profile shifts `x`, module `module` (m) and pressure angle
    /// `alpha` (rad, within 0..pi/4), of a gear set [`check_gear`] accepted.
    #[cfg(test)]
    pub(crate) fn new(z: [u16; 4], x: [f32; 4], module: f32, alpha: f32) -> Self {
        let meshes = (x != [0.0; 4]).then(|| shifted_meshes(z, x, alpha));
        Self::with_meshes(z, module, alpha, meshes.as_ref())
    }

    /// For tooth counts `z`, module `module` (m), pressure angle `alpha` (rad) and, for
    /// shifted gears, the two meshes ([`shifted_meshes`]).
    fn with_meshes(
        z: [u16; 4],
        module: f32,
        alpha: f32,
        meshes: Option<&[ShiftedMesh; 2]>,
    ) -> Self {
        let (c, s) = cos_sin(alpha);
        let t = s / c;
        let zf = z.map(f32::from);
        let axial_force_per_torque = 2.0 * (1.0 + zf[2] / zf[1]) / (module * zf[3] * c);
        if let Some([m12, m34]) = meshes {
            return Self {
                big_lambda: shifted_lambda(zf, c, m12, m34),
                axial_force_per_torque,
            };
        }
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
            axial_force_per_torque,
        }
    }
}

/// One mesh of profile-shifted gears in f32, lengths in modules: `model::involute::Mesh`'s
/// working pressure angle, working centre distance and contact ratios (ISO 21771, tip
/// shortening keeping the 0.25 m bottom clearance).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ShiftedMesh {
    /// cos of the working pressure angle alpha_w (NaN when the shifts are too negative for
    /// a working pressure angle, and then every field).
    cos_w: f32,
    /// tan alpha_w.
    tan_w: f32,
    /// Working centre distance a_w, modules.
    centre_distance: f32,
    /// Tip radii (with tip shortening), modules.
    tip: [f32; 2],
}

impl ShiftedMesh {
    /// The mesh of tooth counts `z` and shifts `x` at reference pressure angle `alpha`
    /// (cosine `c`, tangent `t`): its working pressure angle and centre distance (what the
    /// check needs; the contact ratios follow on demand).
    fn new(z: [f32; 2], x: [f32; 2], alpha: f32, c: f32, t: f32) -> Self {
        let (centre_distance, cos_w, sin_w) = working_centre_distance(z, x, alpha, c, t);
        let tan_w = sin_w / cos_w;
        let reference = (z[0] + z[1]) / 2.0;
        // Tip shortening k = x1 + x2 - y (never a lengthening), y = a_w - a in modules.
        let k = (x[0] + x[1] - (centre_distance - reference)).max(0.0);
        Self {
            cos_w,
            tan_w,
            centre_distance,
            tip: [0, 1].map(|i| z[i] / 2.0 + 1.0 + x[i] - k),
        }
    }

    /// Approach/recess contact ratio of gear `i` (`z` teeth; Eq. 2 generalised) at reference
    /// pressure angle cosine `c`: z / (2 pi) (tan alpha_a - tan alpha_w).
    fn contact_ratio(&self, i: usize, z: f32, c: f32) -> f32 {
        let tip = self.tip[i];
        let base = z * c / 2.0;
        // tan of the tip's pressure angle: sqrt(r_a^2 - r_b^2) / r_b (0 at the base circle).
        let tan_a = if tip > base {
            sqrtf(tip * tip - base * base) / base
        } else {
            0.0
        };
        z / (2.0 * PI) * (tan_a - self.tan_w)
    }

    /// h = 1 - eps_i - eps_j + eps_i^2 + eps_j^2 of the mesh of tooth counts `z`, Eq. (13).
    fn h(&self, z: [f32; 2], c: f32) -> f32 {
        let (a, b) = (
            self.contact_ratio(0, z[0], c),
            self.contact_ratio(1, z[1], c),
        );
        1.0 - a - b + a * a + b * b
    }
}

/// The working centre distance (modules) of the mesh of tooth counts `z` and shifts `x` at
/// reference pressure angle `alpha` (cosine `c`, tangent `t`), with the cosine and sine of
/// its working pressure angle: ISO 21771 Eq. 52, inv alpha_w = 2 tan alpha (x1 + x2) /
/// (z1 + z2) + inv alpha, and a_w = a cos alpha / cos alpha_w.
fn working_centre_distance(
    z: [f32; 2],
    x: [f32; 2],
    alpha: f32,
    c: f32,
    t: f32,
) -> (f32, f32, f32) {
    let z_sum = z[0] + z[1];
    let (cos_w, sin_w) = inv_inverse_cos_sin(2.0 * t * (x[0] + x[1]) / z_sum + (t - alpha));
    (z_sum / 2.0 * c / cos_w, cos_w, sin_w)
}

/// The G1-G2 and G3-G4 meshes of tooth counts `z` and shifts `x` at pressure angle `alpha`.
fn shifted_meshes(z: [u16; 4], x: [f32; 4], alpha: f32) -> [ShiftedMesh; 2] {
    let (c, s) = cos_sin(alpha);
    let (t, zf) = (s / c, z.map(f32::from));
    [
        ShiftedMesh::new([zf[0], zf[1]], [x[0], x[1]], alpha, c, t),
        ShiftedMesh::new([zf[2], zf[3]], [x[2], x[3]], alpha, c, t),
    ]
}

/// `model::gear::lambdas_of_meshes` in f32: the smaller of the static balance's
/// pi cos alpha (h12 / cos alpha_w12 + h34 / cos alpha_w34) / (2 |R'_2 - R'_3|) (lengths in
/// modules) and Willis' pi (h12 (1/Z1 + 1/Z2) + h34 (1/Z3 + 1/Z4)) / (1 - min(u, 1/u)).
fn shifted_lambda(z: [f32; 4], c: f32, m12: &ShiftedMesh, m34: &ShiftedMesh) -> f32 {
    let [z1, z2, z3, z4] = z;
    let (h12, h34) = (m12.h([z1, z2], c), m34.h([z3, z4], c));
    let r2 = m12.centre_distance * z2 / (z1 + z2);
    let r3 = m34.centre_distance * z3 / (z3 + z4);
    let general = PI * c * (h12 / m12.cos_w + h34 / m34.cos_w) / (2.0 * (r2 - r3).abs());
    let u = z1 * z3 / (z2 * z4);
    let loss = PI * (h12 * (1.0 / z1 + 1.0 / z2) + h34 * (1.0 / z3 + 1.0 / z4));
    general.min(loss / (1.0 - u.min(1.0 / u)))
}

/// cos and sin of the angle whose involute (tan a - a) is `v`: Newton's iteration from the
/// series inversion of inv a = a^3/3 + 2 a^5/15 + 17 a^7/315, a ~ y (1 - 2 y^2/15 +
/// 3 y^4/175) with y = (3 v)^(1/3) (within 1e-5 rad at 20 degrees), capped at 1.5 rad (as
/// far as [`cos_sin`] is accurate, beyond any working pressure angle of a valid gear).
/// Newton on this convex, rising function converges from either side, quadratically: after
/// a step below 1e-4 rad the error is below 1e-7 rad for any angle above 0.1 rad, so it
/// stops there, and the last step turns cos and sin to first order (error step^2 / 2).
/// NaN for `v` <= 0 or not finite (the shifts are too negative for a working pressure angle).
fn inv_inverse_cos_sin(v: f32) -> (f32, f32) {
    if !(v > 0.0 && v.is_finite()) {
        return (f32::NAN, f32::NAN);
    }
    let y = cbrtf(3.0 * v);
    let y2 = y * y;
    let mut a = (y * (1.0 - 2.0 / 15.0 * y2 + 3.0 / 175.0 * y2 * y2)).min(1.5);
    for _ in 0..20 {
        let (c, s) = cos_sin(a);
        let t = s / c;
        // d/da (tan a - a) = tan^2 a.
        let step = (t - a - v) / (t * t);
        a -= step;
        if step.abs() <= 1e-4 {
            return (c + s * step, s - c * step);
        }
    }
    cos_sin(a)
}

/// Cube root of `x` > 0 by Newton's iteration from the exponent-thirding first guess (as
/// [`sqrtf`]); only the start of [`inv_inverse_cos_sin`], so a few ulps do not matter.
fn cbrtf(x: f32) -> f32 {
    // The first guess is within 6 %; each step squares the error: 2 reach 2e-5 (a start).
    let mut y = f32::from_bits(x.to_bits() / 3 + 0x2A51_4067);
    for _ in 0..2 {
        y = (2.0 * y + x / (y * y)) * (1.0 / 3.0);
    }
    y
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

/// cos and sin of `x` in 0..=1.5 by their Taylor series to x^14 / x^15 (truncation error
/// 4e-11 at 1.5, far under f32's rounding; to x^8 / x^9 below 0.8 rad): no range
/// reduction, no f64.
fn cos_sin(x: f32) -> (f32, f32) {
    // Horner from the highest term: cos = 1 - x^2/2! (1 - x^2/(3*4) (1 - ...)), with the
    // factors' reciprocals (folded at compile time: no division on the target).
    const COS: [f32; 7] = [
        1.0 / 2.0,
        1.0 / 12.0,
        1.0 / 30.0,
        1.0 / 56.0,
        1.0 / 90.0,
        1.0 / 132.0,
        1.0 / 182.0,
    ];
    const SIN: [f32; 7] = [
        1.0 / 6.0,
        1.0 / 20.0,
        1.0 / 42.0,
        1.0 / 72.0,
        1.0 / 110.0,
        1.0 / 156.0,
        1.0 / 210.0,
    ];
    let x2 = x * x;
    let (mut c, mut s) = (1.0f32, 1.0f32);
    // Below 0.8 rad five terms each leave under 3e-8 (x^10 / 10!): half f32's rounding.
    let terms = if x2 < 0.64 { 5 } else { 7 };
    for k in (0..terms).rev() {
        c = 1.0 - x2 * COS[k] * c;
        s = 1.0 - x2 * SIN[k] * s;
    }
    (c, x * s)
}

/// `model::GearSet::shifted`'s checks of a gear set, in f32 (no soft double on the target;
/// the tests hold the two together), as the record field they concern: standard gears need
/// Z1 + Z2 = Z3 + Z4; shifted ones the same working centre distance for both meshes
/// (within [`model::gear::CENTRE_DISTANCE_TOLERANCE_MODULES`]).
fn check_gear(p: &RigParameters) -> Result<(), ParameterRejection> {
    use ParameterField::{Module, PressureAngle, ProfileShift, Z};
    let z = p.z.map(u32::from);
    let alpha = p.pressure_angle_deg.to_radians();
    let x = p.profile_shift;
    let standard = x == [0.0; 4];
    let (field, reason) = if !x.iter().all(|xi| SHIFT_RANGE.contains(xi)) {
        (ProfileShift, RejectReason::OutOfRange)
    } else if z.contains(&0) {
        (Z, RejectReason::OutOfRange)
    } else if z[0] == z[3] || (standard && z[0] + z[1] != z[2] + z[3]) {
        // Z1 = Z4 (no tooth difference) or, without shifts, unequal centre distances.
        (Z, RejectReason::Inconsistent)
    } else if !(p.module_mm.is_finite() && p.module_mm > 0.0) {
        (Module, RejectReason::OutOfRange)
    } else if !(alpha > 0.0 && alpha < PI / 4.0) {
        (PressureAngle, RejectReason::OutOfRange)
    } else if standard {
        return Ok(());
    } else {
        let (c, s) = cos_sin(alpha);
        let (t, zf) = (s / c, p.z.map(f32::from));
        let a12 = working_centre_distance([zf[0], zf[1]], [x[0], x[1]], alpha, c, t).0;
        let a34 = working_centre_distance([zf[2], zf[3]], [x[2], x[3]], alpha, c, t).0;
        // NaN (a mesh without a working pressure angle) fails the comparison too.
        if (a12 - a34).abs() <= CENTRE_DISTANCE_TOLERANCE {
            return Ok(());
        }
        (ProfileShift, RejectReason::Inconsistent)
    };
    Err(ParameterRejection::new(field, reason))
}

/// The profile shift coefficients `model::GearSet::shifted` accepts.
#[allow(clippy::cast_possible_truncation, reason = "-1 and 2 are exact in f32")]
const SHIFT_RANGE: core::ops::RangeInclusive<f32> =
    model::gear::PROFILE_SHIFT_MIN as f32..=model::gear::PROFILE_SHIFT_MAX as f32;

/// [`model::gear::CENTRE_DISTANCE_TOLERANCE_MODULES`] in f32.
#[allow(
    clippy::cast_possible_truncation,
    reason = "1e-3 in f32: the tolerance, not a measured value"
)]
const CENTRE_DISTANCE_TOLERANCE: f32 = model::gear::CENTRE_DISTANCE_TOLERANCE_MODULES as f32;

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
    fn inverse_involute_matches_the_model() {
        // From a working pressure angle of 6 degrees to 1.2 rad (shifts of 2 on 4 teeth at 45
        // degrees), where the f32 rounding of tan a - a allows.
        let mut a = 6f64.to_radians();
        while a < 1.2 {
            let v = model::involute::inv(a);
            let (c, s) = inv_inverse_cos_sin(v as f32);
            let want = model::involute::inv_inverse(f64::from(v as f32));
            assert!((f64::from(c) - want.cos()).abs() < 3e-6, "{a}: cos {c}");
            assert!((f64::from(s) - want.sin()).abs() < 3e-6, "{a}: sin {s}");
            a *= 1.05;
        }
        assert!(inv_inverse_cos_sin(0.0).0.is_nan() && inv_inverse_cos_sin(-1e-3).1.is_nan());
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
                    [0.0; 4],
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

    /// Shifted gear sets `model::GearSet::shifted` accepts, Z1 + Z2 != Z3 + Z4 among them:
    /// x4 puts the G3-G4 mesh at the G1-G2 mesh's working centre distance (the design
    /// search's rule), as f32 values (what the record carries).
    fn shifted_sets() -> Vec<([u16; 4], [f32; 4], f32, f32)> {
        let mut sets = Vec::new();
        for (z, x123) in [
            ([49, 51, 51, 50], [0.2, 0.3, 0.0]),
            ([49, 51, 50, 50], [0.1, 0.1, 0.3]),
            ([50, 50, 52, 49], [0.5, 0.4, 0.0]),
            ([48, 50, 49, 50], [0.0, 0.0, -0.3]),
            ([20, 30, 24, 25], [0.6, 0.5, 0.2]),
            ([100, 101, 102, 99], [-0.4, 0.3, 0.1]),
            ([12, 14, 12, 15], [0.8, 0.9, 0.5]),
        ] {
            for (module_mm, alpha_deg) in [(1.0f32, 20.0f32), (0.5, 14.5), (2.0, 25.0)] {
                let (m, alpha) = (
                    f64::from(module_mm) * 1e-3,
                    f64::from(alpha_deg).to_radians(),
                );
                let zu = z.map(u32::from);
                let [x1, x2, x3] = x123.map(f64::from);
                let mesh = model::involute::Mesh {
                    z: [zu[0], zu[1]],
                    x: [x1, x2],
                    module: m,
                    alpha,
                };
                let sum34 = model::involute::shift_sum_for_centre_distance(
                    zu[2] + zu[3],
                    m,
                    alpha,
                    mesh.working_centre_distance(),
                );
                let x = [x1, x2, x3, sum34 - x3].map(|v| v as f32);
                sets.push((z, x, module_mm, alpha_deg));
            }
        }
        sets
    }

    /// The model's gear set of a record's geometry.
    fn model_gear(z: [u16; 4], x: [f32; 4], module_mm: f32, alpha_deg: f32) -> model::GearSet {
        model::GearSet::shifted(
            z.map(u32::from),
            x.map(f64::from),
            f64::from(module_mm) * 1e-3,
            f64::from(alpha_deg).to_radians(),
        )
        .expect("a valid shifted set")
    }

    #[test]
    fn shifted_gear_factors_match_the_model() {
        let sets = shifted_sets();
        assert!(sets.iter().any(|(z, ..)| z[0] + z[1] != z[2] + z[3]));
        for (z, x, module_mm, alpha_deg) in sets {
            let g = model_gear(z, x, module_mm, alpha_deg);
            let f = GearFactors::new(z, x, module_mm * 1e-3, alpha_deg.to_radians());
            let rel = |a: f32, b: f64| (f64::from(a) - b).abs() / b.abs();
            assert!(
                rel(f.big_lambda, g.big_lambda()) < 1e-4,
                "{z:?} {x:?} {alpha_deg}: {} vs {}",
                f.big_lambda,
                g.big_lambda()
            );
            assert!(
                rel(f.axial_force_per_torque, g.axial_force_per_torque()) < 1e-5,
                "{z:?} {x:?}"
            );
        }
    }

    #[test]
    fn a_shifted_gear_with_unequal_sums_gets_the_models_lambda_on_the_device() {
        // Z1 + Z2 = 100, Z3 + Z4 = 101 (the golden example): stored and derived, its
        // "keeps moving" and "holds" flags are the model's mu Lambda against 1.
        let config = CoreConfig::default();
        let p = RigParameters {
            z: [49, 51, 51, 50],
            profile_shift: [0.2, 0.3, 0.0, -0.017],
            ..RigParameters::paper()
        };
        let g = model_gear(p.z, p.profile_shift, 1.0, 20.0);
        let d = Derived::new(&p, &config).expect("a shifted gear with one centre distance");
        let f = GearFactors::new(p.z, p.profile_shift, 1e-3, 20f32.to_radians());
        assert!((f64::from(f.big_lambda) / g.big_lambda() - 1.0).abs() < 1e-4);
        assert_eq!(d.keeps_moving, f64::from(p.mu_d) * g.big_lambda() < 1.0);
        assert_eq!(d.holds_at_rest, f64::from(p.mu_s) * g.big_lambda() > 1.0);
        // Lambda for n = 1 with shifts is not the standard (49, 51, 50, 50) gear's.
        let standard = model::GearSet::paper([49, 51, 50, 50])
            .unwrap()
            .big_lambda();
        assert!((g.big_lambda() - standard).abs() > 1e-3 * standard);
        // The same tooth counts without the shifts are refused naming the tooth counts.
        let unshifted = RigParameters {
            profile_shift: [0.0; 4],
            ..p
        };
        assert_eq!(
            Derived::new(&unshifted, &config).err(),
            Some(ParameterRejection::new(
                ParameterField::Z,
                RejectReason::Inconsistent
            ))
        );
    }

    #[test]
    fn shifted_checks_agree_with_the_model() {
        let config = CoreConfig::default();
        let mut cases = Vec::new();
        for (z, x, module_mm, alpha_deg) in shifted_sets() {
            let base = RigParameters {
                z,
                profile_shift: x,
                module_mm,
                pressure_angle_deg: alpha_deg,
                ..RigParameters::paper()
            };
            cases.push(base);
            // Centre distances 0.01 module apart, a shift out of range, too negative shifts.
            let mut off = x;
            off[3] += 0.03;
            cases.push(RigParameters {
                profile_shift: off,
                ..base
            });
            for bad in [2.5, -1.5, 2.0, -1.0] {
                let mut x = x;
                x[0] = bad;
                cases.push(RigParameters {
                    profile_shift: x,
                    ..base
                });
            }
            cases.push(RigParameters {
                profile_shift: [-1.0; 4],
                ..base
            });
        }
        let mut accepted = 0;
        for p in cases {
            let model_ok = p.validate().is_ok()
                && model::GearSet::shifted(
                    p.z.map(u32::from),
                    p.profile_shift.map(f64::from),
                    f64::from(p.module_mm) * 1e-3,
                    f64::from(p.pressure_angle_deg).to_radians(),
                )
                .is_ok();
            let core = Derived::new(&p, &config);
            assert_eq!(core.is_ok(), model_ok, "{p:?}: {core:?}");
            if let Err(e) = core {
                assert!(
                    matches!(e.field, ParameterField::ProfileShift | ParameterField::Z),
                    "{p:?}: {e:?}"
                );
            }
            accepted += usize::from(model_ok);
        }
        assert!(accepted >= 21, "{accepted}");
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
