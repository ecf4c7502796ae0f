//! The virtual rig's link: simulation commands, the session's matching and retries, and
//! the device's identity, through the real wire format in virtual time.

use model::plant::Load;
use protocol::{Capabilities, NackCode, Reply, Request, SimCommand};
use sim::scenarios::hello;
use sim::{SimConfig, SimLink, SimRig};

fn link() -> SimLink {
    let mut link = SimLink::new(SimRig::new(SimConfig::paper()));
    hello(&mut link).expect("hello");
    link
}

#[test]
fn set_load_hangs_a_torque_on_the_plants_output() {
    let mut link = link();
    assert_eq!(link.rig.plant().params().load, Load::Torque(0.0));
    let req = Request::Simulation(SimCommand::SetLoad { tau_rot_nm: 1.84 });
    assert_eq!(link.request(&req).unwrap(), Reply::Ack);
    let load = link.rig.plant().params().load;
    assert!((load.torque() - 1.84).abs() < 1e-6, "{load:?}");
    // The gear holds it without vibration (mu_s Lambda = 1.34 > 1): the output stays put.
    link.wait(1.0);
    assert!(link.rig.plant().state().output_angle.abs() < 1e-6);
    // A load that is not a number is refused; the plant keeps the last one.
    let bad = Request::Simulation(SimCommand::SetLoad {
        tau_rot_nm: f32::NAN,
    });
    assert_eq!(
        link.request(&bad).unwrap(),
        Reply::Nack(NackCode::BadArgument)
    );
    assert!((link.rig.plant().params().load.torque() - 1.84).abs() < 1e-6);
}

#[test]
fn supplies_are_recorded_and_acknowledged() {
    let mut link = link();
    for (cmd, ok) in [
        (SimCommand::SetSupplyVoltage { volts: 6.2 }, true),
        (SimCommand::SetSensorSupply { volts: 4.75 }, true),
        (SimCommand::SetSupplyVoltage { volts: -1.0 }, false),
        (
            SimCommand::SetSensorSupply {
                volts: f32::INFINITY,
            },
            false,
        ),
    ] {
        let reply = link.request(&Request::Simulation(cmd)).unwrap();
        assert_eq!(reply == Reply::Ack, ok, "{}: {}", cmd.name(), reply.name());
    }
    let bench = link.rig.bench();
    assert_eq!(bench.supply_v, Some(6.2));
    assert_eq!(bench.sensor_supply_v, Some(4.75));
    assert_eq!(bench.commands, 2);
    // Applied to the plant, not only recorded: the bridge's supply and the ACS714's.
    let plant = link.rig.plant().params();
    assert_eq!(plant.supply, 6.2f32 as f64);
    assert_eq!(plant.sensors.acs_supply, 4.75);
}

#[test]
fn simulation_commands_work_during_a_fault_hold_and_do_not_block_the_firmware() {
    let mut link = link();
    link.wait(1.2);
    // An operator's action is not a motor command: served even with a fault latched.
    link.rig.inject(sim::Injections {
        current_adc_stuck: Some(4095),
        ..Default::default()
    });
    link.wait(0.05);
    assert!(!link.rig.core().status().latched_faults.is_empty());
    let req = Request::Simulation(SimCommand::SetLoad { tau_rot_nm: 0.5 });
    assert_eq!(link.request(&req).unwrap(), Reply::Ack);
    // The firmware's own requests are still refused in the hold.
    assert_eq!(
        link.request(&Request::Heartbeat { session: 0 }).unwrap(),
        Reply::Nack(NackCode::InFaultHold)
    );
}

#[test]
fn the_virtual_rig_says_it_is_a_simulation() {
    let mut link = link();
    let Reply::Info(info) = link.request(&Request::GetInfo).unwrap() else {
        panic!("GetInfo answered otherwise");
    };
    assert!(info.capabilities.contains(Capabilities::SIMULATION));
    assert_eq!(info.protocol_version, protocol::PROTOCOL_VERSION);
}

#[test]
fn replies_are_matched_by_seq_and_stale_ones_counted() {
    let mut link = link();
    for _ in 0..20 {
        assert!(matches!(
            link.request(&Request::GetFaults).unwrap(),
            Reply::Faults { .. }
        ));
        assert!(matches!(
            link.request(&Request::GetInfo).unwrap(),
            Reply::Info(_)
        ));
    }
    let stats = link.stats();
    assert_eq!((stats.stale_replies, stats.retries), (0, 0));
    assert_eq!(stats.frame_errors, 0);
}
