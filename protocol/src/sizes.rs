//! Worst-case wire sizes, with compile-time checks of the budget.
//!
//! Postcard writes integers as varints and `f32` as 4 bytes, so each type's
//! `MAX_WIRE_SIZE` is the sum of its fields' worst cases. Tests serialise worst-case
//! values and require the exact sum, so adding a field without updating a constant fails.

use crate::framing::CRC_LEN;
use crate::link::{DEFAULT_BAUD_RATE, MAX_TELEMETRY_RATE_HZ};
use crate::{CAPTURE_CHUNK_SAMPLES, DeviceMessage, Request, TelemetrySample};

pub(crate) const U8: usize = 1;
pub(crate) const U16: usize = 3;
pub(crate) const U32: usize = 5;
pub(crate) const I32: usize = 5;
pub(crate) const U64: usize = 10;
pub(crate) const F32: usize = 4;
/// Enum discriminants and collection lengths below 128 take one varint byte.
pub(crate) const TAG: usize = 1;
/// The frame header: the sequence number.
pub(crate) const SEQ: usize = U16;

/// Largest COBS encoding of `len` bytes (one overhead byte per started 254-byte block),
/// not counting the delimiter.
pub const fn cobs_max_encoded_len(len: usize) -> usize {
    len + len.div_ceil(254) + if len == 0 { 1 } else { 0 }
}

const fn frame_size(message: usize) -> usize {
    cobs_max_encoded_len(SEQ + message + CRC_LEN) + 1
}

const fn max(a: usize, b: usize) -> usize {
    if a > b { a } else { b }
}

/// Largest frame body before CRC and COBS: sequence number plus message, bytes.
pub const MAX_MESSAGE_SIZE: usize = SEQ + max(Request::MAX_WIRE_SIZE, DeviceMessage::MAX_WIRE_SIZE);

/// Largest host-to-device frame on the wire, COBS overhead and delimiter included.
pub const MAX_REQUEST_FRAME_SIZE: usize = frame_size(Request::MAX_WIRE_SIZE);

/// Largest device-to-host frame on the wire, COBS overhead and delimiter included.
pub const MAX_DEVICE_FRAME_SIZE: usize = frame_size(DeviceMessage::MAX_WIRE_SIZE);

/// Largest frame in either direction: size encode and receive buffers with it.
pub const MAX_FRAME_SIZE: usize = cobs_max_encoded_len(MAX_MESSAGE_SIZE + CRC_LEN) + 1;

// The size sums above assume one-byte length prefixes and discriminants.
const _: () = assert!(CAPTURE_CHUNK_SAMPLES < 128 && crate::BOARD_NAME_LEN < 128);
const _: () = assert!(MAX_FRAME_SIZE == max(MAX_REQUEST_FRAME_SIZE, MAX_DEVICE_FRAME_SIZE));
// Small enough for a static DMA buffer on the device.
const _: () = assert!(MAX_FRAME_SIZE <= 512);
// Telemetry at the top rate (10 bits per byte at 8N1) must leave room on the link for replies and capture chunks.
const TELEMETRY_FRAME: usize = frame_size(TAG + TelemetrySample::MAX_WIRE_SIZE);
const _: () = assert!(
    TELEMETRY_FRAME * 10 * MAX_TELEMETRY_RATE_HZ as usize <= DEFAULT_BAUD_RATE as usize * 3 / 4
);

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
    fn budget_values() {
        // Pinned so a change is a deliberate, reviewed decision.
        assert_eq!(MAX_MESSAGE_SIZE, 274);
        assert_eq!(MAX_FRAME_SIZE, 281);
        assert_eq!(MAX_REQUEST_FRAME_SIZE, 82);
    }
}
