//! The effect laws, each written once. The current model ([`super::CurrentModel`] and its
//! folded [`super::CurrentEvaluator`]), the plant ([`crate::plant`]) and the firmware's
//! estimator call these; where the plant runs a deliberately different shape, that shape is
//! a named variant here, with the reason.

use core::f64::consts::PI;

use crate::CamDrive;

/// Load torque at which the load-dependent friction coefficient equals mu, N m (the
/// reference of the current model's `load-dependent-friction`).
pub const LOAD_FRICTION_REFERENCE_NM: f64 = 1.0;

/// Local friction exponent of seed 003's average friction coefficient (Eq. 12 there):
/// mu ~ (load)^0.2. Used for the mesh load-sharing ripple.
pub const ISO_LOAD_EXPONENT: f64 = 0.2;

/// The smallest torque-constant factor 1 - k x the thermal drift gives: the floor keeps
/// the current finite however far a fit or a plant run drives k x.
pub const MIN_TORQUE_CONSTANT_FACTOR: f64 = 0.1;

// ---------------------------------------------------------------------------------------
// speed-dependent-axial-friction

/// The shape of the speed-dependent axial friction, mu_ax / mu as a function of cam speed.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum AxialSpeedLaw {
    /// Eq. (40) of the paper with a fixed corner: w_n / sqrt(w_n^2 + w_c^2), w_c = |w_t| /
    /// lambda. The candidate form `rig explain` fits.
    Eq40 {
        /// Corner speed w_c, rad/s.
        corner: f64,
    },
    /// 1 - depth exp(-w_n / w_0): the plant's form. Deliberately not the candidate's shape:
    /// the plant runs it so that a test shows `rig explain` recognising the effect in data
    /// whose law is not in its library (a robustness test).
    ExponentialDip {
        /// Relative dip at standstill, 0..1.
        depth: f64,
        /// Speed over which the dip fades, rad/s.
        omega0: f64,
    },
}

impl AxialSpeedLaw {
    /// mu_ax / mu at cam speed `omega_n` (rad/s).
    #[inline]
    pub fn factor(&self, omega_n: f64) -> f64 {
        match *self {
            AxialSpeedLaw::Eq40 { corner } => axial_friction_speed_factor(omega_n, corner),
            AxialSpeedLaw::ExponentialDip { depth, omega0 } => {
                1.0 - depth * libm::exp(-omega_n.abs() / omega0)
            }
        }
    }
}

/// Speed factor of the axial friction coefficient, Eq. (40) of the paper:
/// mu_ax / mu = w_n / sqrt(w_n^2 + w_c^2) with w_c = |w_t| / lambda (the output speed over
/// lambda of Eq. 41). 1 when `omega_c` is zero.
#[inline]
pub fn axial_friction_speed_factor(omega_n: f64, omega_c: f64) -> f64 {
    axial_friction_speed_factor_sq(omega_n, omega_n * omega_n, omega_c * omega_c)
}

/// [`axial_friction_speed_factor`] from w_n, w_n^2 and w_c^2 (the form the current model's
/// fit uses: smooth at w_c = 0). 1 when `corner_sq` is zero.
#[inline]
pub fn axial_friction_speed_factor_sq(omega_n: f64, omega_sq: f64, corner_sq: f64) -> f64 {
    if corner_sq == 0.0 {
        return 1.0;
    }
    let d = libm::sqrt(omega_sq + corner_sq);
    if d == 0.0 { 1.0 } else { omega_n.abs() / d }
}

/// Corner speed w_c = |w_t| / lambda of Eq. (40) for an output speed `omega_t` (rad/s) and
/// the gear's lambda (Eq. 41).
#[inline]
pub fn axial_corner_speed(omega_t: f64, small_lambda: f64) -> f64 {
    omega_t.abs() / small_lambda
}

// ---------------------------------------------------------------------------------------
// load-dependent-friction

/// Load factor of the friction coefficient, mu(tau) / mu = (|tau| / tau_ref)^b with
/// tau_ref = [`LOAD_FRICTION_REFERENCE_NM`]; seed 003's average friction coefficient (Eq. 12
/// there) grows with the tooth load to the power 0.2.
#[inline]
pub fn load_friction_factor(tau_rot: f64, exponent: f64) -> f64 {
    load_friction_factor_at(tau_rot, exponent, LOAD_FRICTION_REFERENCE_NM)
}

/// Load factor of the friction coefficient with reference load `tau_ref` (N m):
/// (|tau| / tau_ref)^b; 1 at zero load or exponent.
#[inline]
pub fn load_friction_factor_at(tau_rot: f64, exponent: f64, tau_ref: f64) -> f64 {
    let load = tau_rot.abs();
    if load == 0.0 || exponent == 0.0 {
        1.0
    } else {
        libm::pow(load / tau_ref, exponent)
    }
}

/// [`load_friction_factor`] from ln(|tau| / tau_ref), cached per operating point:
/// exp(b ln(|tau| / tau_ref)).
#[inline]
pub fn load_friction_factor_ln(exponent: f64, ln_load: f64) -> f64 {
    if exponent == 0.0 {
        1.0
    } else {
        libm::exp(exponent * ln_load)
    }
}

// ---------------------------------------------------------------------------------------
// current-sensor-offset

/// The current a sensor with zero offset `offset` (A) reads for a true current `current`
/// (A): the ACS714's zero is not exactly at Vcc / 2.
#[inline]
pub fn offset_current(current: f64, offset: f64) -> f64 {
    current + offset
}

// ---------------------------------------------------------------------------------------
// thermal-drift

/// Torque-constant factor 1 - k x of the thermal drift (x = T - T0 in K, or the time in s
/// when only that is known), floored at [`MIN_TORQUE_CONSTANT_FACTOR`].
#[inline]
pub fn torque_constant_factor(coeff: f64, thermal: f64) -> f64 {
    (1.0 - coeff * thermal).max(MIN_TORQUE_CONSTANT_FACTOR)
}

/// [`torque_constant_factor`] with its derivative with respect to k (zero on the floor).
#[inline]
pub fn torque_constant_factor_and_slope(coeff: f64, thermal: f64) -> (f64, f64) {
    let raw = 1.0 - coeff * thermal;
    if raw < MIN_TORQUE_CONSTANT_FACTOR {
        (MIN_TORQUE_CONSTANT_FACTOR, 0.0)
    } else {
        (raw, -thermal)
    }
}

/// Torque constant after thermal drift, C1 (1 - k x), floored at a tenth of C1.
#[inline]
pub fn drifted_torque_constant(c1: f64, coeff: f64, thermal: f64) -> f64 {
    c1 * torque_constant_factor(coeff, thermal)
}

// ---------------------------------------------------------------------------------------
// vibrator-viscous-loss

/// Extra vibrator loss torque c_v |w_n| next to C3's, N m (`c_v` in N m s/rad).
#[inline]
pub fn viscous_loss_torque(c_v: f64, omega_n: f64) -> f64 {
    c_v * omega_n.abs()
}

// ---------------------------------------------------------------------------------------
// inertia-rectification

/// kappa of a drive that takes all the carrier's inertial power back (regenerating): the
/// inertia term averages out over a turn.
pub const KAPPA_POWER_RETURNED: f64 = -1.0;
/// kappa of a drive that cannot take power back but lets the carrier coast: only the
/// positive half of Eq. (9)'s inertia term is paid, M_hat w_n^2 e^2 / (2 pi).
pub const KAPPA_POWER_NOT_RETURNED: f64 = -0.5;
/// kappa of Eq. (10) itself: the mean over the acceleration phase.
pub const KAPPA_EQ10: f64 = 0.0;
/// kappa of a drive that also brakes the carrier: the fully rectified 2 M_hat w_n^2 e^2 / pi.
pub const KAPPA_FULLY_RECTIFIED: f64 = 1.0;

/// kappa of a braking (slow-decay) drive whose return of the carrier's inertial power
/// passes back through the gearhead: -(1 + eta_f eta_b) / 2, -0.82 at the RS-735's 80 %
/// forward and reverse efficiency. From first principles: the cam torque is read from the
/// motor current through the forward efficiency (C1 = eta_f N Kt), so while the motor
/// drives the carrier the reading is the inertia torque T itself; while the carrier pushes
/// the cam the motor receives eta_b T and the reading is eta_f eta_b T, returned. The
/// half-turns of either sign each average M_hat w_n^2 e^2 / (2 pi), so the turn mean is
/// (1 - eta_f eta_b) / 2 of Eq. (10)'s term: (1 + kappa) = (1 - eta_f eta_b) / 2.
/// Between [`KAPPA_POWER_RETURNED`] (lossless gearhead) and [`KAPPA_POWER_NOT_RETURNED`]
/// (nothing back).
pub const KAPPA_BRAKING_DRIVE: f64 = braking_kappa(
    crate::hardware::rs735::GEARHEAD_EFFICIENCY,
    crate::hardware::rs735::GEARHEAD_REVERSE_EFFICIENCY,
);

/// [`KAPPA_BRAKING_DRIVE`] for a gearhead of forward efficiency `eta_f` and reverse
/// efficiency `eta_b` (each in (0, 1]).
#[inline]
pub const fn braking_kappa(eta_f: f64, eta_b: f64) -> f64 {
    -0.5 * (1.0 + eta_f * eta_b)
}

/// The kappa of a drive that does (`true`: a braking drive, [`KAPPA_BRAKING_DRIVE`], its
/// return through the gearhead) or does not (`false`: [`KAPPA_POWER_NOT_RETURNED`]) take
/// the carrier's power back. The plant (`regeneration`), the firmware's estimator
/// (`carrier_power_returned`) and `rig explain`'s base model are such drives
/// (`model::hardware::board::DECAY`).
#[inline]
pub const fn drive_kappa(power_returned: bool) -> f64 {
    if power_returned {
        KAPPA_BRAKING_DRIVE
    } else {
        KAPPA_POWER_NOT_RETURNED
    }
}

/// Whether a fitted `kappa` is nearer a drive that takes power back (through the
/// gearhead, [`KAPPA_BRAKING_DRIVE`]) than one that does not (below -0.66, halfway
/// between the two).
#[inline]
pub fn kappa_returns_power(kappa: f64) -> bool {
    kappa < 0.5 * (KAPPA_BRAKING_DRIVE + KAPPA_POWER_NOT_RETURNED)
}

/// Mean inertia torque (1 + kappa) T_10, floored at zero, for Eq. (10)'s inertia term
/// `eq10_inertia` = M_hat w_n^2 e^2 / pi (N m). See [`rectified_inertia_torque`].
#[inline]
pub fn rectified_inertia(eq10_inertia: f64, kappa: f64) -> f64 {
    ((1.0 + kappa) * eq10_inertia).max(0.0)
}

/// Mean inertia torque of the cam, (1 + kappa) M_hat w_n^2 e^2 / pi, N m, floored at zero.
/// `kappa` = 0 is Eq. (10)'s term (the mean over the acceleration phase); -1 a drive that
/// takes all the carrier's inertial power back (the term averages out over a turn); -1/2 one
/// that takes nothing back but lets the carrier coast (the positive half of Eq. 9's inertia
/// term, M_hat w_n^2 e^2 / (2 pi)); 1 the fully rectified mean 2 M_hat w_n^2 e^2 / pi (the
/// motor also brakes the carrier in the deceleration phase). The turn mean of
/// [`carrier_inertia_torque_taken`] is this with [`drive_kappa`].
#[inline]
pub fn rectified_inertia_torque(drive: &CamDrive, omega_n: f64, kappa: f64) -> f64 {
    rectified_inertia(drive.required_inertia_torque(omega_n), kappa)
}

/// Eq. (9)'s instantaneous inertia term M_hat e^2 w_n^2 sin(theta) cos(theta), N m, from
/// the carrier mass (kg), eccentricity (m), sin and cos of the cam angle and the cam speed.
#[inline]
pub fn carrier_inertia_torque(
    mass: f64,
    eccentricity: f64,
    sin: f64,
    cos: f64,
    omega_n: f64,
) -> f64 {
    mass * eccentricity * eccentricity * sin * cos * omega_n * omega_n
}

/// The part of the instantaneous inertia torque `full` the motor feels at cam speed
/// `omega_n`: all of it when the drive takes power back; otherwise nothing while the
/// carrier pushes the cam (its power is lost, not returned), so the turn mean is
/// [`rectified_inertia_torque`] with [`KAPPA_POWER_NOT_RETURNED`].
#[inline]
pub fn carrier_inertia_torque_taken(full: f64, omega_n: f64, power_returned: bool) -> f64 {
    carrier_inertia_torque_at_kappa(full, omega_n, drive_kappa(power_returned))
}

/// The part of the instantaneous inertia torque `full` a drive of rectification `kappa`
/// takes at cam speed `omega_n`: all of it while the motor drives the carrier, and
/// -(1 + 2 kappa) times it while the carrier pushes the cam, so that the turn mean is
/// exactly [`rectified_inertia_torque`] with that `kappa` (the half-turns of either sign
/// each average M_hat w_n^2 e^2 / (2 pi)). kappa = -1 returns all the power, -1/2 loses
/// it, 0 (Eq. 10) and above brake the carrier too; below -1 the weight is held at 1 (the
/// law's floor at zero).
#[inline]
pub fn carrier_inertia_torque_at_kappa(full: f64, omega_n: f64, kappa: f64) -> f64 {
    if full * omega_n < 0.0 {
        let weight = -(1.0 + 2.0 * kappa);
        if weight == 0.0 {
            0.0
        } else {
            full * weight.min(1.0)
        }
    } else {
        full
    }
}

/// The rectification of a drive whose kappa depends on the load, kappa + kappa_per_nm
/// |tau_rot| (`rig explain`'s `load-dependent` form of `inertia-rectification`).
#[inline]
pub fn load_dependent_kappa(kappa: f64, kappa_per_nm: f64, tau_rot: f64) -> f64 {
    kappa + kappa_per_nm * tau_rot.abs()
}

// ---------------------------------------------------------------------------------------
// linear-bush-friction

/// Mean cam torque of a Coulomb force `force` (N) against the carrier's axial motion of
/// amplitude `eccentricity` (m): the mean of F e |sin| over a turn, (2/pi) F e, N m.
#[inline]
pub fn bush_cam_torque(force: f64, eccentricity: f64) -> f64 {
    2.0 / PI * force.abs() * eccentricity
}

/// Output torque the linear bush holds while the cam turns at `omega_n` (rad/s): as in
/// Eq. (39), the axial slip takes the bush's friction away from the rotation, so its grip
/// fades with cam speed, T_hold(w_n) = T_0 / (1 + |w_n| / w_b), N m. At rest (w_n = 0) the
/// bush holds T_0 whatever w_b; `omega_b` <= 0 means any vibration frees it at once.
#[inline]
pub fn bush_holding_torque(hold_torque: f64, omega_n: f64, omega_b: f64) -> f64 {
    let hold = hold_torque.abs();
    if omega_n == 0.0 {
        hold
    } else if omega_b <= 0.0 {
        0.0
    } else {
        hold / (1.0 + omega_n.abs() / omega_b)
    }
}

// ---------------------------------------------------------------------------------------
// tooth-compliance (and Eq. 10's friction term)

/// Eq. (10)'s friction term with axial tooth compliance `compliance` (m/N, seed 004): the
/// contacts first deflect F c, then slide over e - F c, so the mean friction torque is
/// (2/pi) F (e - c F), N m, and zero once c F reaches e. `compliance` = 0 gives Eq. (10)'s
/// (2/pi) F e. `force` is the axial friction force F_ax (N).
#[inline]
pub fn compliant_friction_torque(force: f64, eccentricity: f64, compliance: f64) -> f64 {
    if compliance * force.abs() < eccentricity {
        2.0 / PI * force * (eccentricity - compliance * force.abs())
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper;

    #[test]
    fn speed_factor_is_eq40() {
        // Eq. (40): mu_ax = mu lambda |w_n| / sqrt(w_t^2 + lambda^2 w_n^2).
        let (lambda, wt, wn) = (0.8, 12.0, 31.4);
        let eq40 = lambda * wn / libm::sqrt(wt * wt + lambda * lambda * wn * wn);
        let f = axial_friction_speed_factor(wn, axial_corner_speed(wt, lambda));
        assert!((f - eq40).abs() < 1e-12);
        assert_eq!(axial_friction_speed_factor(10.0, 0.0), 1.0);
        assert!((load_friction_factor(2.0, 0.2) - libm::pow(2.0, 0.2)).abs() < 1e-12);
        assert_eq!(load_friction_factor(0.0, 0.2), 1.0);
        let law = AxialSpeedLaw::Eq40 { corner: 20.0 };
        assert_eq!(law.factor(31.4), axial_friction_speed_factor(31.4, 20.0));
    }

    #[test]
    fn exponential_variant_falls_at_low_speed_only() {
        let law = AxialSpeedLaw::ExponentialDip {
            depth: 0.5,
            omega0: 20.0,
        };
        assert!(law.factor(31.4) < law.factor(94.2));
        assert!((law.factor(1e6) - 1.0).abs() < 1e-9);
        assert!((law.factor(0.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn load_factor_forms_agree() {
        for tau in [0.368, 1.0, 3.68] {
            let ln = libm::log(tau / LOAD_FRICTION_REFERENCE_NM);
            let a = load_friction_factor(tau, 0.2);
            assert!((a - load_friction_factor_ln(0.2, ln)).abs() < 1e-12);
            assert!(
                (load_friction_factor_at(tau, 0.2, 2.0) - libm::pow(tau / 2.0, 0.2)).abs() < 1e-12
            );
        }
    }

    #[test]
    fn thermal_factor_has_one_floor() {
        assert_eq!(torque_constant_factor(2e-3, 10.0), 1.0 - 2e-2);
        assert_eq!(
            torque_constant_factor(0.1, 100.0),
            MIN_TORQUE_CONSTANT_FACTOR
        );
        assert_eq!(torque_constant_factor_and_slope(0.1, 100.0), (0.1, 0.0));
        assert_eq!(torque_constant_factor_and_slope(1e-3, 10.0), (0.99, -10.0));
        assert_eq!(drifted_torque_constant(0.06, 0.1, 100.0), 0.06 * 0.1);
    }

    #[test]
    fn bush_hold_at_rest_and_under_vibration() {
        assert!((bush_holding_torque(0.8, 40.0, 40.0) - 0.4).abs() < 1e-12);
        assert_eq!(bush_holding_torque(0.6, 10.0, 0.0), 0.0);
        // At rest the bush holds its full torque, with or without a corner speed.
        assert_eq!(bush_holding_torque(0.6, 0.0, 0.0), 0.6);
        assert_eq!(bush_holding_torque(0.6, 0.0, 30.0), 0.6);
        assert!((bush_cam_torque(5.0, 1e-3) - 2.0 / PI * 5e-3).abs() < 1e-15);
    }

    #[test]
    fn the_instantaneous_inertia_law_averages_to_the_kappa_law() {
        // Over a turn, the inertia torque a drive takes averages to (1 + kappa) M w^2 e^2 / pi
        // with kappa = -1 (power returned) or -1/2 (not returned).
        let drive = CamDrive::paper(paper::RIG_GEARS);
        let w = 2.0 * PI * 10.0;
        let n = 36_000;
        for returned in [true, false] {
            let mean = (0..n)
                .map(|k| {
                    let theta = (k as f64 + 0.5) / n as f64 * 2.0 * PI;
                    let (s, c) = (libm::sin(theta), libm::cos(theta));
                    let full =
                        carrier_inertia_torque(drive.carrier_mass, drive.eccentricity, s, c, w);
                    carrier_inertia_torque_taken(full, w, returned)
                })
                .sum::<f64>()
                / n as f64;
            let law = rectified_inertia_torque(&drive, w, drive_kappa(returned));
            assert!((mean - law).abs() < 1e-9, "{returned}: {mean} vs {law}");
        }
        // Any fitted kappa: the instantaneous law's turn mean is the kappa law's.
        for kappa in [-1.5, -1.0, -0.75, -0.5, -0.3, 0.0, 0.4, 1.0] {
            let mean = (0..n)
                .map(|k| {
                    let theta = (k as f64 + 0.5) / n as f64 * 2.0 * PI;
                    let (s, c) = (libm::sin(theta), libm::cos(theta));
                    let full =
                        carrier_inertia_torque(drive.carrier_mass, drive.eccentricity, s, c, w);
                    carrier_inertia_torque_at_kappa(full, w, kappa)
                })
                .sum::<f64>()
                / n as f64;
            let law = rectified_inertia_torque(&drive, w, kappa);
            assert!((mean - law).abs() < 1e-9, "kappa {kappa}: {mean} vs {law}");
        }
        assert!((load_dependent_kappa(-0.5, 0.1, -2.0) + 0.3).abs() < 1e-12);
        assert!(kappa_returns_power(-0.9) && !kappa_returns_power(-0.6));
        assert!(kappa_returns_power(KAPPA_BRAKING_DRIVE));
        assert!(!kappa_returns_power(KAPPA_POWER_NOT_RETURNED));
        // Eq. (10) and the fully rectified form.
        let eq10 = drive.required_inertia_torque(w);
        assert_eq!(rectified_inertia_torque(&drive, w, KAPPA_EQ10), eq10);
        assert_eq!(
            rectified_inertia_torque(&drive, w, KAPPA_FULLY_RECTIFIED),
            2.0 * eq10
        );
        assert_eq!(rectified_inertia_torque(&drive, w, -3.0), 0.0);
    }

    #[test]
    fn a_braking_drive_returns_the_inertia_term_through_the_gearhead() {
        // 80 % forward and back: -(1 + 0.64) / 2 = -0.82, between all returned (-1) and
        // nothing returned (-1/2); lossless it is -1, with no way back it is -1/2.
        assert!(
            (KAPPA_BRAKING_DRIVE + 0.82).abs() < 1e-12,
            "{KAPPA_BRAKING_DRIVE}"
        );
        const { assert!(KAPPA_POWER_RETURNED < KAPPA_BRAKING_DRIVE) };
        const { assert!(KAPPA_BRAKING_DRIVE < KAPPA_POWER_NOT_RETURNED) };
        assert_eq!(braking_kappa(1.0, 1.0), KAPPA_POWER_RETURNED);
        assert_eq!(braking_kappa(0.8, 0.0), KAPPA_POWER_NOT_RETURNED);
        assert_eq!(drive_kappa(true), KAPPA_BRAKING_DRIVE);
        // The instantaneous law returns eta_f eta_b of the inertia torque while the carrier
        // pushes the cam: the reading of the eta_b the motor receives through eta_f.
        let pushed = carrier_inertia_torque_at_kappa(-1.0, 10.0, KAPPA_BRAKING_DRIVE);
        assert!((pushed + 0.64).abs() < 1e-12, "{pushed}");
    }

    #[test]
    fn compliance_shortens_the_stroke() {
        let f = 100.0;
        assert_eq!(compliant_friction_torque(f, 1e-3, 0.0), 2.0 / PI * f * 1e-3);
        assert!(compliant_friction_torque(f, 1e-3, 1e-6) < compliant_friction_torque(f, 1e-3, 0.0));
        assert_eq!(compliant_friction_torque(f, 1e-3, 1e-5), 0.0);
        assert_eq!(offset_current(2.0, 0.03), 2.03);
        assert_eq!(viscous_loss_torque(1e-4, -50.0), 5e-3);
    }
}
