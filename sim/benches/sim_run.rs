//! A 60 s simulated run of the closed loop (firmware core at 1 kHz, ADC at 10 kHz, plant
//! steps at 2 kHz), and the plant alone stepped at 10 kHz with an ADC sample per step: the
//! real-time factor is 60 s divided by the measured time.
//!
//! Measured twice: by wall-clock time (criterion's default), and by the benchmark
//! thread's own CPU time (`sim-cpu`), which a machine shared with other work does not
//! inflate: on a loaded machine the wall clock counts the time the thread waited for a
//! core, the CPU clock only the time it ran. Both print the time per 60 s run.

use std::hint::black_box;

use criterion::measurement::{Measurement, ValueFormatter};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use model::plant::Load;
use sim::scenarios::{hello, release};
use sim::{SimConfig, SimLink, SimRig};

/// The 60 s closed loop of the benchmark: boot, hello, release at 10 Hz under 2 N m.
fn sixty_seconds_closed_loop() -> f64 {
    let config = SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(2.0)).expect("valid gear");
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link).expect("hello");
    release(&mut link, 10.0).expect("release");
    link.wait(60.0);
    link.rig.plant().state().cam_speed
}

fn sixty_seconds_vibrating(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim");
    group.sample_size(10);
    group.bench_function("60 s closed loop, 10 Hz release, 2 N m", |b| {
        b.iter(|| black_box(sixty_seconds_closed_loop()))
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
                black_box(plant.current_adc());
            }
            black_box(plant.state().cam_speed)
        })
    });
    group.finish();
}

/// The benchmark thread's CPU time, ns (`CLOCK_THREAD_CPUTIME_ID`).
struct ThreadCpuTime;

fn thread_cpu_ns() -> u64 {
    let ts = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
    u64::try_from(ts.tv_sec).unwrap_or(0) * 1_000_000_000 + u64::try_from(ts.tv_nsec).unwrap_or(0)
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        thread_cpu_ns()
    }

    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }

    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }

    fn zero(&self) -> u64 {
        0
    }

    fn to_f64(&self, value: &u64) -> f64 {
        *value as f64
    }

    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuMillis
    }
}

/// Formats CPU nanoseconds as CPU milliseconds.
struct CpuMillis;

impl ValueFormatter for CpuMillis {
    fn scale_values(&self, _typical: f64, values: &mut [f64]) -> &'static str {
        values.iter_mut().for_each(|v| *v *= 1e-6);
        "ms (CPU)"
    }

    fn scale_throughputs(
        &self,
        _typical: f64,
        throughput: &Throughput,
        values: &mut [f64],
    ) -> &'static str {
        let n = match *throughput {
            Throughput::Elements(n) | Throughput::Bytes(n) | Throughput::BytesDecimal(n) => n,
            Throughput::Bits(n) => n,
            Throughput::ElementsAndBytes { elements, .. } => elements,
        } as f64;
        values.iter_mut().for_each(|v| *v = n / (*v * 1e-9));
        "per CPU second"
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

fn sixty_seconds_cpu(c: &mut Criterion<ThreadCpuTime>) {
    let mut group = c.benchmark_group("sim-cpu");
    group.sample_size(10);
    group.bench_function("60 s closed loop, 10 Hz release, 2 N m", |b| {
        b.iter(|| black_box(sixty_seconds_closed_loop()))
    });
    group.finish();
}

criterion_group!(benches, sixty_seconds_vibrating);
criterion_group! {
    name = cpu;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = sixty_seconds_cpu
}
criterion_main!(benches, cpu);
