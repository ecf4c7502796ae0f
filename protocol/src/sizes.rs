//! Worst-case wire sizes, with compile-time checks of the budget.
//!
//! Postcard writes integers as varints and `f32` as 4 bytes, so each type's
//! `MAX_WIRE_SIZE` is the sum of its fields' worst cases. Tests serialise worst-case
//! values and require the exact sum, and the layout generator (`src/golden/layout.rs`)
//! derives the same maxima from the types, so adding a field without updating a constant
//! fails.

use crate::framing::{CRC_LEN, FRAME_DELIMITERS};
use crate::link::{DEFAULT_BAUD_RATE, MAX_TELEMETRY_RATE_HZ};
use crate::stream::{MAX_STREAM_RATE_HZ, STREAM_BLOCK_SAMPLES};
use crate::{
    BOARD_NAME_LEN, CAPTURE_CHUNK_SAMPLES, DeviceInfo, DeviceMessage, FIRMWARE_BUILD_LEN,
    HealthSample, NackCode, Reply, Request, RigParameters, TelemetrySample,
};

pub(crate) const U8: usize = 1;
pub(crate) const U16: usize = varint_len(u16::MAX as u64);
pub(crate) const U32: usize = varint_len(u32::MAX as u64);
pub(crate) const I32: usize = U32;
pub(crate) const U64: usize = varint_len(u64::MAX);
pub(crate) const F32: usize = 4;
/// Enum discriminants and collection lengths below 128 take one varint byte.
pub(crate) const TAG: usize = 1;
/// The frame header: the sequence number.
pub(crate) const SEQ: usize = U16;

/// Bytes of the LEB128 varint of `value` (7 bits per byte).
pub const fn varint_len(value: u64) -> usize {
    let mut len = 1;
    let mut rest = value >> 7;
    while rest != 0 {
        len += 1;
        rest >>= 7;
    }
    len
}

/// Largest COBS encoding of `len` bytes (one overhead byte per started 254-byte block),
/// not counting the delimiters.
pub const fn cobs_max_encoded_len(len: usize) -> usize {
    len + len.div_ceil(254) + if len == 0 { 1 } else { 0 }
}

/// Bytes on the wire for a message of `message` bytes: sequence number, CRC, COBS and
/// both delimiters.
const fn frame_size(message: usize) -> usize {
    cobs_max_encoded_len(SEQ + message + CRC_LEN) + FRAME_DELIMITERS
}

const fn max(a: usize, b: usize) -> usize {
    if a > b { a } else { b }
}

/// Largest frame body before CRC and COBS: sequence number plus message, bytes.
pub const MAX_MESSAGE_SIZE: usize = SEQ + max(Request::MAX_WIRE_SIZE, DeviceMessage::MAX_WIRE_SIZE);

/// Largest host-to-device frame on the wire, COBS overhead and both delimiters included.
pub const MAX_REQUEST_FRAME_SIZE: usize = frame_size(Request::MAX_WIRE_SIZE);

/// Largest device-to-host frame on the wire, COBS overhead and both delimiters included.
pub const MAX_DEVICE_FRAME_SIZE: usize = frame_size(DeviceMessage::MAX_WIRE_SIZE);

/// Largest reply frame on the wire (a `DeviceMessage::Reply` with the largest reply, a
/// parameter record), COBS overhead and both delimiters included.
pub const MAX_REPLY_FRAME_SIZE: usize = frame_size(TAG + U16 + Reply::MAX_WIRE_SIZE);

/// Largest frame in either direction: size encode and receive buffers with it.
pub const MAX_FRAME_SIZE: usize =
    cobs_max_encoded_len(MAX_MESSAGE_SIZE + CRC_LEN) + FRAME_DELIMITERS;

// The size sums above assume one-byte length prefixes and discriminants.
const _: () =
    assert!(CAPTURE_CHUNK_SAMPLES < 128 && BOARD_NAME_LEN < 128 && FIRMWARE_BUILD_LEN < 128);
const _: () = assert!(MAX_FRAME_SIZE == max(MAX_REQUEST_FRAME_SIZE, MAX_DEVICE_FRAME_SIZE));
// Small enough for a static DMA buffer on the device.
const _: () = assert!(MAX_FRAME_SIZE <= 512);
// A reply is at most a parameter record (the largest reply), inside the capture-chunk budget.
const _: () = assert!(DeviceInfo::MAX_WIRE_SIZE <= RigParameters::MAX_WIRE_SIZE);
const _: () = assert!(NackCode::MAX_WIRE_SIZE <= RigParameters::MAX_WIRE_SIZE);
const _: () = assert!(TAG + U16 + Reply::MAX_WIRE_SIZE <= DeviceMessage::MAX_WIRE_SIZE);

/// A telemetry frame at its worst case (every varint at its maximum).
const TELEMETRY_FRAME: usize = frame_size(TAG + TelemetrySample::MAX_WIRE_SIZE);

/// A telemetry frame as it is sent in practice: within 50 days of boot (device clock below
/// 2^42 us), fewer than 2^28 samples, named fault and status bits only.
const TELEMETRY_FRAME_TYPICAL: usize = frame_size(
    TAG + varint_len((1 << 28) - 1)
        + varint_len((1 << 42) - 1)
        + 7 * F32
        + TAG
        + varint_len(u16::MAX as u64)
        + varint_len(u8::MAX as u64),
);

/// A health frame at its worst case; one a second, next to a thousand telemetry frames.
const HEALTH_FRAME: usize = frame_size(TAG + HealthSample::MAX_WIRE_SIZE);

/// Bits on the line per byte at 8N1.
const BITS_PER_BYTE: usize = crate::link::UART_BITS_PER_BYTE as usize;

// Telemetry alone can never fill the link, even at its worst case and the top rate.
const _: () = assert!(
    TELEMETRY_FRAME * BITS_PER_BYTE * MAX_TELEMETRY_RATE_HZ as usize <= DEFAULT_BAUD_RATE as usize
);
// In practice, telemetry at the top rate plus the health sample leave a third of the link
// for replies and capture chunks (the slow quantities live in `HealthSample` for this).
const _: () = assert!(
    (TELEMETRY_FRAME_TYPICAL * MAX_TELEMETRY_RATE_HZ as usize + HEALTH_FRAME) * BITS_PER_BYTE
        <= DEFAULT_BAUD_RATE as usize * 2 / 3
);

/// A stream block frame as the device sends it at 10 kHz with the cam vibrating: sample
/// numbers below 2^28 (7.4 h), the first sample absolute (12-bit current 2 bytes, the
/// 16-bit counts 3, duty and tau_cam 3, status and state 1 each), each later sample 2
/// bytes (a current step within +-15 counts and a cam step below 64 counts: 20 Hz is 16
/// counts per sample), the held fields unchanged within the block.
pub const STREAM_FRAME_TYPICAL: usize = frame_size(
    TAG + varint_len((1 << 28) - 1)
        + TAG
        + (2 + 3 + 3 + 3 + 3 + 1 + 1)
        + (STREAM_BLOCK_SAMPLES - 1) * 2,
);

/// Stream bytes per second at the top rate, typical data ([`STREAM_FRAME_TYPICAL`]).
pub const STREAM_BYTES_PER_S_TYPICAL: usize =
    STREAM_FRAME_TYPICAL * MAX_STREAM_RATE_HZ as usize / STREAM_BLOCK_SAMPLES;

// The 10 kHz stream alone leaves more than a third of the default link for replies and
// health; telemetry beside it must run slower (1 kHz telemetry is 55 kB/s of its own).
const _: () =
    assert!(STREAM_BYTES_PER_S_TYPICAL * BITS_PER_BYTE <= DEFAULT_BAUD_RATE as usize * 2 / 3);

/// The highest stream rate at or below `rate_hz` (10 kHz divided by a whole number) that a
/// link at `baud` carries beside telemetry at `telemetry_hz` (0: off) with typical frames
/// (50 B a stream frame, a typical telemetry frame and the health sample once a
/// second), leaving a third of the link for replies and capture chunks, as the telemetry's
/// own budget does. What `StartStream` is refused with (`NackCode::StreamRate`) when it is
/// below the rate asked; `None` for 0, or when not even 1 Hz fits.
pub fn stream_rate_for_link(rate_hz: u16, telemetry_hz: u16, baud: u32) -> Option<u16> {
    let budget = u64::from(crate::link::link_bytes_per_s(baud)) * 2 / 3;
    let telemetry = if telemetry_hz == 0 {
        0
    } else {
        (TELEMETRY_FRAME_TYPICAL as u64) * u64::from(telemetry_hz) + HEALTH_FRAME as u64
    };
    let mut rate = crate::stream::stream_rate_that_fits(rate_hz)?;
    loop {
        // Blocks of STREAM_BLOCK_SAMPLES, one frame each.
        let stream = (STREAM_FRAME_TYPICAL as u64) * u64::from(rate) / STREAM_BLOCK_SAMPLES as u64;
        if telemetry + stream <= budget {
            return Some(rate);
        }
        if rate == 1 {
            return None;
        }
        rate = crate::stream::stream_rate_that_fits(rate - 1)?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cobs_bound_matches_the_encoder() {
        for len in [0usize, 1, 253, 254, 255, 508, 600] {
            let src = std::vec![0x55u8; len];
            let mut dst = std::vec![0u8; cobs_max_encoded_len(len)];
            assert_eq!(
                cobs::encode(&src, &mut dst),
                cobs_max_encoded_len(len),
                "len {len}"
            );
        }
    }

    #[test]
    fn varint_lengths() {
        assert_eq!((U16, U32, U64), (3, 5, 10));
        assert_eq!(varint_len(0), 1);
        assert_eq!(varint_len(127), 1);
        assert_eq!(varint_len(128), 2);
        assert_eq!(varint_len((1 << 42) - 1), 6);
        for v in [0u64, 127, 128, 16_383, 16_384, 1 << 42, u64::MAX] {
            let mut buf = [0u8; 16];
            assert_eq!(
                postcard::to_slice(&v, &mut buf).unwrap().len(),
                varint_len(v),
                "{v}"
            );
        }
    }

    #[test]
    fn the_stream_is_refused_beside_telemetry_the_link_cannot_carry() {
        use crate::link::{DEFAULT_BAUD_RATE, FAST_BAUD_RATE};
        // 921,600 Bd: two thirds of 92,160 B/s is 61,440 B/s. The 10 kHz stream alone
        // (50,000 B/s) fits, and beside 200 Hz telemetry (11,000 + 49 B/s).
        assert_eq!(
            stream_rate_for_link(10_000, 0, DEFAULT_BAUD_RATE),
            Some(10_000)
        );
        assert_eq!(
            stream_rate_for_link(10_000, 200, DEFAULT_BAUD_RATE),
            Some(10_000)
        );
        // Beside 1 kHz telemetry (55,049 B/s) 6,391 B/s are left: 1,250 Hz (6,250 B/s).
        assert_eq!(
            stream_rate_for_link(10_000, 1000, DEFAULT_BAUD_RATE),
            Some(1_250)
        );
        // 4,000,000 Bd (266,666 B/s of 400,000): everything fits.
        assert_eq!(
            stream_rate_for_link(10_000, 1000, FAST_BAUD_RATE),
            Some(10_000)
        );
        // Rates that are not 10 kHz divided by a whole number come down to one that is.
        assert_eq!(
            stream_rate_for_link(3_000, 0, DEFAULT_BAUD_RATE),
            Some(2_500)
        );
        assert_eq!(stream_rate_for_link(0, 0, DEFAULT_BAUD_RATE), None);
        // A link too slow even for telemetry.
        assert_eq!(stream_rate_for_link(10_000, 1000, 9_600), None);
    }

    #[test]
    fn budget_values() {
        // Pinned so a change is a deliberate, reviewed decision. v2 added the opening
        // delimiter (one byte per frame) and grew the request to the same record; the
        // output shaft's angle and speed grew telemetry by 8 bytes, and the slow
        // quantities moved to the once-a-second health sample. v4's output count per
        // capture sample came with 18 (not 32) samples per chunk: 4 bytes smaller. v6's
        // chunk of 10, what the firmware sends, took the largest frame from 278 to 165 bytes.
        // v7's four profile shifts grew the parameter record, so the largest request, by 16;
        // v7's stream block at its worst (every field jumping at every sample) is the
        // largest message now; typical blocks are a quarter of it.
        assert_eq!(MAX_MESSAGE_SIZE, 210);
        assert_eq!(MAX_FRAME_SIZE, 217);
        assert_eq!(STREAM_FRAME_TYPICAL, 50);
        // 50,000 B/s of the link's 92,160 B/s (921,600 Bd at 10 bits a byte): 54 %.
        assert_eq!(STREAM_BYTES_PER_S_TYPICAL, 50_000);
        assert_eq!(MAX_REQUEST_FRAME_SIZE, 99);
        assert_eq!(TELEMETRY_FRAME, 63);
        assert_eq!(TELEMETRY_FRAME_TYPICAL, 55);
        assert_eq!(HEALTH_FRAME, 49);
    }

    #[test]
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_possible_wrap,
        reason = "synthetic signal: values in range by construction, counters wrap on purpose"
    )]
    fn typical_stream_frames_are_what_the_bound_says() {
        use crate::{StreamBlock, StreamSample};
        // One second at 10 kHz of a cam vibrating at 20 Hz (8,192 counts a turn: 16.4
        // counts a sample), a 1 A (230-count) current swing at the cam frequency with
        // +-3 counts of noise, duty and tau_cam moving per 1 ms step, the output creeping.
        let mut total = 0usize;
        let mut largest = 0usize;
        let mut noise: u32 = 0x1234_5678;
        for block in 0..1_000u32 {
            let samples: std::vec::Vec<StreamSample> = (0..10u32)
                .map(|k| {
                    let n = block * 10 + k;
                    noise = noise.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    let t = n as f32 / 10_000.0;
                    let swing = 230.0 * (core::f32::consts::TAU * 20.0 * t).sin();
                    let jitter = (noise >> 29) as f32 - 3.0;
                    StreamSample {
                        current_adc: (2300.0 + swing + jitter) as u16,
                        cam_count: (n as f32 * 16.384) as u32 as u16,
                        output_count: (n / 40) as u16,
                        duty: (4_000 + (block % 50) * 3) as i16,
                        tau_cam: 310 + (block / 50) as i16,
                        status: crate::StatusFlags::HOST_RELEASE.bits(),
                        state: 2,
                    }
                })
                .collect();
            let msg = DeviceMessage::StreamBlock(StreamBlock::pack(
                (1 << 28) - 1 - 10_000 + block * 10,
                &samples,
            ));
            let frame = crate::encode_frame_vec(u16::MAX, &msg).unwrap();
            total += frame.len();
            largest = largest.max(frame.len());
        }
        assert!(largest <= STREAM_FRAME_TYPICAL, "{largest}");
        // Bytes in one second at 10 kHz: within the typical budget, about half the link
        // (46,185 B/s when written: 50 % of 92,160).
        assert!(total <= STREAM_BYTES_PER_S_TYPICAL, "{total}");
        let link = DEFAULT_BAUD_RATE as usize / BITS_PER_BYTE;
        assert_eq!(link, 92_160);
        assert!(total * 100 / link <= 55, "{total} B/s of {link}");
    }

    #[test]
    fn typical_telemetry_frame_is_what_the_bound_says() {
        // A sample 50 days after boot with every named bit set.
        let sample = TelemetrySample {
            seq: (1 << 28) - 1,
            device_time_us: (1 << 42) - 1,
            faults: crate::FaultFlags::all(),
            status: crate::StatusFlags::all(),
            ..crate::golden::examples::telemetry()
        };
        let frame = crate::encode_frame_vec(u16::MAX, &DeviceMessage::Telemetry(sample)).unwrap();
        assert!(frame.len() <= TELEMETRY_FRAME_TYPICAL, "{}", frame.len());
    }
}
