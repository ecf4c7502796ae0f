//! Gear-set geometry: reduction ratio (Eq. 1), contact ratios (Eq. 2), Lambda (Eq. 3),
//! the hold condition (Eq. 4), the expected slip distances p_ij and p (Eqs. 20, 36) and
//! lambda (Eq. 41); for profile-shifted gears ([`GearSet::shifted`]) the same quantities
//! generalised through [`crate::involute`].
//!
//! # Lambda for any tooth numbers and shifts
//!
//! The paper's static analysis (appendix, Eqs. 21-30) balances the planet G2-G3: normal
//! forces act along each mesh's line of action at the base radii, friction mu F_n at the
//! mean slip distance p_ij of Eq. (20) from the pitch point. With profile shift the pitch
//! points are the working pitch points, the lever arms the working pitch radii R'_i and the
//! angles the working pressure angles alpha_w12, alpha_w34; the same steps (mu^2 ~ 0,
//! mu / Z ~ 0) give the lock condition mu Lambda > 1 with
//!
//! Lambda = (p12 / cos alpha_w12 + p34 / cos alpha_w34) / |R'_2 - R'_3|
//!        = pi m cos alpha (h12 / cos alpha_w12 + h34 / cos alpha_w34) / (2 |R'_2 - R'_3|)
//!
//! ([`GearSet::big_lambda_general`]). For standard gears with Z1 + Z2 = Z3 + Z4,
//! alpha_w = alpha and |R'_2 - R'_3| = m n / 2, so it is Eq. (3) exactly.
//!
//! Willis' equation with the mesh efficiencies of Eq. (19) gives the same condition
//! without dropping mu / Z: in the carrier frame G1 drives G4 through eta_12 eta_34 with
//! speed ratio u = Z1 Z3 / (Z2 Z4); backdriven from G4 the carrier's power is
//! T4 w_H (1 - u / eta0) (u < 1) or T4 w_H (1 - eta0 u) (u > 1), which is not positive when
//! eta0 <= min(u, 1/u). To first order in mu that is mu Lambda_W >= 1 with
//! Lambda_W = pi (h12 (1/Z1 + 1/Z2) + h34 (1/Z3 + 1/Z4)) / (1 - min(u, 1/u))
//! ([`GearSet::big_lambda_willis`]). Written in working pitch radii, Lambda_W is Lambda
//! with its two terms multiplied by R'_4 / R'_1 and R'_2 / R'_3 (u < 1; R'_3 / R'_2 and
//! R'_1 / R'_4 for u > 1): ratios 1 + O(n / Z), the terms the paper drops. For shifted
//! gears [`GearSet::big_lambda`] is the smaller of the two, so no verdict rests on the
//! approximation that favours it; for the paper's family Willis' form is never the smaller.

use core::f64::consts::PI;
use core::fmt;

use crate::involute::{self, Mesh};
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
    /// A profile shift coefficient is not finite or outside [-1, 2].
    BadShift {
        /// Gear index 1..=4.
        gear: u8,
    },
    /// Z1 Z3 = Z2 Z4: carrier and output turn together, the reduction ratio is infinite.
    InfiniteRatio,
    /// With the given shifts the two meshes have different working centre distances.
    UnequalWorkingCentreDistance {
        /// Working centre distance of G1-G2, m.
        a12: f64,
        /// Working centre distance of G3-G4, m.
        a34: f64,
        /// x3 + x4 that would put G3-G4 at the G1-G2 distance.
        x34_needed: f64,
    },
    /// The shifts of a mesh are so negative that no working pressure angle exists.
    NoWorkingPressureAngle {
        /// The mesh: 12 or 34.
        mesh: u8,
    },
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
            GearError::BadShift { gear } => write!(
                f,
                "profile shift x{gear} must be a number between -1 and 2 (0 for a standard gear)"
            ),
            GearError::InfiniteRatio => write!(
                f,
                "Z1*Z3 equals Z2*Z4: the reduction ratio is infinite; change a tooth count"
            ),
            GearError::UnequalWorkingCentreDistance {
                a12,
                a34,
                x34_needed,
            } => write!(
                f,
                "unequal working centre distances: G1-G2 {:.4} mm but G3-G4 {:.4} mm; x3 + x4 = {:.4} would match G1-G2",
                a12 * 1e3,
                a34 * 1e3,
                x34_needed
            ),
            GearError::NoWorkingPressureAngle { mesh } => write!(
                f,
                "mesh G{}-G{}: the shifts are too negative for any working pressure angle; raise them",
                mesh / 10,
                mesh % 10
            ),
        }
    }
}

impl core::error::Error for GearError {}

/// A 2K-H planetary gear of external spur gears: G1 fixed, G2-G3 the compound planet on the
/// carrier (the input), G4 the output. One module for both meshes; standard gears
/// ([`GearSet::new`]) or profile-shifted ones ([`GearSet::shifted`]); both validate.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GearSet {
    z: [u32; 4],
    module: f64,
    pressure_angle: f64,
    /// Profile shift coefficients x1..x4 (all zero for standard gears).
    #[cfg_attr(feature = "serde", serde(default))]
    x: [f64; 4],
}

/// Smallest profile shift coefficient [`GearSet::shifted`] accepts.
pub const PROFILE_SHIFT_MIN: f64 = -1.0;
/// Largest profile shift coefficient [`GearSet::shifted`] accepts.
pub const PROFILE_SHIFT_MAX: f64 = 2.0;

/// Largest mismatch of the two working centre distances [`GearSet::shifted`] accepts, in
/// modules (1 um at m = 1 mm: below any manufacturing tolerance of a centre distance).
pub const CENTRE_DISTANCE_TOLERANCE_MODULES: f64 = 1e-3;

/// `v` as a `u32`, `u32::MAX` when larger (for a message's numbers).
const fn saturate_u32(v: u64) -> u32 {
    if v > u32::MAX as u64 {
        u32::MAX
    } else {
        #[allow(clippy::cast_possible_truncation, reason = "checked just above")]
        {
            v as u32
        }
    }
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
        // In u64: tooth counts near u32::MAX (a hostile file) must not overflow the sum.
        let (sum12, sum34) = (z[0] as u64 + z[1] as u64, z[2] as u64 + z[3] as u64);
        if sum12 != sum34 {
            return Err(GearError::UnequalCentreDistance {
                sum12: saturate_u32(sum12),
                sum34: saturate_u32(sum34),
            });
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
            x: [0.0; 4],
        })
    }

    /// A profile-shifted gear set: tooth counts `z`, shift coefficients `x = [x1..x4]`,
    /// module in m, pressure angle in rad. Z1 + Z2 may differ from Z3 + Z4 as long as the
    /// shifts give both meshes the same working centre distance (within
    /// [`CENTRE_DISTANCE_TOLERANCE_MODULES`]). All-zero shifts are [`GearSet::new`].
    pub fn shifted(
        z: [u32; 4],
        x: [f64; 4],
        module: f64,
        pressure_angle: f64,
    ) -> Result<Self, GearError> {
        for (i, xi) in x.iter().enumerate() {
            if !(xi.is_finite() && (PROFILE_SHIFT_MIN..=PROFILE_SHIFT_MAX).contains(xi)) {
                #[allow(clippy::cast_possible_truncation, reason = "i < 4")]
                return Err(GearError::BadShift { gear: i as u8 + 1 });
            }
        }
        if x == [0.0; 4] {
            return Self::new(z, module, pressure_angle);
        }
        if let Some(i) = z.iter().position(|&zi| zi == 0) {
            #[allow(clippy::cast_possible_truncation, reason = "i < 4")]
            return Err(GearError::ZeroTeeth { gear: i as u8 + 1 });
        }
        if z[0] == z[3] {
            return Err(GearError::NoToothDifference);
        }
        if u64::from(z[0]) * u64::from(z[2]) == u64::from(z[1]) * u64::from(z[3]) {
            return Err(GearError::InfiniteRatio);
        }
        if !(module.is_finite() && module > 0.0) {
            return Err(GearError::BadModule);
        }
        if !(pressure_angle > 0.0 && pressure_angle < PI / 4.0) {
            return Err(GearError::BadPressureAngle);
        }
        let g = Self {
            z,
            module,
            pressure_angle,
            x,
        };
        let (m12, m34) = (g.mesh12(), g.mesh34());
        for (mesh, code) in [(m12, 12), (m34, 34)] {
            if !mesh.working_pressure_angle().is_finite() {
                return Err(GearError::NoWorkingPressureAngle { mesh: code });
            }
        }
        let (a12, a34) = (m12.working_centre_distance(), m34.working_centre_distance());
        if (a12 - a34).abs() > CENTRE_DISTANCE_TOLERANCE_MODULES * module {
            return Err(GearError::UnequalWorkingCentreDistance {
                a12,
                a34,
                x34_needed: involute::shift_sum_for_centre_distance(
                    z[2].saturating_add(z[3]),
                    module,
                    pressure_angle,
                    a12,
                ),
            });
        }
        Ok(g)
    }

    /// Profile shift coefficients `[x1, x2, x3, x4]`.
    pub fn shift(&self) -> [f64; 4] {
        self.x
    }

    /// Whether all four gears are standard (zero shift): the paper's Eqs. (2)-(3) as printed.
    pub fn is_standard(&self) -> bool {
        self.x == [0.0; 4]
    }

    /// The G1-G2 mesh.
    pub fn mesh12(&self) -> Mesh {
        Mesh {
            z: [self.z[0], self.z[1]],
            x: [self.x[0], self.x[1]],
            module: self.module,
            alpha: self.pressure_angle,
        }
    }

    /// The G3-G4 mesh.
    pub fn mesh34(&self) -> Mesh {
        Mesh {
            z: [self.z[2], self.z[3]],
            x: [self.x[2], self.x[3]],
            module: self.module,
            alpha: self.pressure_angle,
        }
    }

    /// The mesh G`i` belongs to and its index in it (0 or 1).
    fn mesh_of(&self, i: usize) -> (Mesh, usize) {
        match i {
            1 => (self.mesh12(), 0),
            2 => (self.mesh12(), 1),
            3 => (self.mesh34(), 0),
            _ => (self.mesh34(), 1),
        }
    }

    /// Working pressure angles [alpha_w12, alpha_w34], rad (the pressure angle when standard).
    pub fn working_pressure_angles(&self) -> [f64; 2] {
        if self.is_standard() {
            [self.pressure_angle; 2]
        } else {
            [
                self.mesh12().working_pressure_angle(),
                self.mesh34().working_pressure_angle(),
            ]
        }
    }

    /// Working centre distance of the planet from the central axis (the G1-G2 mesh's; the
    /// G3-G4 one agrees within tolerance), m. m (Z1 + Z2) / 2 for standard gears.
    pub fn centre_distance(&self) -> f64 {
        if self.is_standard() {
            self.pitch_radius(1) + self.pitch_radius(2)
        } else {
            self.mesh12().working_centre_distance()
        }
    }

    /// Working pitch radius R'_i of G`i` in its mesh, m (the pitch radius when standard).
    pub fn working_pitch_radius(&self, i: usize) -> f64 {
        if self.is_standard() {
            self.pitch_radius(i)
        } else {
            let (mesh, k) = self.mesh_of(i);
            mesh.working_pitch_radius(k)
        }
    }

    /// Tip radius of G`i` (with tip shortening), m.
    pub fn tip_radius(&self, i: usize) -> f64 {
        let (mesh, k) = self.mesh_of(i);
        if self.is_standard() {
            self.pitch_radius(i) + self.module
        } else {
            mesh.tip_radius(k)
        }
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

    /// Approach/recess contact ratio of G`i`, Eq. (2); for shifted gears its
    /// generalisation from the shortened tip circle and the working pressure angle
    /// ([`Mesh::contact_ratio`]).
    pub fn contact_ratio(&self, i: usize) -> f64 {
        if !self.is_standard() {
            let (mesh, k) = self.mesh_of(i);
            return mesh.contact_ratio(k);
        }
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

    /// Lambda: Eq. (3), pi (2 - sum eps + sum eps^2) / n, for standard gears; for shifted
    /// ones the smaller of the two generalisations of the module docs
    /// ([`GearSet::big_lambda_general`], [`GearSet::big_lambda_willis`]). Over the paper's
    /// family Willis' form is never the smaller (its radius ratios are both above 1), so
    /// the two rules meet at zero shift.
    pub fn big_lambda(&self) -> f64 {
        if !self.is_standard() {
            let [general, willis] = self.lambdas();
            return general.min(willis);
        }
        let e = self.contact_ratios();
        let sum: f64 = e.iter().sum();
        let sum_sq: f64 = e.iter().map(|x| x * x).sum();
        PI * (2.0 - sum + sum_sq) / self.n() as f64
    }

    /// Lambda for any tooth numbers and shifts from the paper's static balance (module docs):
    /// pi m cos alpha (h12 / cos alpha_w12 + h34 / cos alpha_w34) / (2 |R'_2 - R'_3|).
    pub fn big_lambda_general(&self) -> f64 {
        self.lambdas()[0]
    }

    /// Lambda from Willis' equation and the mesh efficiencies of Eq. (19), first order in mu
    /// (module docs): pi (h12 (1/Z1 + 1/Z2) + h34 (1/Z3 + 1/Z4)) / (1 - min(u, 1/u)),
    /// u = Z1 Z3 / (Z2 Z4).
    pub fn big_lambda_willis(&self) -> f64 {
        self.lambdas()[1]
    }

    /// [`lambdas_of_meshes`] of this set.
    fn lambdas(&self) -> [f64; 2] {
        lambdas_of_meshes(
            self.z,
            self.module,
            self.pressure_angle,
            &self.mesh12().summary(),
            &self.mesh34().summary(),
        )
    }

    /// The smaller of [`GearSet::big_lambda`] and [`GearSet::big_lambda_willis`]: the design
    /// checks' Lambda, so a verdict never rests on the approximation that favours it.
    pub fn big_lambda_conservative(&self) -> f64 {
        self.big_lambda().min(self.big_lambda_willis())
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
        let r12 = self.centre_distance();
        let k = 1.0 + self.zf(1) / self.zf(2);
        inertias.i1 * rho2
            + inertias.m23 * r12 * r12 * rho2
            + inertias.i23 * k * k * rho2
            + inertias.i4
    }

    /// Tangential tooth forces at the reference circles [F_t12, F_t34] for output torque
    /// `tau_out` (N m), N: F_t34 = 2 tau / (m Z4); the planet's moment balance
    /// (F_n12 r_b2 = F_n34 r_b3) gives F_t12 = F_t34 Z3 / Z2. Friction neglected.
    pub fn tangential_forces(&self, tau_out: f64) -> [f64; 2] {
        let ft34 = 2.0 * tau_out.abs() / (self.module * self.zf(4));
        [ft34 * self.zf(3) / self.zf(2), ft34]
    }

    /// Tooth root stress times face width, sigma_F0 b, of G1..G4 at output torque
    /// `tau_out` (N m), N/m: F_t / m Y_Fa Y_Sa Y_eps ([`crate::tooth_strength`], ISO 6336-3
    /// with the load at the tip).
    pub fn root_stress_times_face_width(&self, tau_out: f64) -> [f64; 4] {
        let ft = self.tangential_forces(tau_out);
        let eps = [
            self.contact_ratio(1) + self.contact_ratio(2),
            self.contact_ratio(3) + self.contact_ratio(4),
        ];
        [1usize, 2, 3, 4].map(|i| {
            let mesh = (i - 1) / 2;
            let (y_fa, y_sa) = crate::tooth_strength::form_factors(
                self.z[i - 1],
                self.x[i - 1],
                self.pressure_angle,
                2.0 * self.tip_radius(i) / self.module,
            );
            ft[mesh] / self.module
                * y_fa
                * y_sa
                * crate::tooth_strength::contact_ratio_factor(eps[mesh])
        })
    }

    /// Strength margin at output torque `tau_out` (N m): the highest root stress of the
    /// paper's gear set at its 3.68 N m tooth-strength limit over this set's highest root
    /// stress, same face width and material. Above 1: the teeth are less stressed than the
    /// paper's at its limit.
    pub fn strength_margin(&self, tau_out: f64) -> f64 {
        let max = |s: [f64; 4]| s.into_iter().fold(0.0f64, f64::max);
        let reference =
            max(crate::paper::RIG_GEARS.root_stress_times_face_width(crate::paper::TAU_ROT_MAX));
        reference / max(self.root_stress_times_face_width(tau_out))
    }

    /// Axial force per unit of output torque at the G4 mesh, 2 (1 + Z3/Z2) / (m Z4 cos a), 1/m.
    /// Times mu_ax tau_rot it is the friction part of the excitation force, Eq. (8).
    ///
    /// With profile shift the normal forces act at the working pressure angle:
    /// F_34n = tau_rot / (R'_4 cos alpha_w34) and F_12n = F_34n r_b3 / r_b2, so the factor is
    /// (1 + Z3/Z2) / (R'_4 cos alpha_w34). R'_4 cos alpha_w34 is G4's base radius, so it
    /// equals the standard form: the shift changes neither Eq. (8) nor Eq. (10).
    pub fn axial_force_per_torque(&self) -> f64 {
        if !self.is_standard() {
            let [_, aw34] = self.working_pressure_angles();
            return (1.0 + self.zf(3) / self.zf(2)) / (self.working_pitch_radius(4) * cos(aw34));
        }
        2.0 * (1.0 + self.zf(3) / self.zf(2))
            / (self.module * self.zf(4) * cos(self.pressure_angle))
    }
}

/// [Lambda, Lambda_W] of tooth counts `z`, module `module` (m) and pressure angle `alpha`
/// (rad) from the summaries of the G1-G2 and G3-G4 meshes (module docs): the one place
/// both Lambdas are computed ([`GearSet::big_lambda_general`], [`GearSet::big_lambda_willis`]
/// and the design search).
pub fn lambdas_of_meshes(
    z: [u32; 4],
    module: f64,
    alpha: f64,
    s12: &involute::MeshSummary,
    s34: &involute::MeshSummary,
) -> [f64; 2] {
    let [z1, z2, z3, z4] = z.map(f64::from);
    let h = |s: &involute::MeshSummary| {
        let [a, b] = s.contact_ratio;
        1.0 - a - b + a * a + b * b
    };
    let (h12, h34) = (h(s12), h(s34));
    let r2 = s12.centre_distance * z2 / (z1 + z2);
    let r3 = s34.centre_distance * z3 / (z3 + z4);
    let general = PI * module * cos(alpha) * (h12 / cos(s12.alpha_w) + h34 / cos(s34.alpha_w))
        / (2.0 * (r2 - r3).abs());
    let u = z1 * z3 / (z2 * z4);
    let loss = PI * (h12 * (1.0 / z1 + 1.0 / z2) + h34 * (1.0 / z3 + 1.0 / z4));
    [general, loss / (1.0 - u.min(1.0 / u))]
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

#[cfg(test)]
mod shift_tests;
