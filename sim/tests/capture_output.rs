//! `StartCapture` on the virtual rig records the output encoder: during a release the
//! capture's output counts follow the plant's own output shaft, read once per control
//! step and held over that step's samples; a held output gives a constant count.

use firmware_core::OutputEncoderConfig;
use model::plant::Load;
use protocol::{CaptureSample, Request, session::Event};
use sim::scenarios::{hello, release};
use sim::{SimConfig, SimLink, SimRig};

/// Output-encoder counts per revolution (the AMT102-V at 2048 pulses, x4).
const CPR: f64 = 8192.0;

fn link() -> SimLink {
    let mut config = SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(0.736)).unwrap();
    config.core.output_encoder = Some(OutputEncoderConfig::default());
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link).unwrap();
    link
}

/// The plant's output angle as the encoder counts it, unwrapped.
fn plant_counts(link: &SimLink) -> i64 {
    (link.rig.plant().state().output_angle / std::f64::consts::TAU * CPR).round() as i64
}

/// Sends `StartCapture` without waiting for its reply, then steps the rig one control
/// period at a time until the upload is done, recording the plant's output count after
/// every step (the value the core read at that step). Returns the samples and the trace.
fn capture(link: &mut SimLink, samples: u32) -> (Vec<CaptureSample>, Vec<i64>) {
    let request = Request::StartCapture {
        sample_rate_hz: 10_000,
        samples,
    };
    let frame = protocol::encode_frame_vec(60_000, &request).unwrap();
    link.rig.to_device(&frame);
    let mut trace = Vec::new();
    let mut got = Vec::new();
    for _ in 0..20_000 {
        link.wait(0.001);
        trace.push(plant_counts(link));
        let mut done = false;
        for e in link.events.drain(..) {
            match e {
                Event::CaptureChunk(c) => {
                    assert_eq!(c.first_sample as usize, got.len(), "no gaps");
                    got.extend(c.samples);
                }
                Event::CaptureDone { .. } => done = true,
                _ => {}
            }
        }
        if done {
            assert_eq!(got.len(), samples as usize);
            return (got, trace);
        }
    }
    panic!("the capture never finished ({} samples)", got.len());
}

#[test]
fn a_capture_during_a_release_follows_the_plants_output_shaft() {
    let mut link = link();
    link.request(&Request::StartTelemetry { rate_hz: 50 })
        .unwrap();
    release(&mut link, 10.0).unwrap();
    // Let the load start to fall (the paper's Fig. 5: about 1 rad/s once vibrating).
    link.wait(2.0);
    let (samples, trace) = capture(&mut link, 10_000);
    // One reading per control step, held over its ten samples.
    let per_step: Vec<i32> = samples
        .chunks(10)
        .map(|step| {
            assert!(step.iter().all(|s| s.output_count == step[0].output_count));
            step[0].output_count.expect("an output encoder is fitted")
        })
        .collect();
    assert_eq!(per_step.len(), 1000);
    assert_eq!(per_step[0], 0, "counted from the capture's start");
    // The capture starts within the first few steps after the request; find that step
    // and require every reading to be the plant's own count at its step.
    let start = (0..10)
        .find(|&k0| {
            per_step
                .iter()
                .enumerate()
                .all(|(j, &c)| i64::from(c) == trace[k0 + j] - trace[k0])
        })
        .unwrap_or_else(|| panic!("no start step matches: {:?}", &per_step[..20]));
    // And the output did move: more than 0.3 rad over the second (the falling load).
    let turned = f64::from(*per_step.last().unwrap()) / CPR * std::f64::consts::TAU;
    assert!(turned.abs() > 0.3, "{turned} rad from step {start}");
    let plant_turned = (trace[start + 999] - trace[start]) as f64 / CPR * std::f64::consts::TAU;
    assert!((turned - plant_turned).abs() < 1e-12);
}

#[test]
fn a_held_output_gives_a_constant_count() {
    let mut link = link();
    // No release: the paper's gear (mu_s Lambda = 1.336) holds the 0.736 N m load.
    link.wait(1.0);
    let before = link.rig.plant().state().output_angle;
    let (samples, _) = capture(&mut link, 2000);
    assert!(samples.iter().all(|s| s.output_count == Some(0)));
    assert_eq!(link.rig.plant().state().output_angle, before, "held still");
}

#[test]
fn without_an_output_encoder_the_samples_carry_none() {
    let mut config = SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(0.736)).unwrap();
    config.core.output_encoder = None;
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link).unwrap();
    let (samples, _) = capture(&mut link, 500);
    assert!(samples.iter().all(|s| s.output_count.is_none()));
}
