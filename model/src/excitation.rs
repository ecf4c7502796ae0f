//! Excitation force and cam torque, Eqs. (8)-(10), and the load estimate that inverts Eq. (10).

use core::f64::consts::PI;

use crate::GearSet;
use crate::math::{cos, sin};

/// The cam drive: a gear set shaken axially by an eccentric cam of eccentricity `e` (m)
/// moving the carrier mass `carrier_mass` = M_hat = M1 + M23 (kg).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CamDrive {
    /// The gear set.
    pub gear: GearSet,
    /// Cam eccentricity e, m (amplitude of the carrier's axial motion).
    pub eccentricity: f64,
    /// Carrier mass M_hat, kg.
    pub carrier_mass: f64,
}

impl CamDrive {
    /// The paper's rig around `gear`: e = 1 mm, M_hat = 3.82 kg.
    pub fn paper(gear: GearSet) -> Self {
        Self {
            gear,
            eccentricity: crate::paper::ECCENTRICITY,
            carrier_mass: crate::paper::CARRIER_MASS,
        }
    }

    /// Friction part of the excitation force, N: 2 mu_ax tau_rot (1 + Z3/Z2) / (m Z4 cos a).
    pub fn friction_force(&self, mu_ax: f64, tau_rot: f64) -> f64 {
        Self::friction_force_with(mu_ax, tau_rot, self.gear.axial_force_per_torque())
    }

    /// [`CamDrive::friction_force`] with the gear's axial force per torque
    /// ([`GearSet::axial_force_per_torque`]) given: callers over many points take it once.
    #[inline]
    pub fn friction_force_with(mu_ax: f64, tau_rot: f64, axial_per_torque: f64) -> f64 {
        mu_ax * tau_rot.abs() * axial_per_torque
    }

    /// Excitation force |F_ex| at time `t` (s) for cam speed `omega_n` (rad/s), Eq. (8), N.
    pub fn excitation_force(&self, mu_ax: f64, tau_rot: f64, omega_n: f64, t: f64) -> f64 {
        self.friction_force(mu_ax, tau_rot)
            + self.carrier_mass * omega_n * omega_n * self.eccentricity * cos(omega_n * t)
    }

    /// Instantaneous cam torque at cam angle `theta` (rad), Eq. (9), N m.
    ///
    /// The friction term is dissipative: it always resists the cam (|sin theta|), so it
    /// never returns power. The inertia term M_hat w^2 e^2 sin cos exchanges power with the
    /// carrier and averages to zero over a turn.
    pub fn cam_torque(&self, mu_ax: f64, tau_rot: f64, omega_n: f64, theta: f64) -> f64 {
        let e = self.eccentricity;
        let s = sin(theta);
        self.friction_force(mu_ax, tau_rot) * e * s.abs()
            + self.carrier_mass * omega_n * omega_n * e * e * s * cos(theta)
    }

    /// Inertia part of Eq. (10): M_hat w_n^2 e^2 / pi, N m.
    pub fn required_inertia_torque(&self, omega_n: f64) -> f64 {
        self.carrier_mass * omega_n * omega_n * self.eccentricity * self.eccentricity / PI
    }

    /// Required cam torque, Eq. (10): the mean |tau_cam| over the acceleration phase, N m.
    /// tau_cam_hat = 4 mu tau_rot (1 + Z3/Z2) e / (pi m Z4 cos a) + M_hat w_n^2 e^2 / pi.
    pub fn required_cam_torque(&self, mu: f64, tau_rot: f64, omega_n: f64) -> f64 {
        2.0 / PI * self.friction_force(mu, tau_rot) * self.eccentricity
            + self.required_inertia_torque(omega_n)
    }

    /// Load torque on the output that explains a cam torque `tau_cam` at cam speed `omega_n`,
    /// by inverting Eq. (10), N m. Negative when `tau_cam` is below the no-load requirement.
    pub fn load_from_cam_torque(&self, mu: f64, tau_cam: f64, omega_n: f64) -> f64 {
        let per_nm = 2.0 / PI * self.friction_force(mu, 1.0) * self.eccentricity;
        (tau_cam - self.required_inertia_torque(omega_n)) / per_nm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive() -> CamDrive {
        CamDrive::paper(crate::paper::RIG_GEARS)
    }

    #[test]
    fn eq10_by_hand_at_full_load() {
        // 4 * 0.271 * 3.68 * (1 + 50/51) * 1e-3 / (pi * 1e-3 * 50 * cos 20deg) = 53.5 N mm,
        // plus 3.82 * (2 pi 5)^2 * 1e-6 / pi = 1.20 N mm at 5 Hz.
        let w = 2.0 * PI * 5.0;
        let tau = drive().required_cam_torque(crate::paper::MU_S, crate::paper::TAU_ROT_MAX, w);
        assert!(
            (tau * 1e3 - (53.52 + 1.200)).abs() < 0.05,
            "{} N mm",
            tau * 1e3
        );
    }

    #[test]
    fn eq10_is_the_mean_of_eq9_over_the_acceleration_phase() {
        let d = drive();
        let (mu, tau_rot, w) = (0.2, 2.0, 2.0 * PI * 10.0);
        let steps = 20_000;
        let mean: f64 = (0..steps)
            .map(|k| {
                let theta = (k as f64 + 0.5) / steps as f64 * PI / 2.0;
                d.cam_torque(mu, tau_rot, w, theta)
            })
            .sum::<f64>()
            / steps as f64;
        let eq10 = d.required_cam_torque(mu, tau_rot, w);
        assert!((mean / eq10 - 1.0).abs() < 1e-6, "{mean} vs {eq10}");
    }

    #[test]
    fn inertia_term_averages_out_over_a_turn() {
        let d = drive();
        let w = 2.0 * PI * 15.0;
        let steps = 36_000;
        let mean: f64 = (0..steps)
            .map(|k| d.cam_torque(0.0, 0.0, w, (k as f64 + 0.5) / steps as f64 * 2.0 * PI))
            .sum::<f64>()
            / steps as f64;
        assert!(mean.abs() < 1e-9);
    }

    #[test]
    fn load_estimate_inverts_eq10() {
        let d = drive();
        for tau_rot in [0.368, 1.0, 3.68] {
            for hz in [5.0, 10.0, 15.0] {
                let w = 2.0 * PI * hz;
                let mu = crate::paper::MU_S;
                let tau_cam = d.required_cam_torque(mu, tau_rot, w);
                let back = d.load_from_cam_torque(mu, tau_cam, w);
                assert!((back - tau_rot).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn excitation_force_peak_is_friction_plus_inertia() {
        let d = drive();
        let w = 2.0 * PI * 10.0;
        let (mu, tau) = (crate::paper::MU_S, crate::paper::TAU_ROT_MAX);
        let f0 = d.excitation_force(mu, tau, w, 0.0);
        let expected =
            d.friction_force(mu, tau) + crate::paper::CARRIER_MASS * w * w * d.eccentricity;
        assert!((f0 - expected).abs() < 1e-9);
    }
}
