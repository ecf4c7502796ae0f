//! Software-in-the-loop: the paper's experiments and the fault drills on the simulated rig.
//! Fig. 5, Table 1 and the torque sweep run the procedures of `rig experiment`
//! (`host::experiment`) on the in-process virtual rig: one implementation with `rig sim` and
//! `rig demo`.

use host::experiment::paper;
use sim::scenarios::{faults, fig5, sweep};

/// Fig. 5 on both presets: the paper's rig and the paper's equations alone.
#[test]
fn fig5_load_held_without_vibration_and_falls_once_released() {
    for preset in [sim::Preset::paper(), sim::Preset::ideal()] {
        let r = paper::fig5(&fig5::Fig5Options {
            effects: preset.effects,
            ..Default::default()
        })
        .expect("fig5 runs");
        let name = preset.name;
        assert!(r.held_without_vibration, "{name}: {r:?}");
        let t = r
            .release_to_motion_s
            .expect("the load moves after the release");
        // The equations alone: the load moves as the cam starts; the paper's rig: its
        // linear bush holds until the cam is nearly up to speed.
        let within = if name == "ideal" { 0.5 } else { 1.0 };
        assert!(t < within, "{name}: release to motion {t} s");
        // mu_d Lambda = 0.858 < 1: the load keeps moving after the vibration stops.
        assert!(r.mu_d_lambda < 1.0);
        assert!(
            r.output_speed_after_stop_rad_s > r.output_speed_at_stop_rad_s * 0.99,
            "{name}: {r:?}"
        );
        assert!(r.output_speed_after_stop_rad_s > 0.0, "{name}: {r:?}");
    }
}

/// Table 1 on both presets.
#[test]
fn table1_agrees_with_the_paper() {
    for preset in [sim::Preset::paper(), sim::Preset::ideal()] {
        let rows =
            paper::table1(&model::paper::TABLE1, 10.0, 3, preset.effects).expect("table1 runs");
        assert_eq!(rows.len(), 6);
        for r in &rows {
            assert_eq!(
                r.backdriven_without_vibration,
                r.n >= 2,
                "{}: {r:?}",
                preset.name
            );
            assert!(r.backdriven_with_vibration, "{}: {r:?}", preset.name);
            assert!(r.agrees_with_paper);
        }
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
        // The paper's equations alone: this test checks the plant against Eq. (10).
        effects: sim::Preset::ideal().effects,
        ..Default::default()
    };
    // The paper preset (the default) keeps the trends of Figs. 8-9.
    let paper_opts = sweep::SweepOptions {
        effects: sim::Preset::paper().effects,
        ..opts.clone()
    };
    let paper = sweep::summarise(
        &paper::torque_sweep(&paper_opts).expect("sweep runs"),
        &paper_opts,
    );
    assert!(
        paper.current_grows_with_load
            && paper.current_grows_with_speed
            && paper.tau_cam_grows_with_load
            && paper.tau_cam_grows_with_speed,
        "{paper:?}"
    );
    let points = paper::torque_sweep(&opts).expect("sweep runs");
    assert_eq!(points.len(), 5 * 3 * 2);
    let s = sweep::summarise(&points, &opts);
    assert!(
        s.current_grows_with_load && s.current_grows_with_speed,
        "{s:?}"
    );
    assert!(s.tau_cam_grows_with_load, "{s:?}");
    // Eq. (10)'s speed dependence is its inertia term, which a drive that takes power back
    // (the G2's braking decay, `model::hardware::board::DECAY`) returns over each turn: then
    // the ideal plant's tau_cam is flat in speed, and only a drive that cannot take it back
    // (the paper's bench supply) makes it grow.
    let returned = model::hardware::board::REGENERATIVE_DECAY;
    if !returned {
        assert!(s.tau_cam_grows_with_speed, "{s:?}");
    }
    for ((v, hz), want) in s.mean_hz_per_voltage.iter().zip([5.0, 10.0, 15.0]) {
        assert!((hz / want - 1.0).abs() < 0.15, "{v} V: {hz} Hz");
    }
    // The plant follows Eq. (10) (mu_ax = mu_s) with the drive's share of its inertia
    // term: kappa = -1 (all of it returned) or -1/2 (rectified).
    let drive = model::CamDrive::paper(model::GearSet::paper(model::paper::RIG_Z).unwrap());
    let kappa = model::effects::drive_kappa(returned);
    let rms = (points
        .iter()
        .map(|p| {
            let want = p.tau_cam_eq10.unwrap() + kappa * drive.required_inertia_torque(p.omega_n);
            (p.tau_cam_meas.unwrap() - want).powi(2)
        })
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    assert!(rms < 0.005, "{rms} N m: {s:?}");
    // The firmware's per-revolution estimate matches the logged current's torque.
    assert!(s.rmse_estimate_vs_measured_nm < 0.004, "{s:?}");
    // Temperature and time advance through the session.
    assert!(points.iter().any(|p| p.temp_c.unwrap() > 26.0));
}

#[test]
fn every_fault_drill_ends_safe_and_latched() {
    let outcomes = faults::run(&[], 5).expect("drills run");
    let names: Vec<&str> = outcomes.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, faults::DRILLS);
    for o in &outcomes {
        assert!(o.motor_off, "{o:?}");
        // A debug halt latches nothing (the core is halted): the IWDG's reset is the safe
        // state. Every drill keeps the current inside the sensor's range.
        assert!(o.fault_latched || o.name == "debug-halt", "{o:?}");
        assert!(o.ends_safe(), "{o:?}");
        assert!(o.release_refused, "{o:?}");
        let t = o.time_to_safe_s.expect("reached the safe state");
        assert!(t < 1.0, "{o:?}");
    }
    let row = |name: &str| outcomes.iter().find(|o| o.name == name).unwrap();
    // The comparator's break, not the 10 ms software check: within 1 ms.
    let oc = row("overcurrent");
    assert!(oc.time_to_safe_s.unwrap() <= 0.001, "{oc:?}");
    assert!(oc.faults.iter().any(|f| f == "HW_OVERCURRENT"), "{oc:?}");
    assert_eq!(row("reversed-encoder").faults, ["REVERSED_ENCODER"]);
    assert_eq!(row("load-limit").faults, ["LOAD_LIMIT"]);
    // The braking bridge pumped the bus past the bridge's limit: the drive stopped.
    assert_eq!(row("overvoltage").faults, ["BUS_OVERVOLTAGE"]);
}

#[test]
fn a_release_cycle_survives_noise_bytes_between_frames() {
    // Random bytes between frames, both ways, during a whole release cycle: each costs at
    // most a counted garbled run (every frame opens with a delimiter), never a request, so
    // heartbeats keep arriving and the release completes without a fault. (Before
    // protocol v2, about ten noise bytes a second made a release fail.)
    use sim::riglink as scenario;
    use sim::{LineNoise, SimConfig, SimLink, SimRig};
    for bytes_per_s in [10.0, 50.0] {
        let mut link = SimLink::new(SimRig::new(SimConfig::paper()));
        link.set_line_noise(Some(LineNoise {
            bytes_per_s,
            seed: 9,
        }));
        link.wait(1.2); // the current-sensor zero is measured at boot
        let r = scenario::release_cycle(&mut link, 10.0, 3.0).expect("release cycle runs");
        assert!(r.to_vibrating_s.is_some(), "{bytes_per_s}/s: {r:?}");
        assert!(r.to_locked_s.is_some(), "{bytes_per_s}/s: {r:?}");
        assert_eq!(
            r.latched,
            protocol::FaultFlags::empty().to_string(),
            "{bytes_per_s}/s: {r:?}"
        );
        // The noise was there and was seen on both sides.
        let seconds = link.rig.time();
        let noise = link.noise_bytes() as f64 / 2.0 / seconds;
        assert!(
            (0.7 * bytes_per_s..1.3 * bytes_per_s).contains(&noise),
            "{noise} bytes/s"
        );
        let host = link.stats();
        assert!(host.frame_errors > 0, "{host:?}");
        let device = link.rig.core().status().deframer;
        assert!(device.errors() > 0, "{device:?}");
        // Nothing was lost that mattered: no request went unanswered.
        assert_eq!(host.frames_lost, 0, "{host:?}");
    }
}

#[test]
fn fig5_and_the_sweep_work_across_the_sensor_supply_tolerance() {
    // A ratiometric ACS714 on 4.75 or 5.25 V: no fault (the zero window is sized from the
    // 4.5-5.5 V supply) and the same estimate quality as at 5.0 V.
    for sensor_supply_v in [4.75, 5.25] {
        let r = paper::fig5(&fig5::Fig5Options {
            hold_s: 2.0,
            sensor_supply_v,
            ..Default::default()
        })
        .expect("fig5 runs without a fault");
        assert!(
            r.release_to_motion_s.is_some(),
            "{sensor_supply_v} V: {r:?}"
        );
        let opts = sweep::SweepOptions {
            loads: vec![0.368, 3.68],
            voltages: vec![6.2],
            repeats: 1,
            rest_s: 0.0,
            sensor_supply_v,
            ..Default::default()
        };
        let points = paper::torque_sweep(&opts).expect("the sweep runs without a fault");
        let s = sweep::summarise(&points, &opts);
        assert!(
            s.rmse_estimate_vs_measured_nm < 0.0015,
            "{sensor_supply_v} V: {s:?}"
        );
    }
}
