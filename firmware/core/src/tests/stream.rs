//! The continuous stream through the wire: rates, exact samples at a UART's pace, and
//! every way it stops.

use protocol::{
    DeviceMessage, NackCode, Request, STREAM_BLOCK_SAMPLES, STREAM_DUTY_SCALE, StreamDecoder,
    StreamEvent, StreamSample, SupervisorState,
};

use super::Rig;

/// Bytes a 921,600 Bd UART moves in one 1 ms step (10 bits a byte).
const UART_BYTES_PER_MS: usize = 92;

fn blocks(rig: &Rig) -> usize {
    rig.count(|m| matches!(m, DeviceMessage::StreamBlock(_)))
}

/// Samples with their numbers, and lost runs as (first, count).
type Decoded = (Vec<(u32, StreamSample)>, Vec<(u32, u32)>);

/// Decodes every stream block received so far: the samples and the lost events.
fn decode(rig: &Rig) -> Decoded {
    let mut decoder = StreamDecoder::new();
    let (mut samples, mut lost) = (Vec::new(), Vec::new());
    for m in &rig.received {
        if let DeviceMessage::StreamBlock(b) = m {
            decoder.push(b, |e| match e {
                StreamEvent::Sample { seq, sample } => samples.push((seq, sample)),
                StreamEvent::Lost { first_seq, count } => lost.push((first_seq, count)),
            });
        }
    }
    (samples, lost)
}

#[test]
fn rates_are_10_khz_divided_by_a_whole_number_or_refused_naming_the_rate_that_fits() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    assert_eq!(
        rig.ack(&Request::StartStream { rate_hz: 0 }),
        Err(NackCode::BadArgument)
    );
    for (asked, fits) in [
        (3_000, 2_500),
        (9_999, 5_000),
        (10_001, 10_000),
        (u16::MAX, 10_000),
        (999, 625),
    ] {
        assert_eq!(
            rig.ack(&Request::StartStream { rate_hz: asked }),
            Err(NackCode::StreamRate { fits_hz: fits }),
            "{asked}"
        );
    }
    // A refused request had no effect.
    rig.run_ms(20);
    assert_eq!(blocks(&rig), 0);
    assert_eq!(rig.core.status().stream_rate_hz, 0);
    for (rate, blocks_in_100_ms) in [(10_000u16, 100usize), (2_500, 25), (1_000, 10), (100, 1)] {
        rig.ack(&Request::StartStream { rate_hz: rate }).unwrap();
        assert_eq!(rig.core.status().stream_rate_hz, rate);
        let before = blocks(&rig);
        rig.run_ms(100);
        assert_eq!(blocks(&rig) - before, blocks_in_100_ms, "{rate} Hz");
    }
    rig.ack(&Request::StopStream).unwrap();
}

#[test]
fn every_adc_sample_arrives_exact_at_a_uarts_pace() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.link_budget = Some(UART_BYTES_PER_MS);
    rig.send(&Request::StartStream { rate_hz: 10_000 });
    // One second of known ADC codes, ten a step.
    let code = |n: u32| 1_800 + (n * 7 % 400) as u16;
    for k in 0..1_000u32 {
        if k % 150 == 0 {
            rig.send(&Request::Heartbeat { session: 0 });
        }
        rig.now_us += 1_000;
        let adc: Vec<u16> = (0..10).map(|j| code(10 * k + j)).collect();
        rig.step_with(&adc);
    }
    for _ in 0..10 {
        rig.pump();
    }
    let (samples, lost) = decode(&rig);
    assert!(lost.is_empty(), "{lost:?}");
    assert_eq!(samples.len(), 10_000);
    for (seq, s) in &samples {
        assert_eq!(s.current_adc, code(*seq), "sample {seq}");
        assert_eq!(s.state, SupervisorState::Locked as u8);
    }
    assert_eq!(rig.core.status().stream_samples_skipped, 0);
    assert_eq!(rig.core.status().tx_dropped, 0);
}

#[test]
fn a_vibrating_cam_streams_its_steps_at_10_khz_without_loss() {
    let mut rig = Rig::new(0.5);
    rig.vibrate(10.0);
    rig.link_budget = Some(UART_BYTES_PER_MS);
    rig.send(&Request::StartStream { rate_hz: 10_000 });
    rig.run_ms_alive(1_000);
    let (samples, lost) = decode(&rig);
    assert!(lost.is_empty(), "{lost:?}");
    // 1,000 steps (the last block may still wait in the queue).
    assert!(samples.len() >= 9_990, "{}", samples.len());
    assert_eq!(samples.len() % STREAM_BLOCK_SAMPLES, 0);
    let last = samples.last().unwrap().1;
    assert_eq!(last.state, SupervisorState::Vibrating as u8);
    assert!(last.duty != 0 && last.duty.unsigned_abs() <= STREAM_DUTY_SCALE as u16);
    // 10 Hz on 8,192 counts a turn: ~8 counts a sample, the cam moving every sample.
    let steps: Vec<i16> = samples
        .windows(2)
        .map(|w| {
            w[1].1
                .cam_count
                .wrapping_sub(w[0].1.cam_count)
                .cast_signed()
        })
        .collect();
    let mean = steps.iter().map(|&d| f64::from(d)).sum::<f64>() / steps.len() as f64;
    assert!((6.0..10.0).contains(&mean.abs()), "{mean}");
    assert!(rig.core.status().tau_cam_nm != 0.0);
}

#[test]
fn a_link_that_falls_behind_loses_whole_numbered_samples_never_wrong_ones() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.link_budget = Some(UART_BYTES_PER_MS);
    rig.send(&Request::StartStream { rate_hz: 10_000 });
    rig.run_ms(100);
    // The link stalls for 20 ms, then resumes.
    rig.link_budget = Some(0);
    rig.run_ms(20);
    rig.link_budget = Some(UART_BYTES_PER_MS);
    rig.run_ms(100);
    let (samples, lost) = decode(&rig);
    let lost_count: u32 = lost.iter().map(|l| l.1).sum();
    assert!(!lost.is_empty());
    // At 10 kHz each skipped ADC sample is a stream sample, plus at most the block that
    // was being filled when the ring overflowed.
    let skipped = rig.core.status().stream_samples_skipped;
    assert!(skipped > 0);
    assert!(
        (skipped..skipped + STREAM_BLOCK_SAMPLES as u32).contains(&lost_count),
        "{lost_count} lost, {skipped} skipped"
    );
    // Every sample is numbered once: received or reported lost, none twice.
    let last = samples.last().unwrap().0;
    assert_eq!(samples.len() as u32 + lost_count, last + 1);
}

#[test]
fn the_stream_stops_on_stop_on_comms_timeout_and_on_disconnect() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    // StopStream.
    rig.ack(&Request::StartStream { rate_hz: 10_000 }).unwrap();
    rig.run_ms(10);
    rig.ack(&Request::StopStream).unwrap();
    let before = blocks(&rig);
    rig.run_ms(50);
    assert_eq!(blocks(&rig), before);
    // Heartbeats keep it alive well past the comms timeout (500 ms)...
    rig.ack(&Request::StartStream { rate_hz: 1_000 }).unwrap();
    rig.run_ms_alive(1_200);
    assert_eq!(rig.core.status().stream_rate_hz, 1_000);
    // ...and without a request it stops within the timeout and a step.
    rig.send(&Request::Heartbeat { session: 0 });
    let mut stopped_after = None;
    for ms in 1..=600 {
        rig.step();
        if rig.core.status().stream_rate_hz == 0 {
            stopped_after = Some(ms);
            break;
        }
    }
    assert_eq!(
        stopped_after,
        Some(501),
        "more than 500 ms without a request"
    );
    let before = blocks(&rig);
    rig.run_ms(50);
    assert_eq!(blocks(&rig), before);
    // The link closing stops it too.
    rig.ack(&Request::StartStream { rate_hz: 10_000 }).unwrap();
    rig.core.link_closed();
    assert_eq!(rig.core.status().stream_rate_hz, 0);
    let before = blocks(&rig);
    rig.run_ms(50);
    assert_eq!(blocks(&rig), before);
}

#[test]
fn a_restart_numbers_from_zero_and_the_running_rate_again_changes_nothing() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.ack(&Request::StartStream { rate_hz: 10_000 }).unwrap();
    rig.run_ms(5);
    rig.ack(&Request::StartStream { rate_hz: 10_000 }).unwrap();
    rig.run_ms(5);
    let firsts: Vec<u32> = rig
        .received
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::StreamBlock(b) => Some(b.first_seq),
            _ => None,
        })
        .collect();
    assert_eq!(firsts, (0..10).map(|k| 10 * k).collect::<Vec<_>>());
    rig.ack(&Request::StartStream { rate_hz: 5_000 }).unwrap();
    rig.run_ms(2);
    let last = rig.received.iter().rev().find_map(|m| match m {
        DeviceMessage::StreamBlock(b) => Some(b.first_seq),
        _ => None,
    });
    assert_eq!(last, Some(0));
}

#[test]
fn a_stream_the_link_cannot_carry_beside_telemetry_is_refused_naming_the_rate_that_fits() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.ack(&Request::StartTelemetry { rate_hz: 1000 }).unwrap();
    // 921,600 Bd: beside 1 kHz telemetry two thirds of the link leave room for 1,250 Hz.
    assert_eq!(
        rig.ack(&Request::StartStream { rate_hz: 10_000 }),
        Err(NackCode::StreamRate { fits_hz: 1_250 })
    );
    assert_eq!(rig.core.status().stream_rate_hz, 0);
    rig.ack(&Request::StartStream { rate_hz: 1_250 }).unwrap();
    rig.ack(&Request::StopStream).unwrap();
    // At the fast rate everything fits: switch (the Ack leaves first), then ask again.
    assert_eq!(
        rig.ack(&Request::SetBaud { baud: 1_000_000 }),
        Err(NackCode::BadArgument)
    );
    rig.ack(&Request::SetBaud {
        baud: protocol::FAST_BAUD_RATE,
    })
    .unwrap();
    assert_eq!(rig.core.link_baud(), protocol::DEFAULT_BAUD_RATE);
    // The switch waits for the transmit queue to empty (the Ack and the telemetry sent).
    let mut switched = None;
    for _ in 0..20 {
        rig.run_ms(1);
        if let Some(b) = rig.core.take_baud_switch(rig.now_us) {
            switched = Some(b);
            break;
        }
    }
    assert_eq!(switched, Some(protocol::FAST_BAUD_RATE));
    rig.ack(&Request::StartStream { rate_hz: 10_000 }).unwrap();
    assert_eq!(rig.core.link_baud(), protocol::FAST_BAUD_RATE);
}
