//! The mesh load-sharing ripple (seed 003, Eq. 11): load sharing between single- and
//! double-tooth contact, with a load-dependent local friction, modulates the mesh friction
//! over a mesh cycle. The current's averaging window sits at a random mesh phase, so the
//! friction term scatters from test to test.

/// Load share of a tooth pair at position `x` along the path of contact, in base pitches
/// from the start of contact (0 ..= contact ratio), seed 003's Eq. (11): rising from 0.36 to
/// 0.64 in the double-contact zone of entry, 1 in single contact, falling from 0.64 to 0.36
/// in the double-contact zone of exit. `contact_ratio` is clamped to [1.05, 2].
pub fn load_sharing_factor(x: f64, contact_ratio: f64) -> f64 {
    let eps = contact_ratio.clamp(1.05, 2.0);
    let x = x.clamp(0.0, eps);
    if x < eps - 1.0 {
        0.36 + 0.28 * x / (eps - 1.0)
    } else if x < 1.0 {
        1.0
    } else {
        0.36 - 0.28 * (x - eps) / (eps - 1.0)
    }
}

/// Total mesh friction at mesh phase `phase` (0..1 of a base pitch) relative to a single pair
/// carrying the whole load, when the local friction coefficient grows with the local load to
/// the power `load_exponent` (seed 003, Eq. 12: 0.2): sum of lambda^(1 + b) over the pairs in
/// contact.
pub fn mesh_friction(phase: f64, contact_ratio: f64, load_exponent: f64) -> f64 {
    let eps = contact_ratio.clamp(1.05, 2.0);
    let phi = phase - libm::floor(phase);
    let mut total = libm::pow(load_sharing_factor(phi, eps), 1.0 + load_exponent);
    if phi + 1.0 < eps {
        total += libm::pow(load_sharing_factor(phi + 1.0, eps), 1.0 + load_exponent);
    }
    total
}

/// Points per mesh cycle of the averages in [`mesh_friction_modulation`].
const MESH_SAMPLES: usize = 256;

/// Relative deviation of the mesh friction at `phase` from its mean over a mesh cycle,
/// normalised to unit rms: the shape of the ripple the current window sees at a random
/// phase. Zero for a contact ratio at which the friction does not vary.
pub fn mesh_friction_modulation(phase: f64, contact_ratio: f64, load_exponent: f64) -> f64 {
    let (mean, rms) = mesh_friction_stats(contact_ratio, load_exponent);
    if rms == 0.0 {
        return 0.0;
    }
    (mesh_friction(phase, contact_ratio, load_exponent) / mean - 1.0) / rms
}

/// Mean of [`mesh_friction`] over a cycle and the rms of its relative deviation.
pub fn mesh_friction_stats(contact_ratio: f64, load_exponent: f64) -> (f64, f64) {
    let n = MESH_SAMPLES as f64;
    let sample = |k: usize| mesh_friction((k as f64 + 0.5) / n, contact_ratio, load_exponent);
    let mean = (0..MESH_SAMPLES).map(sample).sum::<f64>() / n;
    let var = (0..MESH_SAMPLES)
        .map(|k| {
            let d = sample(k) / mean - 1.0;
            d * d
        })
        .sum::<f64>()
        / n;
    (mean, libm::sqrt(var))
}

/// Current the mesh ripple adds at a test whose window sat at a mesh phase with
/// normalised modulation `modulation` ([`mesh_friction_modulation`]): the friction term's
/// current `friction_current` (A) times the relative rms `ripple_rms` times the modulation.
#[inline]
pub fn mesh_ripple_current(friction_current: f64, ripple_rms: f64, modulation: f64) -> f64 {
    ripple_rms * modulation * friction_current
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::ISO_LOAD_EXPONENT;

    #[test]
    fn load_sharing_follows_seed_003_eq11() {
        let eps = 1.7;
        assert!((load_sharing_factor(0.0, eps) - 0.36).abs() < 1e-12);
        assert!((load_sharing_factor(0.85, eps) - 1.0).abs() < 1e-12);
        assert!((load_sharing_factor(eps, eps) - 0.36).abs() < 1e-12);
        // The two pairs of a double contact carry the whole load.
        for phi in [0.0, 0.2, 0.5, 0.69] {
            let sum = load_sharing_factor(phi, eps) + load_sharing_factor(phi + 1.0, eps);
            assert!((sum - 1.0).abs() < 1e-12, "{phi}");
        }
        // Pure Coulomb friction (exponent 0) does not ripple; seed 003's 0.2 does.
        assert!(
            mesh_friction_stats(eps, 0.0).1 < 1e-12,
            "{:?}",
            mesh_friction_stats(eps, 0.0)
        );
        let (_, rms) = mesh_friction_stats(eps, ISO_LOAD_EXPONENT);
        assert!(rms > 0.01 && rms < 0.2, "{rms}");
        let mean_mod: f64 = (0..100)
            .map(|k| mesh_friction_modulation(k as f64 / 100.0, eps, 0.2))
            .sum::<f64>()
            / 100.0;
        assert!(mean_mod.abs() < 0.05);
        assert_eq!(mesh_ripple_current(0.5, 0.1, -1.0), -0.05);
    }
}
