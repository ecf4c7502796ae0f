//! Involute geometry of profile-shifted external spur gears: the involute function, the
//! working pressure angle and centre distance of a mesh, tip shortening, tip and root
//! radii, tip thickness, the undercut limit, the root form circle and the contact ratios
//! of each gear (the paper's Eq. (2) generalised).
//!
//! Formulas as in ISO 21771:2007 and KHK's "Gear technical reference" (profile-shifted
//! spur gears, tables 4.5 and 4.9): reference rack with addendum 1 m and dedendum 1.25 m,
//! tip shortening that keeps the standard bottom clearance of 0.25 m. Lengths in m, angles
//! in rad; shift coefficients x and tooth counts z are dimensionless.

use core::f64::consts::PI;

use crate::math::{acos, atan, cos, sin, tan};

/// Addendum of the reference rack, in modules (ISO 53).
pub const ADDENDUM: f64 = 1.0;
/// Dedendum of the reference rack, in modules (ISO 53: 1.25).
pub const DEDENDUM: f64 = 1.25;

/// The involute function inv a = tan a - a.
pub fn inv(a: f64) -> f64 {
    tan(a) - a
}

/// The angle whose involute is `v` (>= 0): Newton's iteration on tan a - a = v from a
/// start that is exact to 1 % for small angles ((3 v)^(1/3)). NaN for negative or
/// non-finite `v`.
pub fn inv_inverse(v: f64) -> f64 {
    if !(v >= 0.0 && v.is_finite()) {
        return f64::NAN;
    }
    if v == 0.0 {
        return 0.0;
    }
    // inv a ~ a^3 / 3 for small a; atan keeps the start below pi/2 for large v.
    let mut a = libm::cbrt(3.0 * v).min(atan(v + 1.0));
    for _ in 0..40 {
        let t = tan(a);
        // d/da (tan a - a) = tan^2 a.
        let step = (t - a - v) / (t * t);
        a -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    a
}

/// One mesh of two external gears with tooth counts `z`, shift coefficients `x`, module
/// `module` (m) and reference pressure angle `alpha` (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mesh {
    /// Tooth counts of the two gears.
    pub z: [u32; 2],
    /// Profile shift coefficients of the two gears.
    pub x: [f64; 2],
    /// Module, m.
    pub module: f64,
    /// Reference pressure angle, rad.
    pub alpha: f64,
}

impl Mesh {
    fn zf(&self) -> [f64; 2] {
        self.z.map(f64::from)
    }

    /// Working pressure angle alpha_w: inv alpha_w = 2 tan alpha (x1 + x2) / (z1 + z2) +
    /// inv alpha (ISO 21771 Eq. 52). NaN when the shifts are so negative that the
    /// involute would be negative.
    pub fn working_pressure_angle(&self) -> f64 {
        let [z1, z2] = self.zf();
        let [x1, x2] = self.x;
        inv_inverse(2.0 * tan(self.alpha) * (x1 + x2) / (z1 + z2) + inv(self.alpha))
    }

    /// Reference centre distance a = m (z1 + z2) / 2, m.
    pub fn reference_centre_distance(&self) -> f64 {
        let [z1, z2] = self.zf();
        self.module * (z1 + z2) / 2.0
    }

    /// Working centre distance a_w = a cos alpha / cos alpha_w, m.
    pub fn working_centre_distance(&self) -> f64 {
        self.reference_centre_distance() * cos(self.alpha) / cos(self.working_pressure_angle())
    }

    /// Centre distance modification coefficient y = (a_w - a) / m.
    pub fn centre_distance_modification(&self) -> f64 {
        (self.working_centre_distance() - self.reference_centre_distance()) / self.module
    }

    /// Tip shortening coefficient k = x1 + x2 - y, where it is needed to keep the standard
    /// bottom clearance (0.25 m); zero otherwise (never lengthens a tooth).
    pub fn tip_shortening(&self) -> f64 {
        (self.x[0] + self.x[1] - self.centre_distance_modification()).max(0.0)
    }

    /// Working pitch radius of gear `k` (0 or 1): a_w z_k / (z1 + z2) = r_b / cos alpha_w, m.
    pub fn working_pitch_radius(&self, k: usize) -> f64 {
        let z = self.zf();
        self.working_centre_distance() * z[k] / (z[0] + z[1])
    }

    /// Tip radius of gear `k`: m (z/2 + 1 + x - k_shortening), m.
    pub fn tip_radius(&self, k: usize) -> f64 {
        let z = self.zf()[k];
        self.module * (z / 2.0 + ADDENDUM + self.x[k] - self.tip_shortening())
    }

    /// Base radius of gear `k`: m z cos alpha / 2, m.
    pub fn base_radius(&self, k: usize) -> f64 {
        self.module * self.zf()[k] * cos(self.alpha) / 2.0
    }

    /// Root radius of gear `k`: m (z/2 - 1.25 + x), m.
    pub fn root_radius(&self, k: usize) -> f64 {
        self.module * (self.zf()[k] / 2.0 - DEDENDUM + self.x[k])
    }

    /// Pressure angle at the tip circle of gear `k`, rad.
    pub fn tip_pressure_angle(&self, k: usize) -> f64 {
        acos((self.base_radius(k) / self.tip_radius(k)).min(1.0))
    }

    /// Approach/recess contact ratio of gear `k`, the paper's Eq. (2) generalised: the
    /// path from the working pitch point to where the tip of gear `k` leaves contact, in
    /// base pitches: z / (2 pi) (tan alpha_a - tan alpha_w). At zero shift it is Eq. (2).
    pub fn contact_ratio(&self, k: usize) -> f64 {
        let z = self.zf()[k];
        z / (2.0 * PI) * (tan(self.tip_pressure_angle(k)) - tan(self.working_pressure_angle()))
    }

    /// Transverse contact ratio of the mesh, eps_alpha = eps_1 + eps_2.
    pub fn total_contact_ratio(&self) -> f64 {
        self.contact_ratio(0) + self.contact_ratio(1)
    }

    /// Tooth thickness (arc) at the tip circle of gear `k`, m:
    /// d_a (pi / (2 z) + 2 x tan alpha / z + inv alpha - inv alpha_a) (KHK table 4.15).
    /// Zero or negative: the tooth is pointed.
    pub fn tip_thickness(&self, k: usize) -> f64 {
        let (z, x) = (self.zf()[k], self.x[k]);
        2.0 * self.tip_radius(k)
            * (PI / (2.0 * z) + 2.0 * x * tan(self.alpha) / z + inv(self.alpha)
                - inv(self.tip_pressure_angle(k)))
    }

    /// Roll parameter tan alpha at the start of the active profile of gear `k` (where the
    /// mating tip first touches it): tan alpha_w - (z_j / z_k)(tan alpha_aj - tan alpha_w).
    pub fn start_of_active_profile_tan(&self, k: usize) -> f64 {
        let z = self.zf();
        let j = 1 - k;
        let tw = tan(self.working_pressure_angle());
        tw - z[j] / z[k] * (tan(self.tip_pressure_angle(j)) - tw)
    }

    /// Involute (meshing) interference on gear `k`: the mating tip reaches below the root
    /// form circle the generating rack leaves ([`form_circle_tan`]).
    pub fn interferes(&self, k: usize) -> bool {
        self.start_of_active_profile_tan(k)
            < form_circle_tan(self.z[k], self.x[k], self.alpha) - 1e-12
    }
}

/// Smallest shift coefficient without undercut for `z` teeth cut by the reference rack:
/// x_min = 1 - z sin^2(alpha) / 2 (KHK Eq. 4.4, ISO 21771 theoretical limit).
pub fn min_shift_without_undercut(z: u32, alpha: f64) -> f64 {
    let s = sin(alpha);
    ADDENDUM - f64::from(z) * s * s / 2.0
}

/// tan of the pressure angle at the root form circle a rack with addendum 1 m leaves on a
/// gear of `z` teeth and shift `x` (tool tip radius neglected):
/// tan alpha - 4 (1 - x) / (z sin 2 alpha), at least 0 (the base circle).
pub fn form_circle_tan(z: u32, x: f64, alpha: f64) -> f64 {
    (tan(alpha) - 4.0 * (ADDENDUM - x) / (f64::from(z) * sin(2.0 * alpha))).max(0.0)
}

/// Sum of shift coefficients x1 + x2 that puts a mesh of `z` teeth (sum) at working
/// centre distance `a_w` (m), module `module`, pressure angle `alpha`: the inverse of
/// [`Mesh::working_centre_distance`]. NaN when `a_w` is too short for any shift.
pub fn shift_sum_for_centre_distance(z_sum: u32, module: f64, alpha: f64, a_w: f64) -> f64 {
    let a = module * f64::from(z_sum) / 2.0;
    let c = a * cos(alpha) / a_w;
    if !(c > 0.0 && c <= 1.0) {
        return f64::NAN;
    }
    let alpha_w = acos(c);
    (inv(alpha_w) - inv(alpha)) * f64::from(z_sum) / (2.0 * tan(alpha))
}

/// Everything a design check needs from one mesh, computed once (one working pressure
/// angle solve): the same numbers as the [`Mesh`] methods.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshSummary {
    /// Working pressure angle, rad.
    pub alpha_w: f64,
    /// Working centre distance, m.
    pub centre_distance: f64,
    /// Tip shortening coefficient k.
    pub tip_shortening: f64,
    /// Tip radii, m.
    pub tip_radius: [f64; 2],
    /// Approach/recess contact ratios of the two gears (Eq. 2 generalised).
    pub contact_ratio: [f64; 2],
    /// Tip thickness in modules.
    pub tip_thickness_modules: [f64; 2],
    /// Undercut: x below [`min_shift_without_undercut`].
    pub undercut: [bool; 2],
    /// Involute interference: the mating tip reaches below the root form circle.
    pub interference: [bool; 2],
}

impl Mesh {
    /// All of [`MeshSummary`] in one pass. NaN fields when no working pressure angle exists.
    pub fn summary(&self) -> MeshSummary {
        let z = self.zf();
        let m = self.module;
        let (ta, ca) = (tan(self.alpha), cos(self.alpha));
        let alpha_w =
            inv_inverse(2.0 * ta * (self.x[0] + self.x[1]) / (z[0] + z[1]) + inv(self.alpha));
        let a = m * (z[0] + z[1]) / 2.0;
        let centre_distance = a * ca / cos(alpha_w);
        let y = (centre_distance - a) / m;
        let k = (self.x[0] + self.x[1] - y).max(0.0);
        let tw = tan(alpha_w);
        let tip_radius = [0, 1].map(|i| m * (z[i] / 2.0 + ADDENDUM + self.x[i] - k));
        let alpha_a = [0, 1].map(|i| acos((m * z[i] * ca / 2.0 / tip_radius[i]).min(1.0)));
        let tan_a = alpha_a.map(tan);
        let contact_ratio = [0, 1].map(|i| z[i] / (2.0 * PI) * (tan_a[i] - tw));
        let tip_thickness_modules = [0, 1].map(|i| {
            2.0 * tip_radius[i] / m
                * (PI / (2.0 * z[i]) + 2.0 * self.x[i] * ta / z[i] + inv(self.alpha)
                    - inv(alpha_a[i]))
        });
        let undercut =
            [0, 1].map(|i| self.x[i] < min_shift_without_undercut(self.z[i], self.alpha) - 1e-12);
        let interference = [0, 1].map(|i| {
            let j = 1 - i;
            let sap = tw - z[j] / z[i] * (tan_a[j] - tw);
            sap < form_circle_tan(self.z[i], self.x[i], self.alpha) - 1e-12
        });
        MeshSummary {
            alpha_w,
            centre_distance,
            tip_shortening: k,
            tip_radius,
            contact_ratio,
            tip_thickness_modules,
            undercut,
            interference,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_agrees_with_the_single_methods() {
        for (z, x) in [
            ([12, 24], [0.6, 0.36]),
            ([49, 52], [0.3, -0.1]),
            ([10, 40], [0.0, 0.0]),
        ] {
            let mesh = Mesh {
                z,
                x,
                module: 1e-3,
                alpha: 20f64.to_radians(),
            };
            let s = mesh.summary();
            assert_eq!(s.alpha_w, mesh.working_pressure_angle());
            assert!((s.centre_distance - mesh.working_centre_distance()).abs() < 1e-15);
            for k in 0..2 {
                assert!((s.tip_radius[k] - mesh.tip_radius(k)).abs() < 1e-15);
                assert!((s.contact_ratio[k] - mesh.contact_ratio(k)).abs() < 1e-12);
                assert!((s.tip_thickness_modules[k] * 1e-3 - mesh.tip_thickness(k)).abs() < 1e-12);
                assert_eq!(s.interference[k], mesh.interferes(k));
            }
        }
        // 10 teeth unshifted: undercut (x_min = 0.42).
        let s = Mesh {
            z: [10, 40],
            x: [0.0, 0.0],
            module: 1e-3,
            alpha: 20f64.to_radians(),
        }
        .summary();
        assert_eq!(s.undercut, [true, false]);
    }
}
