//! Output-shaft dynamics, Eq. (6), with the equivalent inertia of Eq. (7) and the static
//! hold of Eq. (4) when the carrier is not vibrating.

use crate::GearSet;
use crate::math::sqrt;

/// Inertial parameters of the gear for Eq. (7).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Inertias {
    /// I1: input shaft and carrier, kg m^2.
    pub i1: f64,
    /// M23: mass of the compound planet G2-G3, kg.
    pub m23: f64,
    /// I23: compound planet about its own axis, kg m^2.
    pub i23: f64,
    /// I4: output shaft with G4 (and the load pulley), kg m^2.
    pub i4: f64,
}

/// Below this output speed (rad/s) the output counts as standing still for the static check.
pub const STANDSTILL_RAD_S: f64 = 1e-9;

/// The output shaft of Eq. (6): I_hat dw_t/dt + tau_rot mu Lambda |w_t| / sqrt(w_t^2 +
/// lambda^2 w_n^2) = tau_rot, extended with Coulomb sticking: at standstill without vibration
/// the teeth hold up to mu_s Lambda |tau_rot|.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct OutputShaft {
    /// Equivalent inertia I_hat, kg m^2 (Eq. 7).
    pub i_hat: f64,
    /// Lambda of the gear set (Eq. 3).
    pub big_lambda: f64,
    /// lambda of the gear set and cam (Eq. 41).
    pub small_lambda: f64,
    /// Static friction coefficient.
    pub mu_s: f64,
    /// Dynamic friction coefficient.
    pub mu_d: f64,
}

impl OutputShaft {
    /// The shaft of `gear` shaken with amplitude `eccentricity` (m).
    pub fn new(gear: &GearSet, eccentricity: f64, i_hat: f64, mu_s: f64, mu_d: f64) -> Self {
        Self {
            i_hat,
            big_lambda: gear.big_lambda(),
            small_lambda: gear.small_lambda(eccentricity),
            mu_s,
            mu_d,
        }
    }

    /// Whether the gear holds a load at rest without vibration: mu_s Lambda > 1 (Eq. 4).
    pub fn holds_at_rest(&self) -> bool {
        self.mu_s * self.big_lambda > 1.0
    }

    /// Whether a moving output keeps accelerating after vibration stops: mu_d Lambda < 1.
    pub fn keeps_moving_after_stop(&self) -> bool {
        self.mu_d * self.big_lambda < 1.0
    }

    /// Effective radial friction factor mu |w_t| / sqrt(w_t^2 + lambda^2 w_n^2) (Eq. 39) at
    /// output speed `omega_t` and vibration speed `omega_n`; zero when both are zero.
    pub fn radial_friction(&self, mu: f64, omega_t: f64, omega_n: f64) -> f64 {
        let denom =
            sqrt(omega_t * omega_t + self.small_lambda * self.small_lambda * omega_n * omega_n);
        if denom == 0.0 {
            0.0
        } else {
            mu * omega_t.abs() / denom
        }
    }

    /// Friction torque on the output (N m), signed against the motion, for load `tau_rot`.
    /// At standstill with no vibration it is the sticking torque, at most mu_s Lambda |tau_rot|.
    pub fn friction_torque(&self, tau_rot: f64, omega_t: f64, omega_n: f64) -> f64 {
        if omega_t.abs() <= STANDSTILL_RAD_S && omega_n == 0.0 {
            let limit = self.mu_s * self.big_lambda * tau_rot.abs();
            return -tau_rot.clamp(-limit, limit);
        }
        if omega_t.abs() <= STANDSTILL_RAD_S {
            // Vibrating from rest: Eq. (39) gives no radial friction, the load starts to move.
            return 0.0;
        }
        let magnitude =
            tau_rot.abs() * self.big_lambda * self.radial_friction(self.mu_d, omega_t, omega_n);
        -magnitude * omega_t.signum()
    }

    /// Output acceleration dw_t/dt from Eq. (6), rad/s^2.
    ///
    /// A shaft that stops while the friction would reverse it sticks: when the friction
    /// exceeds the load and the shaft is at rest the acceleration is zero.
    pub fn acceleration(&self, tau_rot: f64, omega_t: f64, omega_n: f64) -> f64 {
        let net = tau_rot + self.friction_torque(tau_rot, omega_t, omega_n);
        net / self.i_hat
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shaft(z: [u32; 4]) -> OutputShaft {
        let g = GearSet::paper(z).unwrap();
        OutputShaft::new(
            &g,
            crate::paper::ECCENTRICITY,
            crate::paper::I_HAT,
            crate::paper::MU_S,
            crate::paper::MU_D,
        )
    }

    #[test]
    fn n1_holds_its_load_without_vibration() {
        let s = shaft(crate::paper::FIG5_Z);
        assert!(s.holds_at_rest());
        assert_eq!(s.acceleration(0.736, 0.0, 0.0), 0.0);
        assert_eq!(s.acceleration(-3.68, 0.0, 0.0), 0.0);
    }

    #[test]
    fn n2_backdrives_without_vibration() {
        let s = shaft(crate::paper::TABLE1[3]);
        assert!(!s.holds_at_rest());
        let tau = crate::paper::TAU_ROT_MAX;
        let a = s.acceleration(tau, 0.0, 0.0);
        let expected = tau * (1.0 - crate::paper::MU_S * s.big_lambda) / crate::paper::I_HAT;
        assert!((a - expected).abs() < 1e-12);
    }

    #[test]
    fn vibration_releases_a_held_load() {
        let s = shaft(crate::paper::FIG5_Z);
        let a = s.acceleration(0.736, 0.0, 2.0 * core::f64::consts::PI * 5.0);
        assert!((a - 0.736 / crate::paper::I_HAT).abs() < 1e-12);
        // While moving slowly under vibration the radial friction is a small fraction of mu.
        let f = s.radial_friction(0.174, 0.01, 31.4);
        assert!(f < 0.174 * 0.1, "{f}");
    }

    #[test]
    fn motion_after_vibration_stops_follows_mu_d_lambda() {
        // n = 1: mu_d Lambda = 0.858 < 1, the paper saw the load keep falling.
        let s = shaft(crate::paper::FIG5_Z);
        assert!(s.keeps_moving_after_stop());
        let a = s.acceleration(0.736, 0.5, 0.0);
        let expected = 0.736 * (1.0 - crate::paper::MU_D * s.big_lambda) / crate::paper::I_HAT;
        assert!((a - expected).abs() < 1e-12 && a > 0.0);
    }
}
