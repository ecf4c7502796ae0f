//! The vibrator: a Mabuchi RS-735 DC motor with an 8.5:1 gearhead driving the cam.
//!
//! Parameters are chosen so the paper's calibration (Table 2) is what a calibration of
//! this motor returns, and the paper's voltage-speed points hold:
//! - torque constant at the cam shaft C1 = eta N Kt, Coulomb loss -C2 (also the static
//!   friction that sets the start-up voltage), viscous loss C3 and running loss C4;
//! - back-EMF at the cam shaft N Ke = 0.078 V s/rad and R = 0.44 ohm, so 3.6 / 6.2 / 8.8 V
//!   give about 5 / 10 / 15 Hz under the paper's loads, and the motor breaks away at
//!   R (-C2) / C1 = 0.98 V: it does not turn below 1.0 V.

use crate::Calibration;
use crate::hardware::rs735;

/// Electrical, mechanical and thermal parameters of the vibrator (SI, cam-shaft side unless
/// noted).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotorParams {
    /// Winding resistance at the reference temperature, ohm.
    pub resistance: f64,
    /// Winding inductance, H.
    pub inductance: f64,
    /// Back-EMF constant at the motor shaft (= torque constant Kt), V s/rad.
    pub ke_motor: f64,
    /// Gearhead reduction N (motor turns per cam turn).
    pub gear_ratio: f64,
    /// Torque per ampere delivered at the cam shaft, C1 = eta N Kt, N m/A.
    pub torque_per_amp: f64,
    /// Coulomb (and static) friction torque at the cam shaft, N m (= -C2).
    pub coulomb: f64,
    /// Extra constant loss while turning, N m (= C4).
    pub running_loss: f64,
    /// Viscous loss at the cam shaft, N m s/rad (= C3).
    pub viscous: f64,
    /// Rotor, gearhead and cam inertia seen at the cam shaft, kg m^2.
    pub inertia: f64,
    /// Heat capacity of the winding, J/K.
    pub thermal_capacity: f64,
    /// Thermal resistance winding to ambient, K/W.
    pub thermal_resistance: f64,
    /// Ambient (and reference) temperature, deg C.
    pub ambient_c: f64,
}

impl MotorParams {
    /// The paper's vibrator ([`crate::hardware::rs735`]), built around the calibration
    /// `cal` (Table 2 by default).
    pub fn rs735(cal: &Calibration) -> Self {
        let gear_ratio = rs735::GEAR_RATIO;
        Self {
            resistance: rs735::RESISTANCE_OHM,
            inductance: rs735::INDUCTANCE_H,
            ke_motor: rs735::KE_CAM_V_S_PER_RAD / gear_ratio,
            gear_ratio,
            torque_per_amp: cal.c1,
            coulomb: -cal.c2,
            running_loss: cal.c4,
            viscous: cal.c3,
            // The rotor's inertia times N^2, plus the cam and its shaft.
            inertia: rs735::ROTOR_INERTIA_KG_M2 * gear_ratio * gear_ratio
                + rs735::CAM_INERTIA_KG_M2,
            thermal_capacity: rs735::THERMAL_CAPACITY_J_PER_K,
            thermal_resistance: rs735::THERMAL_RESISTANCE_K_PER_W,
            ambient_c: rs735::AMBIENT_C,
        }
    }

    /// Back-EMF constant at the cam shaft, V s/rad.
    pub fn ke_cam(&self) -> f64 {
        self.ke_motor * self.gear_ratio
    }

    /// Mechanical time constant of the vibrator driven from a voltage source, s: the cam
    /// shaft's inertia over the damping the back-EMF and the viscous loss give it,
    /// J / (C1 ke / R + C3) (about 74 ms for the RS-735 with its cam). After a change of
    /// drive the cam speed approaches its new value as exp(-t / tau), and until it has, the
    /// current carries the accelerating torque J dw/dt on top of the steady-state one.
    pub fn mechanical_time_constant_s(&self) -> f64 {
        self.inertia / (self.torque_per_amp * self.ke_cam() / self.resistance + self.viscous)
    }

    /// Lowest voltage that starts the motor from rest (no cam load), V.
    pub fn breakaway_voltage(&self) -> f64 {
        self.resistance * self.coulomb / self.torque_per_amp
    }

    /// The calibration this motor has by construction (Eqs. 15-17).
    pub fn calibration(&self) -> Calibration {
        Calibration::from_torque_and_no_load(
            self.torque_per_amp,
            -self.coulomb,
            self.viscous / self.torque_per_amp,
            (self.coulomb + self.running_loss) / self.torque_per_amp,
        )
    }
}

impl Default for MotorParams {
    fn default() -> Self {
        Self::rs735(&Calibration::PAPER)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motor_reproduces_table2_and_the_start_voltage() {
        let m = MotorParams::default();
        let c = m.calibration().to_paper_units();
        let paper = crate::paper::TABLE2;
        for (k, (got, want)) in c.iter().zip(paper).enumerate() {
            let tol = if k == 3 { 0.5 } else { 0.05 };
            assert!(
                ((got - want) / want).abs() < tol,
                "C{}: {got} vs {want}",
                k + 1
            );
        }
        let tau = m.mechanical_time_constant_s();
        assert!((tau - 0.074).abs() < 0.002, "{tau}");
        let v = m.breakaway_voltage();
        assert!(v < 1.0 && v > 0.9, "{v}");
        assert!((v - rs735::BREAKAWAY_V).abs() < 1e-12);
    }
}
