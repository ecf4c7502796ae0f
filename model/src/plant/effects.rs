//! Physical effects the paper's model leaves out, which the plant can switch on so the
//! discrepancy workflow (`rig explain`) can be tested on simulated data. Each is off by
//! default; each enters at its physical place through the law of [`crate::effects`] (the
//! table [`crate::effects::EFFECTS`] says how the plant takes each one).

use crate::effects::{
    AxialSpeedLaw, bush_cam_torque, bush_holding_torque, load_friction_factor_at,
    torque_constant_factor,
};

/// Switchable effects (all off in [`Default`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PlantEffects {
    /// `speed-dependent-axial-friction`: mu_ax(w) = mu (1 - depth exp(-w / omega0)), the
    /// [`AxialSpeedLaw::ExponentialDip`] variant; the paper's explanation for the low torque
    /// at 3.6 V. Deliberately not the Eq. (40) shape `rig explain` fits: the tests show it
    /// finding the effect from a law it does not contain. `(depth, omega0 rad/s)`.
    pub axial_friction_speed: Option<(f64, f64)>,
    /// `speed-dependent-axial-friction` as a rig file's `[model]` fits it: Eq. (40) with a
    /// fixed corner speed, mu_ax(w) = mu w / sqrt(w^2 + w_c^2), [`AxialSpeedLaw::Eq40`]: the
    /// law `rig explain` fits, run as fitted. `w_c` in rad/s.
    pub axial_friction_corner: Option<f64>,
    /// `load-dependent-friction`: mu(tau) = mu (tau_rot / tau_ref)^exponent, the tooth-load
    /// dependence of an average friction coefficient. `(exponent, tau_ref N m)`.
    pub load_friction: Option<(f64, f64)>,
    /// `thermal-drift`: the magnets weaken as the winding warms, C1(T) = C1 (1 - k (T - T0)),
    /// floored as the library's law. `k` in 1/K.
    pub thermal_drift: Option<f64>,
    /// `current-sensor-offset`: the logger's current reads this much too high, A.
    pub current_offset: f64,
    /// `vibrator-viscous-loss`: an extra speed-proportional loss at the cam shaft, N m s/rad.
    pub extra_viscous: f64,
    /// `linear-bush-friction`: Coulomb force of the carrier's linear bush, N. It resists the
    /// axial motion (cam torque F_b e |sin|) and holds the output at rest while
    /// tau_rot < F_b * `bush_hold_arm` / (1 + w_n / `bush_omega`).
    pub bush_friction: f64,
    /// Lever arm turning the bush force into a holding torque on the output, m.
    pub bush_hold_arm: f64,
    /// Cam speed at which the bush's grip has halved, rad/s.
    pub bush_omega: f64,
    /// `inertia-rectification` as fitted: the drive takes Eq. (9)'s inertia torque with
    /// kappa + kappa_per_nm |tau_rot| ([`crate::effects::carrier_inertia_torque_at_kappa`]),
    /// `(kappa, kappa_per_nm 1/(N m))`; `None`: the drive's own (`PlantParams::regeneration`).
    pub inertia_kappa: Option<(f64, f64)>,
    /// `tooth-compliance` (seed 004, Xu & Zheng): the teeth deflect axially by c F before
    /// they slide, so the axial friction force F of the teeth works over the stroke e - c F
    /// ([`compliant_stroke`]; its turn mean is [`crate::effects::compliant_friction_torque`]).
    /// `c` in m/N.
    #[cfg_attr(feature = "serde", serde(default))]
    pub tooth_compliance: f64,
    /// `mesh-load-sharing-ripple` (seed 003, Tian et al., Eq. 11): the teeth's friction
    /// force follows the load sharing over the output mesh's angle, relative rms
    /// `ripple_rms` about its mean ([`MeshRipple::friction_factor`]), so a test's window at
    /// a mesh phase of its own sees a friction term that scatters from test to test.
    #[cfg_attr(feature = "serde", serde(default))]
    pub mesh_ripple_rms: f64,
}

/// The stroke over which an axial friction force `force` (N) slides when the teeth first
/// deflect by `compliance` x `force` (seed 004): e - c F, not below zero, m.
#[inline]
pub fn compliant_stroke(eccentricity: f64, compliance: f64, force: f64) -> f64 {
    (eccentricity - compliance * force.abs()).max(0.0)
}

/// The output mesh's friction ripple over its angle (seed 003): the mesh's tooth count, its
/// contact ratio and the mean and relative rms of [`crate::effects::mesh_friction`]
/// there, computed once per plant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshRipple {
    /// Teeth of the output gear that pass per radian of the output.
    teeth_per_rad: f64,
    /// Contact ratio of the output mesh.
    contact_ratio: f64,
    /// Mean of the mesh friction over a cycle.
    mean: f64,
    /// Relative rms of the mesh friction about its mean.
    rms: f64,
}

impl MeshRipple {
    /// The ripple of `gear`'s output mesh (Z3-Z4), with seed 003's local friction exponent.
    pub fn of(gear: &crate::GearSet) -> Self {
        let contact_ratio = gear.contact_ratio(4);
        let (mean, rms) =
            crate::effects::mesh_friction_stats(contact_ratio, crate::effects::ISO_LOAD_EXPONENT);
        Self {
            teeth_per_rad: f64::from(gear.z()[3]) / (2.0 * core::f64::consts::PI),
            contact_ratio,
            mean,
            rms,
        }
    }

    /// The factor on the teeth's friction force at output angle `output_rad` (from a mesh
    /// phase `phase0`, in mesh cycles, at angle zero) for a ripple of relative rms
    /// `ripple_rms`: 1 + ripple_rms m(phase), m the mesh friction's deviation from its mean
    /// in units of its rms (unit rms over a cycle); 1 without a ripple.
    pub fn friction_factor(&self, ripple_rms: f64, output_rad: f64, phase0: f64) -> f64 {
        if ripple_rms <= 0.0 || self.rms <= 0.0 || self.mean <= 0.0 {
            return 1.0;
        }
        let phase = phase0 + self.teeth_per_rad * output_rad;
        let m = (crate::effects::mesh_friction(
            phase,
            self.contact_ratio,
            crate::effects::ISO_LOAD_EXPONENT,
        ) / self.mean
            - 1.0)
            / self.rms;
        (1.0 + ripple_rms * m).max(0.0)
    }
}

impl PlantEffects {
    /// The speed law of the axial friction, when switched on.
    pub fn axial_speed_law(&self) -> Option<AxialSpeedLaw> {
        self.axial_friction_speed
            .map(|(depth, omega0)| AxialSpeedLaw::ExponentialDip { depth, omega0 })
    }

    /// Axial friction coefficient at cam speed `omega_n` and load `tau_rot`, from `mu`.
    pub fn axial_mu(&self, mu: f64, omega_n: f64, tau_rot: f64) -> f64 {
        let mut m = mu;
        if let Some(law) = self.axial_speed_law() {
            m *= law.factor(omega_n);
        }
        if let Some(corner) = self.axial_friction_corner {
            m *= AxialSpeedLaw::Eq40 { corner }.factor(omega_n);
        }
        if let Some((exponent, tau_ref)) = self.load_friction
            && tau_rot.abs() > 0.0
        {
            m *= load_friction_factor_at(tau_rot, exponent, tau_ref);
        }
        m
    }

    /// Factor on the torque constant at winding temperature `temp_c` (reference `ambient_c`).
    pub fn torque_constant_factor(&self, temp_c: f64, ambient_c: f64) -> f64 {
        match self.thermal_drift {
            Some(k) => torque_constant_factor(k, temp_c - ambient_c),
            None => 1.0,
        }
    }

    /// Holding torque of the linear bush at cam speed `omega_n`, N m.
    pub fn bush_hold_torque(&self, omega_n: f64) -> f64 {
        if self.bush_friction <= 0.0 {
            return 0.0;
        }
        bush_holding_torque(
            self.bush_friction * self.bush_hold_arm,
            omega_n,
            self.bush_omega,
        )
    }

    /// Mean cam torque the bush adds over a turn, N m: (2 / pi) F_b e.
    pub fn bush_mean_cam_torque(&self, eccentricity: f64) -> f64 {
        bush_cam_torque(self.bush_friction, eccentricity)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper;

    #[test]
    fn effects_are_off_by_default() {
        let e = PlantEffects::default();
        assert_eq!(e.axial_mu(paper::MU_S, 10.0, 1.0), paper::MU_S);
        assert_eq!(e.torque_constant_factor(60.0, 25.0), 1.0);
        assert_eq!(e.bush_hold_torque(0.0), 0.0);
    }

    #[test]
    fn speed_dependent_friction_falls_at_low_speed_only() {
        let e = PlantEffects {
            axial_friction_speed: Some((0.5, 20.0)),
            ..Default::default()
        };
        let mu = paper::MU_S;
        assert!(e.axial_mu(mu, 31.4, 1.0) < e.axial_mu(mu, 94.2, 1.0));
        assert!((e.axial_mu(mu, 1e6, 1.0) - mu).abs() < 1e-9);
    }

    #[test]
    fn bush_grip_fades_with_cam_speed() {
        let e = PlantEffects {
            bush_friction: 20.0,
            bush_hold_arm: 0.05,
            bush_omega: 30.0,
            ..Default::default()
        };
        assert!((e.bush_hold_torque(0.0) - 1.0).abs() < 1e-12);
        assert!((e.bush_hold_torque(30.0) - 0.5).abs() < 1e-12);
        // Without a corner speed the bush holds at rest only.
        let at_once = PlantEffects {
            bush_omega: 0.0,
            ..e
        };
        assert!((at_once.bush_hold_torque(0.0) - 1.0).abs() < 1e-12);
        assert_eq!(at_once.bush_hold_torque(1.0), 0.0);
    }

    #[test]
    fn tooth_compliance_shortens_the_stroke_as_the_librarys_law() {
        let (e, c) = (1.0e-3, 20e-6);
        for f in [0.0, 10.0, 30.0, 60.0] {
            // The turn mean of F (e - c F) |sin| is the library's compliant friction torque.
            let mean = 2.0 / core::f64::consts::PI * f * compliant_stroke(e, c, f);
            let law = crate::effects::compliant_friction_torque(f, e, c);
            assert!((mean - law).abs() < 1e-15, "{f}: {mean} vs {law}");
        }
        assert_eq!(compliant_stroke(e, c, 100.0), 0.0);
        assert_eq!(compliant_stroke(e, 0.0, 100.0), e);
    }

    #[test]
    fn the_mesh_ripple_has_the_asked_rms_about_a_mean_of_one() {
        let gear = crate::GearSet::paper([49, 51, 50, 50]).unwrap();
        let mesh = MeshRipple::of(&gear);
        assert_eq!(mesh.friction_factor(0.0, 1.0, 0.3), 1.0);
        // Over one mesh cycle of the output (one tooth pitch of the output gear).
        let n = 2000;
        let pitch = 1.0 / mesh.teeth_per_rad;
        let f: Vec<f64> = (0..n)
            .map(|k| mesh.friction_factor(0.1, pitch * (k as f64 + 0.5) / n as f64, 0.0))
            .collect();
        let mean = f.iter().sum::<f64>() / n as f64;
        let rms = (f.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64).sqrt();
        assert!((mean - 1.0).abs() < 1e-3, "{mean}");
        assert!((rms - 0.1).abs() < 2e-3, "{rms}");
    }

    #[test]
    fn thermal_drift_has_the_librarys_floor() {
        let e = PlantEffects {
            thermal_drift: Some(0.05),
            ..Default::default()
        };
        assert!((e.torque_constant_factor(35.0, 25.0) - 0.5).abs() < 1e-12);
        // 1 - 0.05 x 100 = -4 would reverse the motor's torque; the law floors it at 0.1.
        assert_eq!(e.torque_constant_factor(125.0, 25.0), 0.1);
    }
}
