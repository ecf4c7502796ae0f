//! Profile-shifted geometry against a handbook's worked example and first principles, the
//! generalised Lambda against the paper's Eq. (3) and Willis' equation.

use core::f64::consts::PI;

use super::*;
use crate::involute::{self, Mesh, inv, inv_inverse};
use crate::paper;

const ALPHA: f64 = 20.0 * PI / 180.0;

/// KHK, "Gear technical reference", Table 4.5 (calculation of profile-shifted spur gears):
/// m = 3 mm, alpha = 20 deg, z = 12 / 24, x = 0.6 / 0.36 give inv alpha_w = 0.034316,
/// alpha_w = 26.0886 deg, y = 0.83329, a_w = 56.4999 mm, d_a = 44.840 / 79.400 mm (tip
/// heights (1 + y - x_other) m) and d_f = 32.100 / 66.660 mm.
#[test]
fn khk_worked_example_of_a_profile_shifted_pair() {
    let mesh = Mesh {
        z: [12, 24],
        x: [0.6, 0.36],
        module: 3e-3,
        alpha: ALPHA,
    };
    let aw = mesh.working_pressure_angle();
    assert!((inv(aw) - 0.034316).abs() < 1e-6, "inv alpha_w {}", inv(aw));
    assert!(
        (aw.to_degrees() - 26.0886).abs() < 1e-4,
        "{}",
        aw.to_degrees()
    );
    assert!((mesh.centre_distance_modification() - 0.83329).abs() < 1e-5);
    assert!((mesh.working_centre_distance() * 1e3 - 56.4999).abs() < 1e-4);
    assert!((2.0 * mesh.tip_radius(0) * 1e3 - 44.840).abs() < 1e-3);
    assert!((2.0 * mesh.tip_radius(1) * 1e3 - 79.400).abs() < 1e-3);
    assert!((2.0 * mesh.root_radius(0) * 1e3 - 32.100).abs() < 1e-9);
    assert!((2.0 * mesh.root_radius(1) * 1e3 - 66.660).abs() < 1e-9);
    // KHK Table 4.6, the inverse: a_w = 56.4999 mm asks for x1 + x2 = 0.96.
    let xs = involute::shift_sum_for_centre_distance(36, 3e-3, ALPHA, 56.4999e-3);
    assert!((xs - 0.96).abs() < 1e-4, "{xs}");
}

#[test]
fn inverse_involute_round_trips() {
    for deg in [0.5, 5.0, 14.5, 20.0, 26.0886, 35.0, 50.0, 70.0] {
        let a = f64::to_radians(deg);
        assert!((inv_inverse(inv(a)) - a).abs() < 1e-12, "{deg}");
    }
    assert!(inv_inverse(-0.1).is_nan());
}

/// ISO 21771 Eq. (93): eps_alpha = (sqrt(r_a1^2 - r_b1^2) + sqrt(r_a2^2 - r_b2^2) -
/// a_w sin alpha_w) / (pi m cos alpha), the path of contact in base pitches; the split
/// per gear of [`Mesh::contact_ratio`] must add up to it.
#[test]
fn contact_ratio_is_the_path_of_contact_in_base_pitches() {
    for (z, x) in [
        ([12, 24], [0.6, 0.36]),
        ([49, 52], [0.3, -0.1]),
        ([20, 80], [0.0, 0.0]),
        ([18, 30], [-0.2, 0.5]),
    ] {
        let mesh = Mesh {
            z,
            x,
            module: 1e-3,
            alpha: ALPHA,
        };
        let path: f64 = [0, 1]
            .map(|k| {
                let (ra, rb) = (mesh.tip_radius(k), mesh.base_radius(k));
                (ra * ra - rb * rb).sqrt()
            })
            .iter()
            .sum::<f64>()
            - mesh.working_centre_distance() * mesh.working_pressure_angle().sin();
        let iso = path / (PI * 1e-3 * ALPHA.cos());
        assert!(
            (mesh.total_contact_ratio() - iso).abs() < 1e-12,
            "{z:?} {x:?}"
        );
    }
}

#[test]
fn undercut_limit_is_17_teeth_at_20_degrees() {
    // 2 / sin^2(20 deg) = 17.1: 18 teeth and more need no shift.
    assert!(involute::min_shift_without_undercut(17, ALPHA) > 0.0);
    assert!(involute::min_shift_without_undercut(18, ALPHA) < 0.0);
    // KHK Table 4.4: z = 12 needs x >= 0.30 (0.2982).
    assert!((involute::min_shift_without_undercut(12, ALPHA) - 0.2982).abs() < 1e-4);
}

#[test]
fn zero_shift_is_the_paper_s_gear_set() {
    for z in paper::TABLE1 {
        let g = GearSet::shifted(z, [0.0; 4], paper::MODULE, ALPHA).unwrap();
        assert_eq!(g, GearSet::paper(z).unwrap());
        // The general geometry at zero shift: alpha_w = alpha, a_w = a, Eq. (2).
        for mesh in [g.mesh12(), g.mesh34()] {
            assert!((mesh.working_pressure_angle() - ALPHA).abs() < 1e-12);
            assert!((mesh.working_centre_distance() - 50e-3).abs() < 1e-15);
            assert_eq!(mesh.tip_shortening(), 0.0);
        }
        assert!((g.mesh12().contact_ratio(0) - g.contact_ratio(1)).abs() < 1e-12);
        assert!((g.mesh34().contact_ratio(1) - g.contact_ratio(4)).abs() < 1e-12);
    }
}

/// Every Table-1-like family (standard gears, Z1 + Z2 = Z3 + Z4 = S, one module): the
/// generalised Lambda is Eq. (3), and Willis' Lambda is its closed form
/// pi (h12 Z4/Z1 + h34 Z2/Z3) / n (u < 1) or pi (h12 Z3/Z2 + h34 Z1/Z4) / n (u > 1).
#[test]
fn generalised_lambda_is_eq3_over_every_table1_like_family() {
    let mut checked = 0;
    for s in [60u32, 80, 100, 120, 160] {
        for z1 in 18..=s - 18 {
            for z4 in 18..=s - 18 {
                let n = z1.abs_diff(z4);
                if n == 0 || n > 6 {
                    continue;
                }
                let g = GearSet::paper([z1, s - z1, s - z4, z4]).unwrap();
                let e = g.contact_ratios();
                let eq3 = PI * (2.0 - e.iter().sum::<f64>() + e.iter().map(|v| v * v).sum::<f64>())
                    / f64::from(n);
                assert!((g.big_lambda_general() / eq3 - 1.0).abs() < 1e-12);
                assert_eq!(g.big_lambda(), eq3);
                let [z1f, z2f, z3f, z4f] = g.z().map(f64::from);
                let u = z1f * z3f / (z2f * z4f);
                let (h12, h34) = (g.h(1, 2), g.h(3, 4));
                let willis = if u < 1.0 {
                    PI * (h12 * z4f / z1f + h34 * z2f / z3f) / f64::from(n)
                } else {
                    PI * (h12 * z3f / z2f + h34 * z1f / z4f) / f64::from(n)
                };
                assert!((g.big_lambda_willis() / willis - 1.0).abs() < 1e-12);
                // Both radius ratios exceed 1 in the family: Willis' Lambda is never the
                // smaller, so the conservative Lambda is Eq. (3) too.
                assert!(g.big_lambda_willis() >= eq3 - 1e-12);
                assert_eq!(g.big_lambda_conservative(), eq3);
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn table1_verdicts_unchanged_with_the_conservative_lambda() {
    // 6/6 of Table 1 at mu_s = 0.271, also with the smaller of the two Lambdas.
    for z in paper::TABLE1 {
        let g = GearSet::paper(z).unwrap();
        let n1 = g.n() == 1;
        assert_eq!(paper::MU_S * g.big_lambda_conservative() > 1.0, n1, "{z:?}");
    }
}

/// A shifted set with Z1 + Z2 != Z3 + Z4 on the paper's centre distance.
fn shifted_example() -> GearSet {
    let z = [49, 51, 51, 50];
    let x12 = [0.2, 0.3];
    let a = Mesh {
        z: [49, 51],
        x: x12,
        module: 1e-3,
        alpha: ALPHA,
    }
    .working_centre_distance();
    let x34 = involute::shift_sum_for_centre_distance(101, 1e-3, ALPHA, a);
    GearSet::shifted(z, [x12[0], x12[1], x34 / 2.0, x34 / 2.0], 1e-3, ALPHA).unwrap()
}

#[test]
fn willis_lambda_is_the_general_lambda_with_the_dropped_radius_ratios() {
    // Lambda_W = A f1 + B f2 where Lambda = A + B: a weighted mean of the two radius
    // ratios R'_4/R'_1 and R'_2/R'_3 (u < 1), so it lies between them.
    let g = shifted_example();
    let r = |i| g.working_pitch_radius(i);
    let (f1, f2) = (r(4) / r(1), r(2) / r(3));
    let ratio = g.big_lambda_willis() / g.big_lambda_general();
    assert!(
        ratio >= f1.min(f2) - 1e-12 && ratio <= f1.max(f2) + 1e-12,
        "{ratio} not in [{f1}, {f2}]"
    );
    // The exact lock point of Willis' equation with Eq. (19): eta12 eta34 = u. Its mu
    // agrees with 1 / Lambda_W to first order in mu.
    let [z1, z2, z3, z4] = g.z().map(f64::from);
    let u = z1 * z3 / (z2 * z4);
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..100 {
        let mu = 0.5 * (lo + hi);
        if g.mesh_efficiency(1, 2, mu) * g.mesh_efficiency(3, 4, mu) > u {
            lo = mu;
        } else {
            hi = mu;
        }
    }
    let a = PI * g.h(1, 2) * (1.0 / z1 + 1.0 / z2);
    let b = PI * g.h(3, 4) * (1.0 / z3 + 1.0 / z4);
    // eta0 = 1 - mu (a + b) + mu^2 a b: the first-order solution is low by mu^2 a b.
    let first_order = 1.0 / g.big_lambda_willis();
    assert!(
        (lo - first_order).abs() <= 2.0 * lo * lo * a * b / (a + b),
        "{lo} vs {first_order}"
    );
}

#[test]
fn shift_with_unequal_sums_shares_the_carrier_and_raises_lambda() {
    let g = shifted_example();
    let [aw12, aw34] = g.working_pressure_angles();
    // x1 + x2 = 0.5 spreads G1-G2; G3-G4 has one tooth more and needs a small negative
    // x3 + x4 to sit at the same distance.
    assert!(aw12 > ALPHA && aw34 < ALPHA, "{aw12} {aw34}");
    assert!(g.shift()[2] + g.shift()[3] < 0.0);
    assert!(
        (g.mesh12().working_centre_distance() - g.mesh34().working_centre_distance()).abs() < 1e-9
    );
    // R'_2 - R'_3 = a_w (Z2/(Z1+Z2) - Z3/(Z3+Z4)): half the paper's lever arm.
    let arm = g.working_pitch_radius(2) - g.working_pitch_radius(3);
    let expected = g.centre_distance() * (51.0 / 100.0 - 51.0 / 101.0);
    assert!((arm - expected).abs() < 1e-12);
    assert!(g.big_lambda() > 1.5 * paper::RIG_GEARS.big_lambda());
    // Eq. (8): the shift changes the angle and radius, not their product r_b4.
    let std_form = 2.0 * (1.0 + 51.0 / 51.0) / (1e-3 * 50.0 * ALPHA.cos());
    assert!((g.axial_force_per_torque() / std_form - 1.0).abs() < 1e-12);
}

#[test]
fn unequal_working_centre_distances_are_refused_with_the_fix() {
    let err = GearSet::shifted([49, 51, 51, 50], [0.2, 0.3, 0.0, 0.0], 1e-3, ALPHA).unwrap_err();
    let GearError::UnequalWorkingCentreDistance { x34_needed, .. } = err else {
        panic!("{err:?}");
    };
    let g = GearSet::shifted([49, 51, 51, 50], [0.2, 0.3, x34_needed, 0.0], 1e-3, ALPHA);
    assert!(g.is_ok(), "{g:?}");
    assert!(err.to_string().contains("x3 + x4"));
    assert_eq!(
        GearSet::shifted([49, 51, 50, 50], [f64::NAN, 0.0, 0.0, 0.0], 1e-3, ALPHA),
        Err(GearError::BadShift { gear: 1 })
    );
    assert_eq!(
        GearSet::shifted([50, 50, 49, 50], [0.1, 0.1, 0.0, 0.0], 1e-3, ALPHA),
        Err(GearError::NoToothDifference)
    );
}

#[test]
fn strength_margin_is_one_for_the_paper_s_gear_at_its_limit() {
    let g = paper::RIG_GEARS;
    assert!((g.strength_margin(paper::TAU_ROT_MAX) - 1.0).abs() < 1e-12);
    assert!((g.strength_margin(paper::TAU_ROT_MAX / 2.0) - 2.0).abs() < 1e-9);
}
