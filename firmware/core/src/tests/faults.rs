//! Every fault: how it is detected, that it stops the motor at once, what clears it.

use model::plant::CamSetup;
use protocol::{
    DeviceMessage, FaultFlags, NackCode, ParametersStatus, Reply, Request, RigParameters,
    SupervisorState,
};

use super::Rig;
use crate::{BootInfo, CoreConfig};

/// One ampere in ADC counts (0.185 V/A * 2/3 / 3.3 V * 4095).
const COUNTS_PER_AMP: i32 = 153;

fn faults(rig: &mut Rig, request: &Request) -> (FaultFlags, FaultFlags) {
    let replies = rig.request(request);
    match replies.last() {
        Some(DeviceMessage::Reply {
            reply: Reply::Faults { active, latched },
            ..
        }) => (*active, *latched),
        other => panic!("{request:?} answered {other:?}"),
    }
}

/// Vibrating at 10 Hz, then `inject`; returns the step (ms) at which the bridge went off.
fn inject_while_vibrating(rig: &mut Rig, inject: impl FnOnce(&mut Rig), max_ms: u64) -> u64 {
    rig.vibrate(10.0);
    inject(rig);
    for k in 0..max_ms {
        if k % 150 == 0 {
            rig.send(&Request::Heartbeat { session: 0 });
        }
        let out = rig.step();
        if !out.enable {
            assert_eq!(out.duty, 0.0);
            assert_eq!(rig.state(), SupervisorState::Fault);
            return k + 1;
        }
    }
    panic!("the motor kept running");
}

#[test]
fn overcurrent_needs_threshold_and_duration() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    // 5.0 A-equivalent for 5 ms: too short.
    rig.adc_offset = 5 * COUNTS_PER_AMP;
    rig.run_ms(5);
    rig.adc_offset = 0;
    rig.run_ms(5);
    assert!(rig.latched().is_empty());
    // 10 ms: latched.
    rig.adc_offset = 5 * COUNTS_PER_AMP;
    rig.run_ms(11);
    assert_eq!(rig.latched(), FaultFlags::OVERCURRENT);
    // Still flowing: ClearFaults keeps it.
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert_eq!(
        (active, latched),
        (FaultFlags::OVERCURRENT, FaultFlags::OVERCURRENT)
    );
    rig.adc_offset = 0;
    rig.step();
    let (_, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(latched.is_empty());
}

#[test]
fn overcurrent_while_vibrating_stops_the_motor() {
    let mut rig = Rig::new(1.0);
    let t = inject_while_vibrating(&mut rig, |r| r.adc_offset = 4 * COUNTS_PER_AMP, 100);
    assert!(t <= 12, "{t} ms");
    assert!(rig.latched().contains(FaultFlags::OVERCURRENT));
}

#[test]
fn blocked_cam_trips_overcurrent_first() {
    // Locked rotor at ~0.5 duty: 6 V / 0.44 ohm, far above the 4.5 A limit.
    let mut rig = Rig::new(1.0);
    let t = inject_while_vibrating(&mut rig, |r| r.plant.set_cam(CamSetup::Blocked), 1000);
    assert!(t <= 12, "{t} ms");
    assert_eq!(rig.latched(), FaultFlags::OVERCURRENT);
}

#[test]
fn blocked_cam_is_a_stall() {
    // With the current limits out of the way the stall window catches it.
    let mut config = CoreConfig::default();
    config.faults.overcurrent_a = 50.0;
    let boot = BootInfo {
        parameters: RigParameters {
            max_current_a: 50.0,
            ..RigParameters::paper()
        },
        parameters_status: ParametersStatus::Valid,
        ..BootInfo::default()
    };
    let mut rig = Rig::with_config(config, boot, 1.0, |_| {});
    let t = inject_while_vibrating(&mut rig, |r| r.plant.set_cam(CamSetup::Blocked), 1000);
    assert!((200..=260).contains(&t), "{t} ms");
    assert_eq!(rig.latched(), FaultFlags::STALL);
}

#[test]
fn frozen_encoder_is_encoder_loss() {
    let mut rig = Rig::new(1.0);
    let t = inject_while_vibrating(
        &mut rig,
        |r| r.encoder_frozen = Some(r.plant.encoder_count()),
        1000,
    );
    assert!((200..=260).contains(&t), "{t} ms");
    assert_eq!(rig.latched(), FaultFlags::ENCODER_LOSS);
}

#[test]
fn implausible_current_zero_at_boot_and_rezero() {
    let mut rig = Rig::new(0.0);
    // 2 A-equivalent off Vcc/2: beyond any sensor supply in 4.5-5.5 V (the window is
    // about +-1.7 A wide since the zero follows the ratiometric sensor's supply).
    rig.adc_offset = 2 * COUNTS_PER_AMP;
    rig.run_ms(150);
    assert_eq!(rig.latched(), FaultFlags::CURRENT_ZERO_RANGE);
    rig.run_ms(500);
    // The condition stays until a good zero is measured.
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert_eq!(active, FaultFlags::CURRENT_ZERO_RANGE);
    assert_eq!(latched, FaultFlags::CURRENT_ZERO_RANGE);
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        }),
        Err(NackCode::InFaultHold)
    );
    // A small offset (0.1 A) is within range and gets zeroed out.
    rig.adc_offset = COUNTS_PER_AMP / 10;
    assert_eq!(rig.ack(&Request::RezeroCurrent), Ok(()));
    rig.run_ms(110);
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(active.is_empty() && latched.is_empty());
    assert!(rig.core.status().current_a.abs() < 0.05);
}

#[test]
fn late_step_is_a_control_overrun() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.now_us += 1000; // 2 periods: still on time
    rig.step();
    assert!(rig.latched().is_empty());
    rig.now_us += 2000; // 3 periods since the last step
    rig.step();
    assert_eq!(rig.latched(), FaultFlags::CONTROL_OVERRUN);
    assert_eq!(rig.core.status().control_overruns, 1);
    // An empty sample block (the ADC ring lapped) on time is no overrun.
    rig.now_us += 1000;
    rig.step_with(&[]);
    assert_eq!(rig.core.status().control_overruns, 1);
    let (_, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(latched.is_empty());
}

#[test]
fn invalid_stored_calibration_latches_until_a_valid_one_is_set() {
    let boot = BootInfo {
        parameters_status: ParametersStatus::Invalid,
        ..BootInfo::default()
    };
    let mut rig = Rig::with(boot, 0.0, |_| {});
    rig.run_ms(600);
    assert_eq!(rig.latched(), FaultFlags::CALIBRATION_INVALID);
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert_eq!(active, FaultFlags::CALIBRATION_INVALID);
    assert_eq!(latched, FaultFlags::CALIBRATION_INVALID);
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        }),
        Err(NackCode::InFaultHold)
    );
    // After the hold a calibration may be set; once stored the fault can be cleared.
    rig.send(&Request::SetParameters(RigParameters::paper()));
    rig.step();
    assert!(
        rig.count(|m| matches!(
            m,
            DeviceMessage::Reply {
                reply: Reply::Ack,
                ..
            }
        )) >= 1
    );
    assert_eq!(rig.core.status().parameters_status, ParametersStatus::Valid);
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(active.is_empty() && latched.is_empty());
}

#[test]
fn implausible_boot_values_count_as_invalid() {
    let boot = BootInfo {
        parameters: RigParameters {
            mu_d: 0.5, // above mu_s
            ..RigParameters::paper()
        },
        parameters_status: ParametersStatus::Valid,
        ..BootInfo::default()
    };
    let rig = Rig::with(boot, 0.0, |_| {});
    let s = rig.core.status();
    assert_eq!(s.parameters_status, ParametersStatus::Invalid);
    assert_eq!(s.parameters, RigParameters::paper());
    assert_eq!(s.latched_faults, FaultFlags::CALIBRATION_INVALID);
}

#[test]
fn watchdog_reset_is_reported_and_clearable() {
    let boot = BootInfo {
        reset_cause: protocol::ResetCause::Watchdog,
        ..BootInfo::default()
    };
    let mut rig = Rig::with(boot, 0.0, |_| {});
    rig.step();
    assert_eq!(rig.latched(), FaultFlags::WATCHDOG_RESET);
    assert!(rig.received.iter().any(|m| matches!(
        m,
        DeviceMessage::FaultEvent { flags, .. } if *flags == FaultFlags::WATCHDOG_RESET
    )));
    let (_, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(latched.is_empty());
}

#[test]
fn fault_hold_refuses_commands_for_500_ms() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.adc_offset = 5 * COUNTS_PER_AMP;
    rig.run_ms(12);
    rig.adc_offset = 0;
    rig.step();
    assert!(rig.latched().contains(FaultFlags::OVERCURRENT));
    let events: Vec<_> = rig
        .received
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::FaultEvent {
                flags,
                device_time_us,
            } => Some((*flags, *device_time_us)),
            _ => None,
        })
        .collect();
    assert_eq!(events.len(), 1, "a fault is announced once");
    assert_eq!(events[0].0, FaultFlags::OVERCURRENT);

    for request in [
        Request::Heartbeat { session: 0 },
        Request::GetParameters,
        Request::StartTelemetry { rate_hz: 10 },
        Request::RezeroCurrent,
        Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0,
        },
    ] {
        assert_eq!(rig.ack(&request), Err(NackCode::InFaultHold), "{request:?}");
    }
    // A lock (the safe direction) is never held off.
    assert_eq!(
        rig.ack(&Request::Release {
            on: false,
            target_hz: 0.0,
            session: 0
        }),
        Ok(())
    );
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 0.0,
            session: 0
        }),
        Ok(())
    );
    // Status and clear are always answered.
    assert!(matches!(
        rig.request(&Request::GetInfo)[..],
        [DeviceMessage::Reply {
            reply: Reply::Info(_),
            ..
        }]
    ));
    assert!(matches!(
        rig.request(&Request::GetFaults)[..],
        [DeviceMessage::Reply {
            reply: Reply::Faults { .. },
            ..
        }]
    ));
    let hold_end = events[0].1 + 500_000;
    while rig.now_us < hold_end {
        rig.step();
    }
    assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
    // Still latched: no release until cleared.
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        }),
        Err(NackCode::InFaultHold)
    );
    faults(&mut rig, &Request::ClearFaults);
    assert!(rig.latched().is_empty());
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        }),
        Ok(())
    );
}

#[test]
fn button_must_be_let_go_after_a_fault() {
    let mut rig = Rig::new(0.5);
    rig.run_ms(150);
    rig.button = true;
    rig.run_until(2000, false, |s| s.state == SupervisorState::Vibrating)
        .unwrap();
    rig.now_us += 5000; // an overrun while the button is held
    rig.step();
    assert_eq!(rig.state(), SupervisorState::Fault);
    rig.run_ms(600);
    faults(&mut rig, &Request::ClearFaults);
    rig.run_ms(1000);
    assert!(
        matches!(rig.state(), SupervisorState::Locked),
        "{:?}",
        rig.state()
    );
    rig.button = false;
    rig.step();
    rig.button = true;
    rig.run_until(2000, false, |s| s.state == SupervisorState::SpinUp)
        .unwrap();
}

#[test]
fn reversed_encoder_latches_and_stops() {
    let mut rig = Rig::new(0.0);
    rig.encoder_reversed = true;
    rig.run_ms(150);
    rig.ack(&Request::Release {
        on: true,
        target_hz: 10.0,
        session: 0,
    })
    .unwrap();
    let t = rig.run_until(3000, true, |s| !s.latched_faults.is_empty());
    assert!(t.is_some(), "{:?}", rig.core.status());
    assert_eq!(rig.latched(), FaultFlags::REVERSED_ENCODER);
    assert!(!rig.step().enable);
}

#[test]
fn a_normal_release_never_sees_a_reversed_encoder() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.run_ms_alive(1000);
    assert_eq!(
        rig.ack(&Request::Release {
            on: false,
            target_hz: 10.0,
            session: 0
        }),
        Ok(())
    );
    rig.run_ms(2000);
    assert!(rig.latched().is_empty(), "{}", rig.latched());
}

#[test]
fn hardware_break_latches_hw_overcurrent_until_cleared() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.core.set_board_inputs(crate::BoardInputs {
        hw_break: true,
        ..Default::default()
    });
    assert!(!rig.step().enable, "off at the first step after the break");
    assert!(rig.latched().contains(FaultFlags::HW_OVERCURRENT));
    assert!(rig.core.break_latched());
    // The binary keeps the break until the fault is cleared; the flag itself is a latch
    // in the timer, so clearing works once the current is back to zero.
    rig.core.set_board_inputs(crate::BoardInputs::default());
    rig.run_ms(600);
    let (_, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(!latched.contains(FaultFlags::HW_OVERCURRENT), "{latched}");
    assert!(!rig.core.break_latched());
}

#[test]
fn bus_overvoltage_stops_the_drive_and_holds_while_the_bus_is_high() {
    let limit = model::hardware::board::BUS_OVERVOLTAGE_V as f32;
    let bus = |v: f32| crate::BoardInputs {
        bus_voltage_v: v,
        ..Default::default()
    };
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    // Just under the limit (the feed-forward follows the bus): still driving.
    rig.core.set_board_inputs(bus(limit - 0.1));
    assert!(rig.step().enable);
    assert!(rig.latched().is_empty(), "{}", rig.latched());
    // Over it: off at this step, latched.
    rig.core.set_board_inputs(bus(limit + 0.5));
    assert!(!rig.step().enable, "off at the first step over the limit");
    assert_eq!(rig.latched(), FaultFlags::BUS_OVERVOLTAGE);
    rig.run_ms(600);
    // While the bus stays high the fault cannot be cleared.
    let (active, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(active.contains(FaultFlags::BUS_OVERVOLTAGE), "{active}");
    assert!(latched.contains(FaultFlags::BUS_OVERVOLTAGE), "{latched}");
    assert!(!rig.step().enable);
    // Back to the supply's 12 V: cleared on request.
    rig.core.set_board_inputs(bus(12.0));
    rig.step();
    let (_, latched) = faults(&mut rig, &Request::ClearFaults);
    assert!(latched.is_empty(), "{latched}");
}
