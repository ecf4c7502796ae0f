//! The hardware overcurrent trip on the virtual rig: it latches `HW_OVERCURRENT`, stays
//! latched while its cause is there, and clears with `ClearFaults` once the cause is gone
//! (the break is re-armed before the core reads the next step's inputs).

use model::plant::CamSetup;
use protocol::{FaultFlags, Reply, Request};
use sim::scenarios::{hello, release};
use sim::{SimConfig, SimLink, SimRig};

fn faults(link: &mut SimLink, req: &Request) -> (FaultFlags, FaultFlags) {
    match link.request(req).unwrap() {
        Reply::Faults { active, latched } => (active, latched),
        other => panic!("{other:?}"),
    }
}

#[test]
fn hw_overcurrent_clears_once_its_cause_is_gone() {
    let mut link = SimLink::new(SimRig::new(SimConfig::paper()));
    hello(&mut link).unwrap();
    release(&mut link, 10.0).unwrap();
    link.wait(1.5);
    // The cam jams while driven: the comparator trips the break.
    link.rig.plant_mut().set_cam(CamSetup::Blocked);
    link.wait(0.2);
    let (_, latched) = faults(&mut link, &Request::GetFaults);
    assert!(latched.contains(FaultFlags::HW_OVERCURRENT), "{latched}");
    link.keep_alive(None);
    assert_eq!(
        link.request(&Request::Release {
            on: false,
            target_hz: 0.0,
            session: 0
        })
        .ok(),
        Some(Reply::Ack)
    );
    // The cause goes: the cam turns freely again.
    link.rig.plant_mut().set_cam(CamSetup::Coupled);
    link.wait(0.6);
    let (_, latched) = faults(&mut link, &Request::ClearFaults);
    assert!(latched.is_empty(), "{latched}");
    // And it stays cleared: the break was re-armed before the next step read it.
    link.wait(0.7);
    let (_, latched) = faults(&mut link, &Request::GetFaults);
    assert!(latched.is_empty(), "{latched}");
    assert!(!link.rig.plant().break_tripped());
    // The rig releases again.
    release(&mut link, 10.0).unwrap();
    link.wait(1.0);
    assert!(link.rig.bridge_on());
    let (_, latched) = faults(&mut link, &Request::GetFaults);
    assert!(latched.is_empty(), "{latched}");
}
