//! The paper's numbers, written once: Noda et al., "Switching backdrivability of a planetary
//! gear by vibration" (equation and table numbers are the paper's).
//!
//! This module is the one home of every number the paper prints about its gears, its rig
//! and its tests. The firmware's configuration defaults, the plant, the host tools, the
//! simulator and the tests read them from here; a test that checks a computed value against
//! the paper's printed result keeps that result as a literal (that is the point of the
//! test) and takes its inputs from here. The rig's hardware (motor, sensors, ADC, encoder,
//! bridge) lives in [`crate::hardware`].
//!
//! Units are SI (m, kg, N m, rad/s, V, Hz) unless a name says otherwise; Table 2 is kept in
//! the paper's printed units next to its SI form [`CALIBRATION`].

use core::f64::consts::PI;

use crate::load::Load;
use crate::{Calibration, GearSet};

/// The paper's Table 1 gear sets `[Z1, Z2, Z3, Z4]`, in the table's order (n = 1, 1, 2, 2,
/// 3, 3; every set has Z1 + Z2 = Z3 + Z4 = 100).
pub const TABLE1: [[u32; 4]; 6] = [
    [49, 51, 50, 50],
    [50, 50, 51, 49],
    [50, 50, 48, 52],
    [52, 48, 50, 50],
    [49, 51, 48, 52],
    [52, 48, 51, 49],
];

/// Tooth counts of the rig the required-torque tests and the calibration use, (Z1, Z4) =
/// (49, 50): Table 1's first row. The tools default to this gear set.
pub const RIG_Z: [u32; 4] = TABLE1[0];

/// Tooth counts of Fig. 5's gear set, (Z1, Z4) = (50, 49): Table 1's second row, also the
/// gear of the weight test that gives mu_s and mu_d (Eqs. 11-14).
pub const FIG5_Z: [u32; 4] = TABLE1[1];

/// Module of the paper's gears, m.
pub const MODULE: f64 = 1.0e-3;
/// Pressure angle of the paper's standard gears, rad (20 degrees).
pub const PRESSURE_ANGLE: f64 = 20.0 * PI / 180.0;

/// A Table 1 gear set with the paper's module and pressure angle, checked at compile time.
const fn table1_gear(z: [u32; 4]) -> GearSet {
    match GearSet::paper(z) {
        Ok(g) => g,
        Err(_) => panic!("a Table 1 gear set is not a valid 2K-H gear"),
    }
}

/// The rig's gear set [`RIG_Z`] = (49, 51, 50, 50), module 1 mm, 20 degrees.
pub const RIG_GEARS: GearSet = table1_gear(RIG_Z);
/// Fig. 5's gear set [`FIG5_Z`] = (50, 50, 51, 49), module 1 mm, 20 degrees.
pub const FIG5_GEARS: GearSet = table1_gear(FIG5_Z);

/// Gross efficiency at the onset of forward drive of the (50, 49) gear, static (Eq. 14):
/// gives [`MU_S`] through Eqs. (12)-(13).
pub const ETA_GROSS_STATIC: f64 = 0.423;
/// Gross efficiency of the (50, 49) gear while driven (Eq. 14): gives [`MU_D`].
pub const ETA_GROSS_DYNAMIC: f64 = 0.533;
/// Static friction coefficient of the paper's gears (from [`ETA_GROSS_STATIC`]).
pub const MU_S: f64 = 0.271;
/// Dynamic friction coefficient of the paper's gears (from [`ETA_GROSS_DYNAMIC`]).
pub const MU_D: f64 = 0.174;

/// Input pulley radius r_in of the weight test (Eq. 14), m.
pub const R_IN: f64 = 0.100;
/// Output pulley radius r_out of the weight test (Eq. 14) and of Fig. 5, m.
pub const R_OUT: f64 = 0.075;

/// Cam eccentricity e (the carrier's axial vibration amplitude), m.
pub const ECCENTRICITY: f64 = 1.0e-3;
/// Smallest eccentricity the paper finds necessary for the switching, m.
pub const MIN_ECCENTRICITY: f64 = 0.3e-3;
/// Carrier mass M_hat = M1 + M23, kg.
pub const CARRIER_MASS: f64 = 3.82;
/// Equivalent output inertia I_hat of the (49, 50) rig from CAD, kg m^2 (Eq. 7).
pub const I_HAT: f64 = 2.79;
/// Carrier radius L, m.
pub const CARRIER_RADIUS: f64 = 0.100;

/// Table 2 as printed: C1 N mm/A, C2 N mm, C3 N mm s/rad, C4 N mm, C5 A s/rad, C6 A.
pub const TABLE2: [f64; 6] = [62.1, -138.0, 0.235, 1.69, 0.00378, 2.25];
/// Table 2 in SI units (the same numbers as [`Calibration::PAPER`]).
pub const CALIBRATION: Calibration = Calibration::from_paper_units(TABLE2);

/// Largest load torque on the output the gear's teeth take (tooth strength), N m: the top of
/// the required-torque tests and the cap of a release load on the paper's gear.
pub const TAU_ROT_MAX: f64 = 3.68;
/// Smallest load torque of the required-torque tests, N m (a tenth of [`TAU_ROT_MAX`]); at
/// 3.6 and 6.2 V the output did not backdrive under it (linear-bush friction).
pub const TAU_ROT_MIN_TESTED: f64 = 0.368;
/// Repeats of each required-torque test.
pub const REQUIRED_TORQUE_REPEATS: u32 = 5;

/// Vibrator supply voltages of the required-torque tests, V; they give about
/// [`VIBRATION_HZ`].
pub const SUPPLY_VOLTAGES: [f64; 3] = [3.6, 6.2, 8.8];
/// The vibration frequencies [`SUPPLY_VOLTAGES`] give, about, Hz.
pub const VIBRATION_HZ: [f64; 3] = [5.0, 10.0, 15.0];
/// Below this supply voltage the vibrator does not turn, V.
pub const START_VOLTAGE: f64 = 1.0;
/// Supply voltages of the no-load current test (Eq. 17), V.
pub const NO_LOAD_VOLTAGE_RANGE: (f64, f64) = (1.0, 1.9);

/// The input current is averaged over this window at the start of constant cam rotation, s.
pub const CURRENT_AVERAGING_S: f64 = 0.5;
/// Sample rate of the paper's current logger (Elmos RAI-16), Hz.
pub const LOGGING_RATE_HZ: f64 = 10_000.0;

/// Fig. 5's load mass m_out, kg (hung on [`R_OUT`]).
pub const FIG5_MASS: f64 = 1.0;
/// Fig. 5's load: [`FIG5_MASS`] on the pulley of radius [`R_OUT`].
pub const FIG5_LOAD: Load = Load::Mass {
    mass: FIG5_MASS,
    radius: R_OUT,
};
/// How long Fig. 5's load stayed still without vibration, s.
pub const FIG5_HOLD_S: f64 = 14.5;
/// Supply voltage of Fig. 5's release, V (about 5 Hz).
pub const FIG5_VOLTS: f64 = 3.6;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_gear_sets_are_table1_rows() {
        assert_eq!(RIG_GEARS.z(), [49, 51, 50, 50]);
        assert_eq!(FIG5_GEARS.z(), [50, 50, 51, 49]);
        assert_eq!(RIG_GEARS, GearSet::paper(RIG_Z).unwrap());
        assert_eq!(RIG_GEARS.module(), 1e-3);
        // 20 degrees.
        assert!((PRESSURE_ANGLE - 0.349_065_850_398_865_9).abs() < 1e-15);
    }

    #[test]
    fn table2_in_si() {
        assert_eq!(CALIBRATION, Calibration::PAPER);
        assert!((CALIBRATION.c1 - 0.0621).abs() < 1e-15);
        assert!((CALIBRATION.c2 + 0.138).abs() < 1e-15);
        assert_eq!(CALIBRATION.c6, 2.25);
    }

    #[test]
    fn fig5_load_is_1_kg_on_75_mm() {
        // 1.0 kg x g x 0.075 m = 0.7355 N m.
        assert!((FIG5_LOAD.torque() - 0.735_5).abs() < 1e-4);
        assert!((VIBRATION_HZ[0] - 5.0).abs() < 1e-12 && SUPPLY_VOLTAGES[0] == FIG5_VOLTS);
    }
}
