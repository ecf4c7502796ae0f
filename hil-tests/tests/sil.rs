//! Software-in-the-loop: the paper's experiments and the fault drills on the simulated rig.

use sim::scenarios::{faults, fig5, sweep, table1};

#[test]
fn fig5_load_held_without_vibration_and_falls_once_released() {
    let r = fig5::run(&fig5::Fig5Options::default()).expect("fig5 runs");
    assert!(r.held_without_vibration, "{r:?}");
    let t = r
        .release_to_motion_s
        .expect("the load moves after the release");
    assert!(t < 0.5, "release to motion {t} s");
    // mu_d Lambda = 0.858 < 1: the load keeps moving after the vibration stops.
    assert!(r.mu_d_lambda < 1.0);
    assert!(
        r.output_speed_after_stop_rad_s > r.output_speed_at_stop_rad_s * 0.99,
        "{r:?}"
    );
    assert!(r.output_speed_after_stop_rad_s > 0.0);
}

#[test]
fn table1_agrees_with_the_paper() {
    let rows = table1::run(&model::paper::TABLE1, 10.0, 3).expect("table1 runs");
    assert_eq!(rows.len(), 6);
    for r in &rows {
        assert_eq!(r.backdriven_without_vibration, r.n >= 2, "{r:?}");
        assert!(r.backdriven_with_vibration, "{r:?}");
        assert!(r.agrees_with_paper);
    }
}

#[test]
fn torque_sweep_current_and_torque_grow_with_load_and_speed() {
    let opts = sweep::SweepOptions {
        loads: vec![
            model::paper::TAU_ROT_MIN_TESTED,
            1.2,
            2.0,
            2.8,
            model::paper::TAU_ROT_MAX,
        ],
        repeats: 2,
        rest_s: 2.0,
        seed: 7,
        ..Default::default()
    };
    let points = sweep::run(&opts).expect("sweep runs");
    assert_eq!(points.len(), 5 * 3 * 2);
    let s = sweep::summarise(&points, &opts);
    assert!(
        s.current_grows_with_load && s.current_grows_with_speed,
        "{s:?}"
    );
    assert!(
        s.tau_cam_grows_with_load && s.tau_cam_grows_with_speed,
        "{s:?}"
    );
    for ((v, hz), want) in s.mean_hz_per_voltage.iter().zip([5.0, 10.0, 15.0]) {
        assert!((hz / want - 1.0).abs() < 0.15, "{v} V: {hz} Hz");
    }
    // The plant follows Eq. (10) (mu_ax = mu_s) up to its rectified-free inertia term.
    assert!(s.rmse_tau_cam_vs_eq10_nm < 0.005, "{s:?}");
    // The firmware's per-revolution estimate matches the logged current's torque.
    assert!(s.rmse_estimate_vs_measured_nm < 0.004, "{s:?}");
    // Temperature and time advance through the session.
    assert!(points.iter().any(|p| p.temp_c > 26.0));
}

#[test]
fn every_fault_drill_ends_safe_and_latched() {
    let outcomes = faults::run(&[], 5).expect("drills run");
    let names: Vec<&str> = outcomes.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, faults::DRILLS);
    for o in &outcomes {
        assert!(o.motor_off, "{o:?}");
        assert!(o.fault_latched, "{o:?}");
        assert!(o.release_refused, "{o:?}");
        let t = o.time_to_safe_s.expect("reached the safe state");
        assert!(t < 1.0, "{o:?}");
    }
}
