//! Friction coefficient from the gross efficiency of the whole gear, Eqs. (11)-(14).

use core::f64::consts::PI;

use crate::GearSet;

/// Gross forward efficiency of the gear (carrier in, G4 out) by Ryokaku's method, Eq. (11),
/// with the mesh efficiencies of Eq. (19) for friction coefficient `mu`.
///
/// With k = (Z1/Z2)(Z3/Z4) and eta0 = eta12 eta34:
/// eta = (1 - k) / (1 - eta0 k) when k < 1, and (1 - k) / (1 - k / eta0) when k > 1.
pub fn eta_gross(gear: &GearSet, mu: f64) -> f64 {
    let [z1, z2, z3, z4] = gear.z().map(|z| z as f64);
    let k = z1 * z3 / (z2 * z4);
    let eta0 = gear.mesh_efficiency(1, 2, mu) * gear.mesh_efficiency(3, 4, mu);
    if k < 1.0 {
        (1.0 - k) / (1.0 - eta0 * k)
    } else {
        (1.0 - k) / (1.0 - k / eta0)
    }
}

/// Friction coefficient from a measured gross efficiency, Eqs. (12)-(13) (first order in mu,
/// as the paper: mu^2 ~ 0 and mu n / Z_i ~ 0).
pub fn mu_from_eta_gross(gear: &GearSet, eta_gross: f64) -> f64 {
    let [z1, z2, z3, z4] = gear.z().map(|z| z as f64);
    let numerator = (1.0 / eta_gross - 1.0) * (z2 * z4 / (z1 * z3) - 1.0).abs();
    let denominator =
        PI * gear.h(1, 2) * (1.0 / z1 + 1.0 / z2) + PI * gear.h(3, 4) * (1.0 / z3 + 1.0 / z4);
    numerator / denominator
}

/// Gross efficiency from the paper's weight test, Eq. (14): a mass `m_out` on the output
/// pulley of radius `r_out` is lifted by a mass `m_in` on the input (carrier) pulley of radius
/// `r_in` at the onset of forward drive.
///
/// The paper prints the torque ratio m_out g r_out / (m_in g r_in); the ideal torque gain of
/// the reducer, |rho|, is divided out here so the result is an efficiency in (0, 1].
pub fn eta_gross_from_masses(gear: &GearSet, m_out: f64, r_out: f64, m_in: f64, r_in: f64) -> f64 {
    (m_out * r_out) / (gear.rho().abs() * m_in * r_in)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::paper;

    fn gear_50_49() -> GearSet {
        paper::FIG5_GEARS
    }

    #[test]
    fn paper_friction_coefficients_from_eta_gross() {
        let g = gear_50_49();
        let mu_s = mu_from_eta_gross(&g, paper::ETA_GROSS_STATIC);
        let mu_d = mu_from_eta_gross(&g, paper::ETA_GROSS_DYNAMIC);
        assert!((mu_s - 0.271).abs() < 0.001, "mu_s {mu_s}");
        assert!((mu_d - 0.174).abs() < 0.001, "mu_d {mu_d}");
        // rig-facts quotes four digits.
        assert!((mu_s - 0.2712).abs() < 0.0005 && (mu_d - 0.1742).abs() < 0.0005);
    }

    #[test]
    fn eq12_inverts_eq11_to_first_order() {
        for z in crate::paper::TABLE1 {
            let g = GearSet::paper(z).unwrap();
            for mu in [0.02, 0.05, 0.1] {
                let back = mu_from_eta_gross(&g, eta_gross(&g, mu));
                assert!((back / mu - 1.0).abs() < 0.05, "{z:?} mu {mu} -> {back}");
            }
        }
    }

    #[test]
    fn efficiency_falls_as_friction_rises() {
        let g = gear_50_49();
        assert!((eta_gross(&g, 0.0) - 1.0).abs() < 1e-12);
        assert!(eta_gross(&g, 0.1) > eta_gross(&g, 0.2));
    }

    #[test]
    fn weight_test_gives_the_efficiency() {
        let g = gear_50_49();
        // 3.0 kg on 75 mm lifted at eta 0.423 needs m_in = 3 * 0.075 / (24.5 * 0.423 * 0.1).
        let (r_in, r_out) = (paper::R_IN, paper::R_OUT);
        let m_in = 3.0 * r_out / (24.5 * 0.423 * r_in);
        let eta = eta_gross_from_masses(&g, 3.0, r_out, m_in, r_in);
        assert!((eta - 0.423).abs() < 1e-9);
    }
}
