//! The paced link ([`SimRig::set_link_baud`]): the virtual rig never sends faster than the
//! board's UART, and what does not fit is skipped in the core, numbered, as on the board.

use protocol::session::Session;
use protocol::{
    DEFAULT_BAUD_RATE, DeviceDeframer, DeviceMessage, Request, StreamDecoder, StreamEvent,
    encode_frame_vec, link_bytes_per_s,
};
use sim::{SimConfig, SimRig};

/// What the host saw of a paced run.
#[derive(Debug, Default)]
struct Seen {
    bytes: u64,
    /// Most bytes within one 1 ms step of device time.
    busiest_ms: u64,
    telemetry: u64,
    decoder: StreamDecoder,
    /// The last sample number delivered or reported lost, plus one.
    numbered: u32,
}

/// Runs telemetry at `telemetry_hz` beside the stream at 10 kHz for `ms` of device time on
/// a link at `baud`, heartbeats every 100 ms; checks the line rate at every step.
fn run(baud: u32, telemetry_hz: u16, ms: u32) -> (SimRig, Seen) {
    let mut rig = SimRig::new(SimConfig::paper());
    rig.set_link_baud(Some(baud));
    // The board's byte rate: the nominal one, or less where the USART's divider is slower.
    let rate = sim::board_bytes_per_s(baud);
    assert!(rate <= u64::from(link_bytes_per_s(baud)));
    assert_eq!(rig.link_bytes_per_s(), Some(rate));
    let mut seq = 0u16;
    let mut send = |rig: &mut SimRig, req: &Request| {
        seq += 1;
        rig.to_device(&encode_frame_vec(seq, req).unwrap());
    };
    rig.to_device(&Session::OPENING);
    // The stream first: started beside telemetry the link could not carry, it is refused.
    send(&mut rig, &Request::StartStream { rate_hz: 10_000 });
    if telemetry_hz > 0 {
        send(
            &mut rig,
            &Request::StartTelemetry {
                rate_hz: telemetry_hz,
            },
        );
    }
    let t0 = rig.time();
    let mut deframer = DeviceDeframer::new();
    let mut seen = Seen::default();
    let mut out = Vec::new();
    for step in 1..=ms {
        if step % 100 == 0 {
            send(&mut rig, &Request::Heartbeat { session: 0 });
        }
        rig.advance(1e-3);
        out.clear();
        rig.from_device(&mut out);
        seen.bytes += out.len() as u64;
        seen.busiest_ms = seen.busiest_ms.max(out.len() as u64);
        // Never more than the line carried since the start, on the device's clock (the
        // byte in flight aside).
        let carried = (rig.time() - t0) * rate as f64;
        assert!(
            seen.bytes as f64 <= carried + 1.0,
            "{} bytes in {} s at {rate} B/s",
            seen.bytes,
            rig.time() - t0
        );
        assert_eq!(seen.bytes, rig.link_bytes_sent());
        deframer.push(&out, |frame| match frame.expect("whole frames").msg {
            DeviceMessage::Telemetry(_) => seen.telemetry += 1,
            DeviceMessage::StreamBlock(block) => {
                let numbered = &mut seen.numbered;
                seen.decoder.push(&block, |e| match e {
                    StreamEvent::Sample { seq, .. } => *numbered = seq + 1,
                    StreamEvent::Lost { first_seq, count } => *numbered = first_seq + count,
                });
            }
            _ => {}
        });
    }
    (rig, seen)
}

#[test]
fn the_stream_alone_fits_the_default_link_with_nothing_skipped() {
    let (rig, seen) = run(DEFAULT_BAUD_RATE, 0, 2000);
    let d = &seen.decoder;
    assert_eq!((d.lost, d.bad_blocks, d.restarts), (0, 0, 0));
    // Two seconds at 10 kHz, less the samples still in the ring and the queue.
    assert!(d.samples >= 19_900, "{} samples", d.samples);
    assert_eq!(seen.numbered as u64, d.samples);
    assert_eq!(rig.core().status().stream_samples_skipped, 0);
    // Within a 1 ms step: 92.16 bytes, plus the byte in flight.
    assert!(seen.busiest_ms <= 94, "{} bytes in 1 ms", seen.busiest_ms);
}

#[test]
fn a_link_too_slow_for_the_stream_skips_numbered_samples_never_sends_faster() {
    // 1 kHz telemetry (about 55 kB/s) and the 10 kHz stream (about 40 kB/s) on a link of
    // half the default rate (46,080 B/s): the line runs full, the stream skips.
    let baud = DEFAULT_BAUD_RATE / 2;
    let (rig, seen) = run(baud, 1000, 2000);
    let rate = f64::from(link_bytes_per_s(baud));
    // The line is used to the full (the last write's bytes aside).
    assert!(
        seen.bytes as f64 >= 0.98 * 2.0 * rate,
        "{} bytes in 2 s at {rate} B/s",
        seen.bytes
    );
    let d = &seen.decoder;
    assert_eq!((d.bad_blocks, d.restarts), (0, 0));
    assert!(d.lost > 0, "nothing skipped on a full link");
    // Every number is accounted for: delivered or reported lost, none silently.
    assert_eq!(u64::from(seen.numbered), d.samples + d.lost);
    let skipped = u64::from(rig.core().status().stream_samples_skipped);
    assert!(d.lost <= skipped, "{} lost, {skipped} skipped", d.lost);
    assert!(seen.telemetry > 0);
}

#[test]
fn a_rate_agreed_with_set_baud_paces_the_link_once_the_ack_is_out() {
    let mut rig = SimRig::new(SimConfig::paper());
    rig.set_link_baud(Some(DEFAULT_BAUD_RATE));
    rig.to_device(&Session::OPENING);
    rig.to_device(
        &encode_frame_vec(
            1,
            &Request::SetBaud {
                baud: protocol::FAST_BAUD_RATE,
            },
        )
        .unwrap(),
    );
    rig.advance(0.01);
    let mut out = Vec::new();
    rig.from_device(&mut out);
    let mut acked = false;
    DeviceDeframer::new().push(&out, |f| {
        acked |= matches!(f.unwrap().msg.as_reply(), Some(protocol::Reply::Ack));
    });
    assert!(acked, "the Ack left at the old rate");
    // 4,000,000 Bd as the board's USART runs it: 3,953,488 Bd.
    assert_eq!(rig.link_bytes_per_s(), Some(395_348));
    assert_eq!(sim::board_bytes_per_s(protocol::FAST_BAUD_RATE), 395_348);
    assert_eq!(rig.core().link_baud(), protocol::FAST_BAUD_RATE);
    // No request at the new rate within BAUD_CONFIRM_MS: both back to the default.
    rig.advance(f64::from(protocol::BAUD_CONFIRM_MS) / 1000.0 + 0.01);
    assert_eq!(rig.core().link_baud(), DEFAULT_BAUD_RATE);
    assert_eq!(
        rig.link_bytes_per_s(),
        Some(u64::from(link_bytes_per_s(DEFAULT_BAUD_RATE)))
    );
}
