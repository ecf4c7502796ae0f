//! Encode and deframe throughput for the two frames that dominate the link.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use heapless::Vec;
use protocol::{
    CAPTURE_CHUNK_SAMPLES, CaptureChunk, CaptureSample, DeviceDeframer, DeviceMessage, FaultFlags,
    MAX_FRAME_SIZE, StatusFlags, SupervisorState, TelemetrySample, encode_frame,
};

fn telemetry() -> DeviceMessage {
    DeviceMessage::Telemetry(TelemetrySample {
        seq: 123_456,
        device_time_us: 987_654_321,
        cam_speed_rad_s: 62.8,
        current_a: 2.5,
        pwm_duty: 0.4,
        tau_cam_nm: 0.02,
        tau_rot_nm: 1.5,
        state: SupervisorState::Vibrating,
        faults: FaultFlags::empty(),
        status: StatusFlags::HOST_RELEASE,
        output_angle_rad: 0.31,
        output_speed_rad_s: 0.0,
    })
}

fn chunk() -> DeviceMessage {
    let samples = (0..CAPTURE_CHUNK_SAMPLES as i32)
        .map(|i| CaptureSample {
            current_adc: 2048 + i as u16,
            encoder_count: i * 7,
            output_count: Some(-i * 3),
        })
        .collect::<Vec<_, CAPTURE_CHUNK_SAMPLES>>();
    DeviceMessage::CaptureChunk(CaptureChunk {
        capture_id: 1,
        first_sample: 4096,
        total_samples: 10_000,
        samples,
    })
}

fn bench(c: &mut Criterion) {
    for (name, msg) in [("telemetry", telemetry()), ("capture_chunk", chunk())] {
        let mut buf = [0u8; MAX_FRAME_SIZE];
        let frame = encode_frame(1, &msg, &mut buf).unwrap().to_vec();
        let mut group = c.benchmark_group(name);
        group.throughput(Throughput::Bytes(frame.len() as u64));
        group.bench_function("encode", |b| {
            b.iter(|| encode_frame(1, black_box(&msg), &mut buf).map(|f| f.len()))
        });
        let mut deframer = DeviceDeframer::new();
        group.bench_function("deframe", |b| {
            b.iter(|| {
                let mut n = 0;
                deframer.push(black_box(&frame), |r| n += r.is_ok() as u32);
                n
            })
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
