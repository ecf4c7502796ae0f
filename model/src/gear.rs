//! Gear-set geometry: reduction ratio (Eq. 1), contact ratios (Eq. 2), Lambda (Eq. 3),
//! the hold condition (Eq. 4), the expected slip distances p_ij and p (Eqs. 20, 36) and
//! lambda (Eq. 41).

use core::f64::consts::PI;
use core::fmt;

use crate::math::{cos, sqrt, tan};

/// Why a set of gear parameters does not describe a buildable 2K-H gear.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum GearError {
    /// A tooth count is zero.
    ZeroTeeth {
        /// Gear index 1..=4 (G1 fixed, G2-G3 planet, G4 output).
        gear: u8,
    },
    /// Z1 = Z4: the tooth difference n is zero, the reduction ratio is infinite.
    NoToothDifference,
    /// Z1 + Z2 differs from Z3 + Z4: with one module the two meshes cannot share a centre distance.
    UnequalCentreDistance {
        /// Z1 + Z2.
        sum12: u32,
        /// Z3 + Z4.
        sum34: u32,
    },
    /// The module is not a positive finite length.
    BadModule,
    /// The pressure angle is outside (0, 45) degrees.
    BadPressureAngle,
}

impl fmt::Display for GearError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GearError::ZeroTeeth { gear } => {
                write!(f, "Z{gear} is zero: every gear needs at least one tooth")
            }
            GearError::NoToothDifference => write!(
                f,
                "Z1 equals Z4: the tooth difference n = |Z1 - Z4| must be at least 1"
            ),
            GearError::UnequalCentreDistance { sum12, sum34 } => write!(
                f,
                "unequal centre distances: Z1 + Z2 = {sum12} but Z3 + Z4 = {sum34}; with one module they must be equal"
            ),
            GearError::BadModule => write!(f, "the module must be a positive length"),
            GearError::BadPressureAngle => {
                write!(f, "the pressure angle must lie between 0 and 45 degrees")
            }
        }
    }
}

impl core::error::Error for GearError {}

/// A 2K-H planetary gear of external spur gears: G1 fixed, G2-G3 the compound planet on the
/// carrier (the input), G4 the output. Standard gears (addendum = one module), one module for
/// both meshes. Construct with [`GearSet::new`], which validates.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GearSet {
    z: [u32; 4],
    module: f64,
    pressure_angle: f64,
}

impl GearSet {
    /// Module of the paper's gears, m ([`crate::paper::MODULE`]).
    pub const MODULE_PAPER: f64 = crate::paper::MODULE;
    /// Pressure angle of standard gears, rad (20 degrees, [`crate::paper::PRESSURE_ANGLE`]).
    pub const PRESSURE_ANGLE_STANDARD: f64 = crate::paper::PRESSURE_ANGLE;

    /// A gear set with tooth counts `z = [Z1, Z2, Z3, Z4]`, module in m and pressure angle in rad.
    pub const fn new(z: [u32; 4], module: f64, pressure_angle: f64) -> Result<Self, GearError> {
        let mut i = 0;
        while i < 4 {
            if z[i] == 0 {
                #[allow(clippy::cast_possible_truncation, reason = "i < 4")]
                return Err(GearError::ZeroTeeth { gear: i as u8 + 1 });
            }
            i += 1;
        }
        if z[0] == z[3] {
            return Err(GearError::NoToothDifference);
        }
        let (sum12, sum34) = (z[0] + z[1], z[2] + z[3]);
        if sum12 != sum34 {
            return Err(GearError::UnequalCentreDistance { sum12, sum34 });
        }
        if !(module.is_finite() && module > 0.0) {
            return Err(GearError::BadModule);
        }
        if !(pressure_angle > 0.0 && pressure_angle < PI / 4.0) {
            return Err(GearError::BadPressureAngle);
        }
        Ok(Self {
            z,
            module,
            pressure_angle,
        })
    }

    /// The paper's gears: module 1 mm, pressure angle 20 degrees.
    pub const fn paper(z: [u32; 4]) -> Result<Self, GearError> {
        Self::new(z, Self::MODULE_PAPER, Self::PRESSURE_ANGLE_STANDARD)
    }

    /// Tooth counts `[Z1, Z2, Z3, Z4]`.
    pub fn z(&self) -> [u32; 4] {
        self.z
    }

    /// Tooth count of G`i` for `i` in 1..=4.
    fn zf(&self, i: usize) -> f64 {
        self.z[i - 1] as f64
    }

    /// Module, m.
    pub fn module(&self) -> f64 {
        self.module
    }

    /// Pressure angle, rad.
    pub fn pressure_angle(&self) -> f64 {
        self.pressure_angle
    }

    /// Tooth-number difference n = |Z1 - Z4|.
    pub fn n(&self) -> u32 {
        self.z[0].abs_diff(self.z[3])
    }

    /// Pitch radius R_i = m Z_i / 2 of G`i` (i in 1..=4), m.
    pub fn pitch_radius(&self, i: usize) -> f64 {
        self.module * self.zf(i) / 2.0
    }

    /// Reduction ratio rho, Eq. (1): 1/rho = 1 - (Z1/Z2)(Z3/Z4). Positive when carrier and
    /// output turn the same way.
    pub fn rho(&self) -> f64 {
        let z1z3 = self.zf(1) * self.zf(3);
        let z2z4 = self.zf(2) * self.zf(4);
        z2z4 / (z2z4 - z1z3)
    }

    /// Approach/recess contact ratio of G`i`, Eq. (2).
    pub fn contact_ratio(&self, i: usize) -> f64 {
        let z = self.zf(i);
        let (c, t) = (cos(self.pressure_angle), tan(self.pressure_angle));
        z / (2.0 * PI) * (sqrt((z + 2.0) * (z + 2.0) - z * z * c * c) / (z * c) - t)
    }

    /// The four contact ratios epsilon_1..epsilon_4, Eq. (2).
    pub fn contact_ratios(&self) -> [f64; 4] {
        [1, 2, 3, 4].map(|i| self.contact_ratio(i))
    }

    /// h_ij = 1 - eps_i - eps_j + eps_i^2 + eps_j^2, Eq. (13).
    pub fn h(&self, i: usize, j: usize) -> f64 {
        let (ei, ej) = (self.contact_ratio(i), self.contact_ratio(j));
        1.0 - ei - ej + ei * ei + ej * ej
    }

    /// Lambda, Eq. (3): pi (2 - sum eps + sum eps^2) / n.
    pub fn big_lambda(&self) -> f64 {
        let e = self.contact_ratios();
        let sum: f64 = e.iter().sum();
        let sum_sq: f64 = e.iter().map(|x| x * x).sum();
        PI * (2.0 - sum + sum_sq) / self.n() as f64
    }

    /// Hold condition, Eq. (4): without vibration the gear is not backdriven when mu Lambda > 1.
    pub fn holds(&self, mu: f64) -> bool {
        mu * self.big_lambda() > 1.0
    }

    /// Expected slip distance p_ij of the pair (i, j), Eq. (20), m.
    pub fn p_ij(&self, i: usize, j: usize) -> f64 {
        0.5 * self.module * PI * self.h(i, j) * cos(self.pressure_angle)
    }

    /// Mean expected slip distance p = (p12 + p34) / 2, Eq. (36), m.
    pub fn p(&self) -> f64 {
        0.5 * (self.p_ij(1, 2) + self.p_ij(3, 4))
    }

    /// lambda, Eq. (41): the ratio of axial to radial slip speed per unit
    /// (omega_n / omega_t), for a vibration amplitude `eccentricity` in m.
    pub fn small_lambda(&self, eccentricity: f64) -> f64 {
        let (z1, z2, z3, z4) = (self.zf(1), self.zf(2), self.zf(3), self.zf(4));
        4.0 * eccentricity * z1 * z3
            / (PI * self.p() * (self.rho() - 1.0).abs() * (z1 + z2) * (z1 + z4))
    }

    /// Mesh efficiency of the pair (i, j) for friction coefficient `mu`, Eq. (19).
    pub fn mesh_efficiency(&self, i: usize, j: usize, mu: f64) -> f64 {
        1.0 - mu * PI * self.h(i, j) * (1.0 / self.zf(i) + 1.0 / self.zf(j))
    }

    /// Equivalent output inertia I_hat, Eq. (7), kg m^2.
    pub fn equivalent_inertia(&self, inertias: &crate::Inertias) -> f64 {
        let rho2 = self.rho() * self.rho();
        let r12 = self.pitch_radius(1) + self.pitch_radius(2);
        let k = 1.0 + self.zf(1) / self.zf(2);
        inertias.i1 * rho2
            + inertias.m23 * r12 * r12 * rho2
            + inertias.i23 * k * k * rho2
            + inertias.i4
    }

    /// Axial force per unit of output torque at the G4 mesh, 2 (1 + Z3/Z2) / (m Z4 cos a), 1/m.
    /// Times mu_ax tau_rot it is the friction part of the excitation force, Eq. (8).
    pub fn axial_force_per_torque(&self) -> f64 {
        2.0 * (1.0 + self.zf(3) / self.zf(2))
            / (self.module * self.zf(4) * cos(self.pressure_angle))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper::{self, TABLE1};

    /// Table 1 of the paper: z, rho, mu_s Lambda (mu_s = 0.271), non-backdriven point.
    const TABLE1_EXPECTED: [([u32; 4], f64, f64, bool); 6] = [
        ([49, 51, 50, 50], 25.5, 1.336, true),
        ([50, 50, 51, 49], -24.5, 1.336, true),
        ([50, 50, 48, 52], 13.0, 0.668, false),
        ([52, 48, 50, 50], -12.0, 0.668, false),
        ([49, 51, 48, 52], 8.84, 0.445, false),
        ([52, 48, 51, 49], -7.84, 0.445, false),
    ];

    #[test]
    fn table1_rows_reproduce_the_paper() {
        for (z, rho, mu_lambda, holds) in TABLE1_EXPECTED {
            let g = GearSet::paper(z).unwrap();
            assert!((g.rho() - rho).abs() < 0.01, "{z:?}: rho {}", g.rho());
            let ml = paper::MU_S * g.big_lambda();
            assert!((ml - mu_lambda).abs() < 0.001, "{z:?}: mu_s Lambda {ml}");
            assert_eq!(g.holds(paper::MU_S), holds, "{z:?}");
        }
        assert_eq!(TABLE1.map(|z| z), TABLE1_EXPECTED.map(|r| r.0));
    }

    #[test]
    fn contact_ratio_of_a_50_tooth_gear_matches_first_principles() {
        // Path of approach of a standard 20-degree gear pair with one addendum: for Z = 50,
        // (sqrt(52^2 - (50 cos a)^2) - 50 sin a) / (2 pi cos a) = 0.8773
        // (hand calculation: sqrt(2704 - 2207.555) = 22.281, 22.281 / 46.985 - 0.36397 = 0.11025, x 50 / 2 pi).
        let g = paper::FIG5_GEARS;
        assert!(
            (g.contact_ratio(1) - 0.8773).abs() < 1e-4,
            "{}",
            g.contact_ratio(1)
        );
        let sum: f64 = paper::RIG_GEARS.contact_ratios().iter().sum();
        assert!(
            sum > 3.4 && sum < 3.7,
            "total contact ratio of two meshes ~1.7 each: {sum}"
        );
    }

    #[test]
    fn lambda_scales_with_one_over_n() {
        let n1 = paper::FIG5_GEARS.big_lambda();
        let n2 = GearSet::paper(TABLE1[3]).unwrap().big_lambda();
        assert!((n1 / n2 - 2.0).abs() < 0.01);
    }

    #[test]
    fn invalid_sets_are_rejected_with_the_reason() {
        assert_eq!(
            GearSet::paper([0, 51, 50, 50]),
            Err(GearError::ZeroTeeth { gear: 1 })
        );
        assert_eq!(
            GearSet::paper([50, 50, 50, 50]),
            Err(GearError::NoToothDifference)
        );
        assert_eq!(
            GearSet::paper([49, 51, 50, 51]),
            Err(GearError::UnequalCentreDistance {
                sum12: 100,
                sum34: 101
            })
        );
        assert_eq!(
            GearSet::new(paper::RIG_Z, -1.0, 0.3),
            Err(GearError::BadModule)
        );
        assert_eq!(
            GearSet::new(paper::RIG_Z, 1e-3, 1.0),
            Err(GearError::BadPressureAngle)
        );
    }

    #[test]
    fn slip_distance_and_small_lambda_are_consistent_with_eq41() {
        let g = paper::RIG_GEARS;
        let e = paper::ECCENTRICITY;
        // Eq. (41) middle form: lambda = v_ax |w_t| / (v_rad |w_n|) with Eqs. (37), (38).
        let v_ax_per_wn = 2.0 * e / PI;
        let [z1, z2, z3, z4] = g.z().map(f64::from);
        let v_rad_per_wt =
            g.p() * (z4 / z3 + z2 * z4 / (2.0 * z1 * z3) + 0.5) * (g.rho() - 1.0).abs();
        let lambda = v_ax_per_wn / v_rad_per_wt;
        assert!((g.small_lambda(e) / lambda - 1.0).abs() < 1e-12);
        // p = pi m h cos(a) / 2 with h ~ 0.79: about 1.16 module.
        assert!((g.p() / g.module() - 1.16).abs() < 0.02, "{}", g.p());
    }

    #[test]
    fn mesh_efficiency_is_high_for_a_single_pair() {
        // The paper notes eta_ij >= 0.9 for one pair.
        let g = paper::FIG5_GEARS;
        let eta = g.mesh_efficiency(1, 2, paper::MU_S);
        assert!(eta > 0.9 && eta < 1.0, "{eta}");
    }

    #[test]
    fn equivalent_inertia_of_eq7() {
        let g = paper::RIG_GEARS;
        let only_output = crate::Inertias {
            i1: 0.0,
            m23: 0.0,
            i23: 0.0,
            i4: 0.5,
        };
        assert_eq!(g.equivalent_inertia(&only_output), 0.5);
        let only_carrier = crate::Inertias {
            i1: 1e-3,
            m23: 0.0,
            i23: 0.0,
            i4: 0.0,
        };
        assert!((g.equivalent_inertia(&only_carrier) - 1e-3 * 25.5 * 25.5).abs() < 1e-9);
        let planet_mass = crate::Inertias {
            i1: 0.0,
            m23: 1.0,
            i23: 0.0,
            i4: 0.0,
        };
        assert!((g.equivalent_inertia(&planet_mass) - 0.05 * 0.05 * 25.5 * 25.5).abs() < 1e-9);
    }
}
