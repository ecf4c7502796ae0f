//! Cost of one control step ([`Core::step`]) on the host, in its two regimes: locked
//! (sensors, faults, supervisor) and vibrating at 10 Hz (plus the speed loop, the
//! revolution estimator and 1 kHz telemetry).
//!
//! `cargo bench -p firmware-core --bench control_step`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use firmware_core::{BootInfo, Core, CoreConfig, Inputs};
use protocol::{MAX_FRAME_SIZE, Request, SupervisorState, encode_frame};

/// 1 ms of ADC samples around 2.8 A (2068 counts is zero, 153 counts per ampere): at
/// 10 Hz a cam torque of ~20 N mm, a load of ~1.4 N m.
const RUNNING: [u16; 10] = [2495, 2500, 2505, 2502, 2496, 2491, 2485, 2488, 2493, 2497];
/// 1 ms of ADC samples at zero current.
const AT_REST: [u16; 10] = [2066, 2069, 2070, 2068, 2067, 2065, 2068, 2071, 2069, 2067];
/// Encoder counts per 1 ms at 10 Hz (8192 counts per turn).
const COUNTS_PER_MS: u64 = 82;

struct Bench {
    core: Core,
    now_us: u64,
    position: u64,
    sink: [u8; 512],
}

impl Bench {
    fn new(vibrating: bool) -> Self {
        let mut b = Self {
            core: Core::new(CoreConfig::default(), BootInfo::default()),
            now_us: 0,
            position: 0,
            sink: [0; 512],
        };
        let mut frame = [0u8; MAX_FRAME_SIZE];
        let telemetry = encode_frame(0, &Request::StartTelemetry { rate_hz: 1000 }, &mut frame)
            .unwrap()
            .to_vec();
        b.core.receive(0, &telemetry);
        // Boot (zero), then hold the release button and turn the cam at 10 Hz.
        for k in 0..3000 {
            b.step(vibrating && k > 200);
        }
        let expected = if vibrating {
            SupervisorState::Vibrating
        } else {
            SupervisorState::Locked
        };
        assert_eq!(b.core.status().state, expected);
        b
    }

    fn step(&mut self, turning: bool) {
        self.now_us += 1000;
        if turning {
            self.position += COUNTS_PER_MS;
        }
        let out = self.core.step(&Inputs {
            now_us: self.now_us,
            current_adc: if turning { &RUNNING } else { &AT_REST },
            encoder_count: self.position as u16,
            release_button: turning,
        });
        black_box(out);
        while self.core.transmit(&mut self.sink) > 0 {}
    }
}

fn control_step(c: &mut Criterion) {
    let mut locked = Bench::new(false);
    c.bench_function("core_step_locked", |b| b.iter(|| locked.step(false)));
    let mut vibrating = Bench::new(true);
    c.bench_function("core_step_vibrating_10hz_telemetry_1khz", |b| {
        b.iter(|| vibrating.step(true))
    });
    assert_eq!(
        vibrating.core.status().latched_faults,
        protocol::FaultFlags::empty()
    );
}

criterion_group!(benches, control_step);
criterion_main!(benches);
