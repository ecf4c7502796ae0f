//! The current model against the paper's model and first principles.

use core::f64::consts::PI;

use super::*;
use crate::{CamDrive, paper};

fn model() -> CurrentModel {
    let drive = CamDrive::paper(paper::RIG_GEARS);
    CurrentModel::paper(drive, paper::CALIBRATION, paper::MU_S)
}

#[test]
fn without_effects_it_is_the_paper_model() {
    let m = model();
    for (w, tau) in [(31.4, 0.368), (62.8, 1.84), (94.2, 3.68)] {
        let op = OperatingPoint::new(w, tau, 12.0);
        let eq10 = m.drive.required_cam_torque(m.mu, tau, w);
        let expected = m.calibration.current_for(eq10, w);
        assert!((m.current(&op) - expected).abs() < 1e-12);
        let mut g = [0.0; PARAM_COUNT];
        assert!((m.current_and_gradient(&op, &mut g) - expected).abs() < 1e-12);
        assert!(m.backdrives(&op));
    }
    // The paper's current range: about 2.3 to 3.7 A.
    let lo = m.current(&OperatingPoint::new(31.4, 0.368, 0.0));
    let hi = m.current(&OperatingPoint::new(94.2, 3.68, 0.0));
    assert!(lo > 2.3 && lo < 2.6 && hi > 3.4 && hi < 3.8, "{lo} {hi}");
}

fn every_effect() -> CurrentModel {
    let mut m = model();
    m.effects = EffectParams {
        axial_corner_speed: 20.0,
        load_exponent: 0.2,
        tooth_compliance: 1e-6,
        rectification: 0.5,
        viscous_loss: 1e-4,
        bush_force: 3.0,
        bush_hold_torque: 0.6,
        bush_corner_speed: 40.0,
        thermal_coeff: 2e-3,
        current_offset: 0.02,
        mesh_ripple_rms: 0.05,
    };
    m
}

#[test]
fn gradient_matches_finite_differences() {
    let m = every_effect();
    let op = OperatingPoint::new(40.0, 2.2, 15.0);
    let mut g = [0.0; PARAM_COUNT];
    let i = m.current_and_gradient(&op, &mut g);
    assert!((i - m.current(&op)).abs() < 1e-12);
    let p = m.params();
    for k in 0..PARAM_COUNT {
        let h = 1e-6 * p[k].abs().max(1e-6);
        let (mut up, mut down) = (m, m);
        let (mut pu, mut pd) = (p, p);
        pu[k] += h;
        pd[k] -= h;
        up.set_params(&pu);
        down.set_params(&pd);
        let fd = (up.current(&op) - down.current(&op)) / (2.0 * h);
        let scale = fd.abs().max(1e-9);
        assert!(
            (g[k] - fd).abs() / scale < 1e-4,
            "param {k}: {} vs {fd}",
            g[k]
        );
    }
}

#[test]
fn evaluator_is_the_same_physics() {
    let m = every_effect();
    let ev = m.evaluator();
    for (w, tau, x) in [(31.4, 0.368, 0.0), (62.8, 1.84, 10.0), (94.2, 3.68, 20.0)] {
        let op = OperatingPoint::new(w, tau, x);
        assert!((ev.current(&op) - m.current(&op)).abs() < 1e-12);
        assert!((ev.friction_current(&op) - m.friction_current(&op)).abs() < 1e-12);
    }
    // Past the compliance limit the friction term vanishes in both.
    let mut soft = m;
    soft.effects.tooth_compliance = 1.0;
    let op = OperatingPoint::new(50.0, 3.0, 0.0);
    assert!((soft.evaluator().current(&op) - soft.current(&op)).abs() < 1e-12);
}

#[test]
fn each_effect_moves_the_current_the_physical_way() {
    let base = model();
    let op_slow = OperatingPoint::new(31.4, 3.0, 20.0);
    let op_fast = OperatingPoint::new(94.2, 3.0, 20.0);
    let with = |f: fn(&mut EffectParams)| {
        let mut m = base;
        f(&mut m.effects);
        m
    };
    // Lower axial friction at low cam speed: less current, mostly at 5 Hz.
    let m = with(|e| e.axial_corner_speed = 20.0);
    let d_slow = base.current(&op_slow) - m.current(&op_slow);
    let d_fast = base.current(&op_fast) - m.current(&op_fast);
    assert!(d_slow > 0.0 && d_slow > 3.0 * d_fast);
    // Inertia rectification grows with w^2: kappa = 1 doubles Eq. 10's inertia term.
    let m = with(|e| e.rectification = 1.0);
    let extra = m.current(&op_fast) - base.current(&op_fast);
    let expected = base.drive.required_inertia_torque(94.2) / base.calibration.c1;
    assert!((extra - expected).abs() < 1e-12);
    // Thermal drift: more current for the same torque when warm.
    let m = with(|e| e.thermal_coeff = 2e-3);
    assert!(m.current(&op_slow) > base.current(&op_slow));
    // Compliance shortens the sliding stroke: less friction current.
    let m = with(|e| e.tooth_compliance = 1e-6);
    assert!(m.current(&op_slow) < base.current(&op_slow));
    // The bush: a constant (2/pi) F e of torque.
    let m = with(|e| e.bush_force = 5.0);
    let extra = (m.current(&op_slow) - base.current(&op_slow)) * base.calibration.c1;
    assert!((extra - 2.0 / PI * 5.0 * 1e-3).abs() < 1e-12);
}

#[test]
fn bush_holds_light_loads_at_low_speed_only() {
    let mut m = model();
    m.effects.bush_hold_torque = 0.8;
    m.effects.bush_corner_speed = 40.0;
    assert!(!m.backdrives(&OperatingPoint::new(31.4, 0.368, 0.0)));
    assert!(m.backdrives(&OperatingPoint::new(94.2, 0.368, 0.0)));
    assert!(m.backdrives(&OperatingPoint::new(31.4, 0.736, 0.0)));
    assert!((bush_holding_torque(0.8, 40.0, 40.0) - 0.4).abs() < 1e-12);
    assert_eq!(bush_holding_torque(0.6, 10.0, 0.0), 0.0);
}

#[test]
fn names_round_trip() {
    for e in Effect::ALL {
        assert_eq!(Effect::from_name(e.name()), Some(e));
    }
    assert_eq!(Effect::from_name("nope"), None);
    assert_eq!(Effect::MeshLoadSharingRipple.mean_param(), None);
}

#[test]
fn every_effect_has_physical_limits_with_reasons_on_its_reported_parameters() {
    let ctx = LimitContext {
        max_axial_force_n: 100.0,
        eccentricity_m: 1e-3,
    };
    for info in EFFECTS {
        assert!(!info.limits.is_empty(), "{} has no limits", info.name);
        for l in info.limits {
            assert!(
                info.param(l.key).is_some(),
                "{}: no parameter {}",
                info.name,
                l.key
            );
            assert!(
                l.why.len() > 40,
                "{}: {} needs its reason",
                info.name,
                l.key
            );
            let (lo, hi) = l.range(&ctx);
            assert!(lo < hi, "{}: {}", info.name, l.key);
        }
    }
    // The cases: kappa beyond fully rectified, a torque constant that rises as the
    // motor warms, teeth that deflect by half the stroke.
    let limit = |e: Effect, key: &str| {
        *e.info()
            .limits
            .iter()
            .find(|l| l.key == key)
            .expect("limit")
    };
    let outside = |l: PhysicalLimit, v: f64| {
        let (lo, hi) = l.range(&ctx);
        v < lo || v > hi
    };
    assert!(outside(limit(Effect::InertiaRectification, "kappa"), 2.4));
    assert!(outside(limit(Effect::ThermalDrift, "k_per_c"), -1e-3));
    // Half the 1 mm stroke at 100 N: 5 um/N.
    assert!(outside(
        limit(Effect::ToothCompliance, "compliance_um_per_n"),
        5.0
    ));
    assert!(!outside(
        limit(Effect::ToothCompliance, "compliance_um_per_n"),
        1.0
    ));
    assert!(outside(MU_PHYSICAL, 0.0002));
}
