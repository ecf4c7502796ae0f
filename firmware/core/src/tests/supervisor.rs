//! Every supervisor transition, closed loop on the plant.

use core::f32::consts::TAU;

use protocol::{
    FaultFlags, NackCode, ParametersStatus, Request, RigParameters, StatusFlags, SupervisorState,
};

use super::{PAPER_Z, Rig};
use crate::BootInfo;

fn release(hz: f32) -> Request {
    Request::Release {
        on: true,
        target_hz: hz,
        session: 0,
    }
}

const STOP: Request = Request::Release {
    on: false,
    target_hz: 0.0,
    session: 0,
};

fn boot_with(calibration: RigParameters) -> BootInfo {
    BootInfo {
        parameters: calibration,
        parameters_status: ParametersStatus::Valid,
        ..BootInfo::default()
    }
}

#[test]
fn boots_locked_and_waits_for_the_current_zero() {
    let mut rig = Rig::new(2.0);
    rig.button = true; // held from power-up: ignored until let go
    // Before the first zero ends there is no measured zero for the overcurrent trip: the
    // binary keeps the trip on it and the bridge off (`measured_current_zero_adc`).
    assert_eq!(rig.core.measured_current_zero_adc(), None);
    let out = rig.step();
    assert!(!out.enable);
    assert!(rig.core.status().zeroing);
    assert_eq!(rig.core.measured_current_zero_adc(), None);
    // A release before the zero exists is refused with the reason, and has no effect.
    assert_eq!(rig.ack(&release(10.0)), Err(NackCode::CurrentZeroPending));
    // Zero takes 1000 samples (100 ms): nothing drives meanwhile, and every release asked
    // for meanwhile is refused.
    let mut steps = 1;
    while rig.core.measured_current_zero_adc().is_none() {
        assert!(!rig.step().enable);
        assert_eq!(rig.state(), SupervisorState::Locked);
        steps += 1;
        assert!(steps <= 120, "the zero took more than 120 steps");
        if rig.core.measured_current_zero_adc().is_none() {
            assert_eq!(rig.ack(&release(10.0)), Err(NackCode::CurrentZeroPending));
        }
    }
    assert!(
        steps >= 99,
        "the zero took {steps} steps, fewer than its 1000 samples"
    );
    let zero = rig.core.measured_current_zero_adc().expect("zero measured");
    // Now the release is accepted: the trip is centred on the measured zero already.
    assert_eq!(rig.ack(&release(10.0)), Ok(()));
    assert!((zero - 2068.0).abs() < 3.0, "{zero}");
    rig.run_ms_alive(5);
    let s = rig.core.status();
    assert!(!s.zeroing && (s.current_zero_adc - 2068.0).abs() < 3.0);
    assert_eq!(s.state, SupervisorState::SpinUp);
}

#[test]
fn host_release_spins_up_vibrates_estimates_and_stops() {
    let load = 2.0;
    let mut rig = Rig::new(load);
    let took = rig.vibrate(10.0);
    // 62.8 rad/s at 60 rad/s^2 is 1.05 s, plus 100 ms at speed.
    assert!((1000..1600).contains(&took), "{took} ms to Vibrating");
    rig.run_ms_alive(1000);
    let s = rig.core.status();
    assert!(((s.cam_speed_rad_s - TAU * 10.0) / (TAU * 10.0)).abs() < 0.03);
    assert!(s.estimate_valid && s.revolutions >= 8);
    assert!(
        (s.tau_rot_nm - load as f32).abs() < 0.15 * load as f32,
        "tau_rot {}",
        s.tau_rot_nm
    );
    assert!(s.flags.contains(StatusFlags::HOST_RELEASE));
    // The output turned while vibrating (the gear was backdriven).
    assert!(rig.plant.state().output_speed > 0.0);

    assert_eq!(rig.ack(&STOP), Ok(()));
    rig.step();
    assert_eq!(rig.state(), SupervisorState::Stopping);
    assert!(!rig.step().enable, "stopping coasts with the bridge off");
    let t = rig
        .run_until(2000, false, |s| s.state == SupervisorState::Locked)
        .unwrap();
    assert!(t < 1000, "{t} ms to come to rest");
    assert!(rig.core.status().cam_speed_rad_s.abs() < 2.0);
    assert!(rig.latched().is_empty(), "a requested stop is no fault");
}

#[test]
fn release_withdrawn_during_spin_up_stops() {
    let mut rig = Rig::new(1.0);
    rig.run_ms(150);
    rig.ack(&release(10.0)).unwrap();
    rig.run_ms_alive(300);
    assert_eq!(rig.state(), SupervisorState::SpinUp);
    assert!(rig.core.status().enabled);
    rig.ack(&STOP).unwrap();
    rig.step();
    assert_eq!(rig.state(), SupervisorState::Stopping);
    assert!(!rig.step().enable);
}

#[test]
fn stopping_goes_back_to_spin_up_when_released_again() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.ack(&STOP).unwrap();
    rig.run_ms(20);
    assert_eq!(rig.state(), SupervisorState::Stopping);
    rig.ack(&release(10.0)).unwrap();
    rig.step();
    assert_eq!(rig.state(), SupervisorState::SpinUp);
    // The loop restarts from the coasting speed, not from zero.
    assert!(rig.core.status().speed_reference_rad_s > 30.0);
    rig.run_until(1000, true, |s| s.state == SupervisorState::Vibrating)
        .unwrap();
}

#[test]
fn a_new_target_while_vibrating_spins_up_again() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.ack(&release(5.0)).unwrap();
    rig.step();
    assert_eq!(rig.state(), SupervisorState::SpinUp);
    rig.run_until(2000, true, |s| s.state == SupervisorState::Vibrating)
        .unwrap();
    rig.run_ms_alive(300);
    let w = rig.core.status().cam_speed_rad_s;
    assert!((w - TAU * 5.0).abs() < 0.05 * TAU * 5.0, "{w}");
}

#[test]
fn button_release_vibrates_while_held() {
    let mut rig = Rig::new(1.0);
    rig.run_ms(150);
    rig.button = true;
    rig.run_until(2000, false, |s| s.state == SupervisorState::Vibrating)
        .unwrap();
    let s = rig.core.status();
    assert!(s.button_release && !s.host_release);
    assert!(s.flags.contains(StatusFlags::BUTTON_RELEASE));
    // No heartbeat needed while the button holds the release.
    rig.run_ms(1500);
    assert_eq!(rig.state(), SupervisorState::Vibrating);
    assert!((rig.core.status().target_hz - 10.0).abs() < 1e-6);
    rig.button = false;
    rig.step();
    assert_eq!(rig.state(), SupervisorState::Stopping);
}

#[test]
fn release_lapses_without_heartbeat() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    // The last heartbeat was at most 150 ms ago; silence for 600 ms.
    let mut stopped_at = None;
    for k in 0..600 {
        let out = rig.step();
        if !out.enable && stopped_at.is_none() {
            stopped_at = Some(k);
        }
    }
    assert!(rig.latched().contains(FaultFlags::COMMS_TIMEOUT));
    assert_eq!(rig.state(), SupervisorState::Fault);
    assert!(!rig.core.status().host_release);
    assert!(stopped_at.unwrap() <= 500);
}

#[test]
fn fault_clears_to_locked_or_stopping() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.run_ms(600); // comms timeout while turning
    assert_eq!(rig.state(), SupervisorState::Fault);
    rig.request(&Request::ClearFaults);
    rig.step();
    // Cleared: the cam may still coast, then it locks. No release is live any more.
    assert!(matches!(
        rig.state(),
        SupervisorState::Locked | SupervisorState::Stopping
    ));
    rig.run_until(2000, false, |s| s.state == SupervisorState::Locked)
        .unwrap();
    rig.run_ms(200);
    assert_eq!(rig.state(), SupervisorState::Locked);
}

#[test]
fn weak_cam_torque_raises_the_frequency_then_cannot_release() {
    // C2 too low by 20 N mm: the measured tau_cam stays ~20 N mm below Eq. (10)'s need.
    let cal = RigParameters {
        c2_nmm: -158.0,
        ..RigParameters::paper()
    };
    let mut rig = Rig::with(boot_with(cal), 0.3, |_| {});
    rig.vibrate(10.0);
    let mut targets = vec![rig.core.status().target_hz];
    for k in 0..8000 {
        if k % 150 == 0 {
            rig.send(&Request::Heartbeat { session: 0 });
        }
        rig.step();
        let s = rig.core.status();
        if *targets.last().unwrap() != s.target_hz {
            targets.push(s.target_hz);
        }
        if s.state == SupervisorState::Fault {
            break;
        }
    }
    // Raised in 2 Hz steps up to the calibration's 15 Hz limit, then the fault.
    assert_eq!(targets, [10.0, 12.0, 14.0, 15.0]);
    assert!(rig.latched().contains(FaultFlags::CANNOT_RELEASE));
}

#[test]
fn spin_up_that_never_reaches_speed_cannot_release() {
    // A 4 V supply cannot turn the cam at 10 Hz (the core believes in 12 V).
    let mut rig = Rig::with(BootInfo::default(), 0.5, |p| p.supply = 4.0);
    rig.run_ms(150);
    rig.ack(&release(10.0)).unwrap();
    let t = rig
        .run_until(4000, true, |s| s.state == SupervisorState::Fault)
        .unwrap();
    assert!((2900..3100).contains(&t), "{t}");
    assert_eq!(rig.latched(), FaultFlags::CANNOT_RELEASE);
}

#[test]
fn load_above_the_gears_strength_is_load_limit() {
    // A stored record from before the caps, asking for 1e30 N m: the cap still holds.
    let cal = RigParameters {
        max_release_load_nm: 1e30,
        max_current_a: 4.8,
        ..RigParameters::paper()
    };
    let mut rig = Rig::with(boot_with(cal), 3.95, |_| {});
    rig.run_ms(150);
    rig.ack(&release(10.0)).unwrap();
    rig.run_until(4000, true, |s| s.state == SupervisorState::Fault)
        .unwrap();
    assert_eq!(
        rig.latched(),
        FaultFlags::LOAD_LIMIT,
        "{:?}",
        rig.core.status()
    );
    assert!(!rig.step().enable);
}

#[test]
fn overload_stops_the_release() {
    let cal = RigParameters {
        max_release_load_nm: 2.0,
        ..RigParameters::paper()
    };
    let mut rig = Rig::with(boot_with(cal), 3.0, |_| {});
    rig.run_ms(150);
    rig.ack(&release(10.0)).unwrap();
    rig.run_until(3000, true, |s| s.state == SupervisorState::Fault)
        .unwrap();
    assert_eq!(rig.latched(), FaultFlags::OVERLOAD);
    assert!(!rig.step().enable);
    // Refused from now on until cleared.
    rig.run_ms(500);
    assert_eq!(
        rig.ack(&release(10.0)),
        Err(protocol::NackCode::InFaultHold)
    );
}

#[test]
fn jam_when_the_cam_torque_is_far_above_expectation() {
    // Eq. (10) at the 1 N m limit is ~14.5 N mm; a 3.5 N m load needs ~51 N mm > 2x.
    let cal = RigParameters {
        max_release_load_nm: 1.0,
        ..RigParameters::paper()
    };
    let mut rig = Rig::with(boot_with(cal), 3.5, |_| {});
    rig.run_ms(150);
    rig.ack(&release(10.0)).unwrap();
    rig.run_until(3000, true, |s| s.state == SupervisorState::Fault)
        .unwrap();
    assert_eq!(rig.latched(), FaultFlags::JAM);
}

#[test]
fn coasting_and_self_locking_flags_follow_the_gear_set() {
    let flags = |z: [u16; 4], mu_d: f32| {
        let cal = RigParameters {
            z,
            mu_d,
            ..RigParameters::paper()
        };
        let rig = Rig::with(boot_with(cal), 0.0, |_| {});
        let s = rig.core.status();
        (s.keeps_moving_after_stop, s.holds_at_rest, s.flags)
    };
    let rig_z = PAPER_Z.map(|z| z as u16);
    let (mu_s, mu_d) = (model::paper::MU_S as f32, model::paper::MU_D as f32);
    // (49, 50): mu_s Lambda = 1.34 holds; mu_d Lambda = 0.86 < 1 keeps moving.
    let (moving, holds, f) = flags(rig_z, mu_d);
    assert!(moving && holds);
    assert!(f.contains(StatusFlags::COASTS_AFTER_STOP));
    assert!(!f.contains(StatusFlags::NOT_SELF_LOCKING));
    // With mu_d = mu_s it stops with the vibration.
    let (moving, _, f) = flags(rig_z, mu_s);
    assert!(!moving && !f.contains(StatusFlags::COASTS_AFTER_STOP));
    // n = 2: never self-locking.
    let (moving, holds, f) = flags(model::paper::TABLE1[2].map(|z| z as u16), mu_d);
    assert!(moving && !holds && f.contains(StatusFlags::NOT_SELF_LOCKING));
}

#[test]
fn load_estimate_tracks_the_plant_across_the_papers_range() {
    let cal = RigParameters {
        max_release_load_nm: 5.0,
        max_freq_hz: 20.0,
        ..RigParameters::paper()
    };
    for (load, hz) in [
        (0.368, 5.0),
        (1.84, 10.0),
        (3.68, 10.0),
        (3.68, 15.0),
        (1.0, 20.0),
    ] {
        let mut rig = Rig::with(boot_with(cal), load, |_| {});
        rig.vibrate(hz);
        rig.run_ms_alive(1500);
        let s = rig.core.status();
        assert!(s.latched_faults.is_empty(), "{}", s.latched_faults);
        // The plant is the paper's model with the calibration's constants: within 2 %.
        let err = (f64::from(s.tau_rot_nm) - load) / load;
        assert!(
            err.abs() < 0.02,
            "{load} N m at {hz} Hz read as {}",
            s.tau_rot_nm
        );
        let w = TAU * hz;
        assert!(
            (s.cam_speed_rad_s - w).abs() < 0.02 * w,
            "{hz} Hz: {}",
            s.cam_speed_rad_s
        );
    }
}

#[test]
fn the_rig_works_across_the_sensor_supply_tolerance() {
    // A ratiometric ACS714 on 4.75 V or 5.25 V: the zero moves by 0.7 A-equivalent (the
    // old +-0.3 A window latched CURRENT_ZERO_RANGE) and the sensitivity by 5 %; the core
    // reads the supply from the zero, so the load estimate stays within 2 %.
    for supply in [4.75, 5.25] {
        let mut rig = Rig::with(BootInfo::default(), 1.84, |p| p.sensors.acs_supply = supply);
        rig.vibrate(10.0);
        rig.run_ms_alive(1500);
        let s = rig.core.status();
        assert!(
            s.latched_faults.is_empty(),
            "{supply} V: {}",
            s.latched_faults
        );
        let err = (f64::from(s.tau_rot_nm) - 1.84) / 1.84;
        assert!(err.abs() < 0.02, "{supply} V: {} N m", s.tau_rot_nm);
    }
}
