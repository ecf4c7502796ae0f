//! The optional output-shaft encoder on the virtual rig: the plant's output angle through
//! the encoder's resolution into the firmware core, backdrive detection, and the
//! output-overspeed fault that stops vibrating.

use firmware_core::OutputEncoderConfig;
use model::plant::Load;
use protocol::{Capabilities, FaultFlags};
use sim::{SimConfig, SimRig};

fn rig(encoder: Option<OutputEncoderConfig>) -> SimRig {
    let mut config = SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(0.736)).unwrap();
    config.core.output_encoder = encoder;
    SimRig::new(config)
}

#[test]
fn the_output_encoder_sees_backdrive_once_released() {
    let mut r = rig(Some(OutputEncoderConfig::default()));
    r.advance(2.0);
    assert_eq!(
        r.core().output_motion().map(|m| m.0),
        Some(0.0),
        "held at rest"
    );
    assert!(!r.core().output_moving());
    // The release button: the load falls.
    r.set_button(true);
    r.advance(3.0);
    let (angle, speed) = r.core().output_motion().unwrap();
    let plant = r.plant().state();
    let resolution = std::f64::consts::TAU / 8192.0;
    assert!(
        (f64::from(angle) - plant.output_angle).abs() < 2.0 * resolution,
        "{angle} vs {}",
        plant.output_angle
    );
    assert!(speed.abs() > 0.01 && r.core().output_moving(), "{speed}");
    assert!(r.core().status().latched_faults.is_empty());
}

#[test]
fn without_the_encoder_nothing_is_reported() {
    let mut r = rig(None);
    r.advance(2.0);
    r.set_button(true);
    r.advance(2.0);
    assert_eq!(r.core().output_motion(), None);
    assert!(!r.core().output_moving());
}

#[test]
fn output_overspeed_latches_and_stops_vibrating() {
    let limit = OutputEncoderConfig {
        overspeed_rad_s: 0.05,
        ..OutputEncoderConfig::default()
    };
    let mut r = rig(Some(limit));
    assert!(
        r.core()
            .config()
            .capabilities
            .contains(Capabilities::OUTPUT_ENCODER)
    );
    r.advance(2.0);
    r.set_button(true);
    r.advance(3.0);
    let status = r.core().status();
    assert!(
        status.latched_faults.contains(FaultFlags::OUTPUT_OVERSPEED),
        "{}",
        status.latched_faults
    );
    assert!(!r.drive().enabled, "the bridge is off");
}
