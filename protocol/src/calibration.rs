//! The calibration record stored on the device and exchanged with the host.
//!
//! Units are the paper's (N mm, mm, A, rad/s) so values read straight against its
//! Table 2; the model converts to SI.

use serde::{Deserialize, Serialize};

use crate::Error;
use crate::sizes::{F32, U16};

/// Vibrator constants (Eqs. 15-17), gear geometry, friction and safety limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// C1, torque per current of the vibrator motor, N mm/A (`|tau_cam| = C1 i_in + C2`).
    pub c1_nmm_per_a: f32,
    /// C2, torque offset of the torque-current line, N mm.
    pub c2_nmm: f32,
    /// C3, speed slope of the vibrator's own loss torque, N mm s/rad.
    pub c3_nmm_s_per_rad: f32,
    /// C4, offset of the vibrator's own loss torque, N mm.
    pub c4_nmm: f32,
    /// C5, speed slope of the no-load current, A s/rad.
    pub c5_a_s_per_rad: f32,
    /// C6, offset of the no-load current, A.
    pub c6_a: f32,
    /// Tooth counts (Z1, Z2, Z3, Z4): G1 fixed, G2-G3 the compound planet, G4 the output.
    pub z: [u16; 4],
    /// Gear module, mm.
    pub module_mm: f32,
    /// Pressure angle, degrees.
    pub pressure_angle_deg: f32,
    /// Cam eccentricity e (vibration amplitude), mm.
    pub eccentricity_mm: f32,
    /// Vibrating mass M_hat = M1 + M23, kg.
    pub carrier_mass_kg: f32,
    /// Static tooth friction coefficient.
    pub mu_s: f32,
    /// Dynamic tooth friction coefficient.
    pub mu_d: f32,
    /// Largest output load the firmware will release, N m.
    pub max_release_load_nm: f32,
    /// Motor current limit, A.
    pub max_current_a: f32,
    /// Highest vibration frequency the firmware will drive, Hz.
    pub max_freq_hz: f32,
}

impl Calibration {
    /// Largest serialised size, bytes: 15 `f32` and four `u16` varints.
    pub const MAX_WIRE_SIZE: usize = 15 * F32 + 4 * U16;

    /// The paper's rig: Table 2 constants, gear set (49, 51, 50, 50), m 1 mm, 20 deg,
    /// e 1 mm, M_hat 3.82 kg, mu_s 0.271, mu_d 0.174.
    ///
    /// Limits: 3.68 N m (tooth strength), 4.5 A (inside the ACS714's +-5 A range so an
    /// overcurrent is still measurable), 15 Hz (the paper's fastest test, 8.8 V).
    pub const fn paper() -> Self {
        Self {
            c1_nmm_per_a: 62.1,
            c2_nmm: -138.0,
            c3_nmm_s_per_rad: 0.235,
            c4_nmm: 1.69,
            c5_a_s_per_rad: 0.00378,
            c6_a: 2.25,
            z: [49, 51, 50, 50],
            module_mm: 1.0,
            pressure_angle_deg: 20.0,
            eccentricity_mm: 1.0,
            carrier_mass_kg: 3.82,
            mu_s: 0.271,
            mu_d: 0.174,
            max_release_load_nm: 3.68,
            max_current_a: 4.5,
            max_freq_hz: 15.0,
        }
    }

    /// C1..C6 in the paper's units (see the field docs), widened to `f64` for the model.
    pub fn constants(&self) -> [f64; 6] {
        [
            self.c1_nmm_per_a,
            self.c2_nmm,
            self.c3_nmm_s_per_rad,
            self.c4_nmm,
            self.c5_a_s_per_rad,
            self.c6_a,
        ]
        .map(f64::from)
    }

    /// Range checks shared by host (before sending) and firmware (before storing).
    ///
    /// They reject values that are non-finite or physically meaningless, not values that
    /// are merely unusual: the model decides whether a gear set locks.
    pub fn validate(&self) -> Result<(), Error> {
        let check = |ok: bool, field: &'static str| {
            if ok {
                Ok(())
            } else {
                Err(Error::InvalidCalibration { field })
            }
        };
        let finite = |v: f32| v.is_finite();
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let non_negative = |v: f32| v.is_finite() && v >= 0.0;

        check(positive(self.c1_nmm_per_a), "c1_nmm_per_a")?;
        check(finite(self.c2_nmm), "c2_nmm")?;
        check(non_negative(self.c3_nmm_s_per_rad), "c3_nmm_s_per_rad")?;
        check(finite(self.c4_nmm), "c4_nmm")?;
        check(non_negative(self.c5_a_s_per_rad), "c5_a_s_per_rad")?;
        check(non_negative(self.c6_a), "c6_a")?;
        let [z1, z2, z3, z4] = self.z.map(u32::from);
        check(self.z.iter().all(|&z| z >= 4), "z")?;
        // Z1 Z3 = Z2 Z4 gives 1/rho = 0 (Eq. 1): the output would not turn at all.
        check(z1 * z3 != z2 * z4, "z")?;
        check(positive(self.module_mm), "module_mm")?;
        let alpha = self.pressure_angle_deg;
        check(
            alpha.is_finite() && alpha > 0.0 && alpha < 45.0,
            "pressure_angle_deg",
        )?;
        check(positive(self.eccentricity_mm), "eccentricity_mm")?;
        check(positive(self.carrier_mass_kg), "carrier_mass_kg")?;
        check(positive(self.mu_s) && self.mu_s < 1.0, "mu_s")?;
        check(positive(self.mu_d) && self.mu_d <= self.mu_s, "mu_d")?;
        check(positive(self.max_release_load_nm), "max_release_load_nm")?;
        check(positive(self.max_current_a), "max_current_a")?;
        check(positive(self.max_freq_hz), "max_freq_hz")?;
        Ok(())
    }
}

impl Default for Calibration {
    fn default() -> Self {
        Self::paper()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_values_are_valid() {
        assert_eq!(Calibration::paper().validate(), Ok(()));
        assert_eq!(Calibration::default(), Calibration::paper());
    }

    #[test]
    fn rejects_bad_fields_by_name() {
        let field = |c: Calibration| match c.validate() {
            Err(Error::InvalidCalibration { field }) => field,
            other => panic!("expected rejection, got {other:?}"),
        };
        let p = Calibration::paper();
        assert_eq!(
            field(Calibration {
                c1_nmm_per_a: f32::NAN,
                ..p
            }),
            "c1_nmm_per_a"
        );
        assert_eq!(
            field(Calibration {
                z: [50, 50, 50, 50],
                ..p
            }),
            "z"
        );
        assert_eq!(
            field(Calibration {
                z: [0, 51, 50, 50],
                ..p
            }),
            "z"
        );
        assert_eq!(field(Calibration { mu_d: 0.3, ..p }), "mu_d");
        assert_eq!(
            field(Calibration {
                pressure_angle_deg: 90.0,
                ..p
            }),
            "pressure_angle_deg"
        );
        assert_eq!(
            field(Calibration {
                max_freq_hz: 0.0,
                ..p
            }),
            "max_freq_hz"
        );
    }
}
