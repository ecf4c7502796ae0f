//! A 60 s simulated run of the closed loop (firmware core at 1 kHz, plant at 10 kHz):
//! the real-time factor is 60 s divided by the measured time.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use model::plant::Load;
use sim::scenarios::{hello, release};
use sim::{SimConfig, SimLink, SimRig};

fn sixty_seconds_vibrating(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim");
    group.sample_size(10);
    group.bench_function("60 s closed loop, 10 Hz release, 2 N m", |b| {
        b.iter(|| {
            let config =
                SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(2.0)).expect("valid gear");
            let mut link = SimLink::new(SimRig::new(config));
            hello(&mut link).expect("hello");
            release(&mut link, 10.0).expect("release");
            link.wait(60.0);
            black_box(link.rig.plant().state().cam_speed)
        })
    });
    group.bench_function("60 s plant alone at 10 kHz", |b| {
        b.iter(|| {
            let config =
                SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(2.0)).expect("valid gear");
            let mut plant = model::plant::Plant::new(config.plant, 1);
            let drive = model::plant::Drive {
                duty: 6.2 / 12.0,
                enabled: true,
            };
            for _ in 0..600_000 {
                plant.step(1e-4, drive);
            }
            black_box(plant.state().cam_speed)
        })
    });
    group.finish();
}

criterion_group!(benches, sixty_seconds_vibrating);
criterion_main!(benches);
