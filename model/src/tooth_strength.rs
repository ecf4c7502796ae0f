//! Tooth root bending stress of external spur gears by ISO 6336-3:2006 with the load at
//! the tooth tip (the method-C form of the standard): sigma_F0 = F_t / (b m) Y_Fa Y_Sa
//! Y_eps, with the form factor Y_Fa and stress-correction factor Y_Sa from the 30-degree
//! tangent on the root fillet the ISO 53 basic rack (dedendum 1.25 m, root radius 0.38 m,
//! no protuberance) generates, and Y_eps = 0.25 + 0.75 / eps_alpha.
//!
//! The rig's reference point is the paper's: its gear set (49, 51, 50, 50) carries at most
//! 3.68 N m ([`crate::paper::TAU_ROT_MAX`]). Without a material and face width the
//! strength margin of a design is the stress of that reference over the design's stress
//! at its rated load, same face width and material ([`crate::GearSet::strength_margin`]).

use core::f64::consts::PI;

use crate::involute::{DEDENDUM, inv};
use crate::math::{acos, cos, sin, sqrt, tan};

/// Root fillet radius of the ISO 53 basic rack (profiles A and B), in modules.
pub const RACK_ROOT_RADIUS: f64 = 0.38;

/// Form factor Y_Fa and stress-correction factor Y_Sa for load at the tip of a gear of `z`
/// teeth, shift `x`, pressure angle `alpha` (rad) and tip diameter `tip_diameter_modules`
/// (d_a / m). ISO 6336-3:2006 Eqs. (14)-(25) with d_en = d_a.
pub fn form_factors(z: u32, x: f64, alpha: f64, tip_diameter_modules: f64) -> (f64, f64) {
    let zf = f64::from(z);
    let (h_fp, rho_fp) = (DEDENDUM, RACK_ROOT_RADIUS);
    // All lengths in modules.
    let e = PI / 4.0 - h_fp * tan(alpha) - (1.0 - sin(alpha)) * rho_fp / cos(alpha);
    let g = rho_fp - h_fp + x;
    let h = 2.0 / zf * (PI / 2.0 - e) - PI / 3.0;
    let mut theta = PI / 6.0;
    for _ in 0..50 {
        let next = 2.0 * g / zf * tan(theta) - h;
        let done = (next - theta).abs() < 1e-13;
        theta = next;
        if done {
            break;
        }
    }
    let s_fn = zf * sin(PI / 3.0 - theta) + sqrt(3.0) * (g / cos(theta) - rho_fp);
    let rho_f = rho_fp + 2.0 * g * g / (cos(theta) * (zf * cos(theta) * cos(theta) - 2.0 * g));
    let d_b = zf * cos(alpha);
    let alpha_en = acos((d_b / tip_diameter_modules).min(1.0));
    let gamma_e = (PI / 2.0 + 2.0 * x * tan(alpha)) / zf + inv(alpha) - inv(alpha_en);
    let alpha_fen = alpha_en - gamma_e;
    let h_fe = 0.5
        * ((cos(gamma_e) - sin(gamma_e) * tan(alpha_fen)) * tip_diameter_modules
            - zf * cos(PI / 3.0 - theta)
            - g / cos(theta)
            + rho_fp);
    let y_fa = 6.0 * h_fe * cos(alpha_fen) / (s_fn * s_fn * cos(alpha));
    let l = s_fn / h_fe;
    let q_s = s_fn / (2.0 * rho_f);
    let y_sa = (1.2 + 0.13 * l) * libm::pow(q_s, 1.0 / (1.21 + 2.3 / l));
    (y_fa, y_sa)
}

/// Contact-ratio factor Y_eps = 0.25 + 0.75 / eps_alpha (ISO 6336-3 Eq. 5).
pub fn contact_ratio_factor(eps_alpha: f64) -> f64 {
    0.25 + 0.75 / eps_alpha
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Y_Fa and Y_Sa of standard 20-degree gears (x = 0, d_a = (z + 2) m) as tabulated from
    /// DIN 3990-3 / ISO 6336-3 for load at the tip (e.g. Roloff/Matek, Maschinenelemente,
    /// Tabellenbuch TB 21-19; Budynas/Shigley's metric tables quote the same values).
    const TABULATED: [(u32, f64, f64); 6] = [
        (20, 2.80, 1.55),
        (25, 2.62, 1.59),
        (30, 2.52, 1.625),
        (40, 2.40, 1.67),
        (50, 2.32, 1.70),
        (100, 2.18, 1.79),
    ];

    #[test]
    fn standard_gear_form_factors_match_the_tabulated_values() {
        let alpha = 20f64.to_radians();
        for (z, y_fa, y_sa) in TABULATED {
            let (fa, sa) = form_factors(z, 0.0, alpha, f64::from(z) + 2.0);
            assert!((fa / y_fa - 1.0).abs() < 0.02, "z {z}: Y_Fa {fa} vs {y_fa}");
            assert!((sa / y_sa - 1.0).abs() < 0.02, "z {z}: Y_Sa {sa} vs {y_sa}");
        }
    }

    #[test]
    fn positive_shift_thickens_the_root() {
        // A positive shift moves the rack out: thicker root chord, smaller Y_Fa (ISO 6336-3
        // Fig. 1 trend), for the same tip diameter rule d_a = (z + 2 + 2x) m.
        let alpha = 20f64.to_radians();
        let (y0, _) = form_factors(30, 0.0, alpha, 32.0);
        let (y5, _) = form_factors(30, 0.5, alpha, 33.0);
        assert!(y5 < y0 - 0.1, "{y5} vs {y0}");
    }
}
