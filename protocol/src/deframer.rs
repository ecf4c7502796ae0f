//! Sans-IO frame receiver: bytes in, frames out, no allocation, no panics.

use core::marker::PhantomData;

use serde::de::DeserializeOwned;

use crate::framing::{FRAME_DELIMITER, decode_body, frame_body};
use crate::{DeviceMessage, Error, Frame, MAX_DEVICE_FRAME_SIZE, MAX_REQUEST_FRAME_SIZE, Request};

/// Counters of what a [`Deframer`] has seen; they saturate instead of wrapping.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DeframerStats {
    /// Frames decoded successfully.
    pub frames_ok: u32,
    /// Frames dropped for a CRC mismatch.
    pub crc_errors: u32,
    /// Frames dropped for being longer than the buffer.
    pub overflow_errors: u32,
    /// Frames with a good CRC that are not a message of this schema.
    pub decode_errors: u32,
    /// Byte runs that were not COBS or too short to be a frame (garbage, line noise).
    pub framing_errors: u32,
}

impl DeframerStats {
    /// Frames dropped for any reason.
    pub fn errors(&self) -> u32 {
        self.crc_errors
            .saturating_add(self.overflow_errors)
            .saturating_add(self.decode_errors)
            .saturating_add(self.framing_errors)
    }

    fn record<M>(&mut self, result: &Result<Frame<M>, Error>) {
        let counter = match result {
            Ok(_) => &mut self.frames_ok,
            Err(Error::Crc) => &mut self.crc_errors,
            Err(Error::Overflow) => &mut self.overflow_errors,
            Err(Error::Decode { .. }) => &mut self.decode_errors,
            Err(_) => &mut self.framing_errors,
        };
        *counter = counter.saturating_add(1);
    }
}

/// Receives frames of message type `M` from a byte stream, buffering up to `N` encoded
/// bytes per frame.
///
/// The bytes between two `0x00` delimiters are decoded as one frame; a frame that goes
/// wrong costs only itself, and the next delimiter resynchronises. Since every frame
/// starts with a delimiter, noise between frames ends at the next frame's start and
/// costs nothing but a counted error. Empty frames (repeated delimiters) are ignored.
pub struct Deframer<M, const N: usize> {
    buf: [u8; N],
    len: usize,
    overflowed: bool,
    /// Length of the CRC-checked body at the start of `buf`, until the next byte arrives.
    body_len: Option<usize>,
    stats: DeframerStats,
    msg: PhantomData<fn() -> M>,
}

/// The host's receiver of device messages.
pub type DeviceDeframer = Deframer<DeviceMessage, MAX_DEVICE_FRAME_SIZE>;

/// The device's receiver of host requests.
pub type RequestDeframer = Deframer<Request, MAX_REQUEST_FRAME_SIZE>;

impl<M: DeserializeOwned, const N: usize> Deframer<M, N> {
    /// An empty deframer.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
            body_len: None,
            stats: DeframerStats {
                frames_ok: 0,
                crc_errors: 0,
                overflow_errors: 0,
                decode_errors: 0,
                framing_errors: 0,
            },
            msg: PhantomData,
        }
    }

    /// Feeds one byte; returns a result when the byte ends a frame.
    pub fn push_byte(&mut self, byte: u8) -> Option<Result<Frame<M>, Error>> {
        if byte != FRAME_DELIMITER {
            self.body_len = None;
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflowed = true,
            }
            return None;
        }
        let len = core::mem::take(&mut self.len);
        let result = if core::mem::take(&mut self.overflowed) {
            Err(Error::Overflow)
        } else if len == 0 {
            return None;
        } else {
            match frame_body(&mut self.buf[..len]) {
                Ok(body) => {
                    let body_len = body.len();
                    self.body_len = Some(body_len);
                    decode_body(&self.buf[..body_len])
                }
                Err(e) => Err(e),
            }
        };
        self.stats.record(&result);
        Some(result)
    }

    /// The CRC-checked body (`seq` and message, postcard-encoded) of the frame that the
    /// last [`Deframer::push_byte`] completed, when it passed its CRC, whether or not it
    /// decoded; `None` once another byte arrives. For [`crate::identify_peer`] on an
    /// older device's frame that failed with [`Error::Decode`].
    pub fn last_body(&self) -> Option<&[u8]> {
        self.body_len.and_then(|n| self.buf.get(..n))
    }

    /// Feeds a chunk of any size, calling `on_frame` for every frame it completes.
    pub fn push(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<Frame<M>, Error>)) {
        for &byte in bytes {
            if let Some(result) = self.push_byte(byte) {
                on_frame(result);
            }
        }
    }

    /// Drops any partial frame (e.g. after reopening the port); keeps the stats.
    pub fn clear(&mut self) {
        self.len = 0;
        self.overflowed = false;
        self.body_len = None;
    }

    /// Bytes of the current partial frame.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Counters since creation.
    pub fn stats(&self) -> DeframerStats {
        self.stats
    }
}

impl<M: DeserializeOwned, const N: usize> Default for Deframer<M, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M, const N: usize> core::fmt::Debug for Deframer<M, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Deframer")
            .field("pending", &self.len)
            .field("overflowed", &self.overflowed)
            .field("stats", &self.stats)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MAX_FRAME_SIZE, encode_frame_vec};

    fn collect(d: &mut DeviceDeframer, bytes: &[u8]) -> Vec<Result<Frame<DeviceMessage>, Error>> {
        let mut out = Vec::new();
        d.push(bytes, |r| out.push(r));
        out
    }

    #[test]
    fn corrupted_byte_is_counted_and_next_frame_decodes() {
        let ack = DeviceMessage::ack;
        let mut stream = encode_frame_vec(1, &ack(10)).unwrap();
        let first_len = stream.len();
        stream.extend(encode_frame_vec(2, &ack(11)).unwrap());
        // Every byte of the first frame, both delimiters included.
        for i in 0..first_len {
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut bytes = stream.clone();
                bytes[i] ^= flip;
                let mut d = DeviceDeframer::new();
                let results = collect(&mut d, &bytes);
                let last = results.last().unwrap();
                assert_eq!(
                    last,
                    &Ok(Frame {
                        seq: 2,
                        msg: ack(11)
                    }),
                    "byte {i} ^ {flip:#x}"
                );
                assert_eq!(d.stats().frames_ok, 1);
                assert!(
                    d.stats().errors() >= 1,
                    "byte {i} ^ {flip:#x}: {:?}",
                    d.stats()
                );
            }
        }
    }

    #[test]
    fn single_bit_flips_are_crc_or_framing_errors() {
        let frame = encode_frame_vec(
            5,
            &DeviceMessage::reply(
                3,
                crate::Reply::Faults {
                    active: crate::FaultFlags::STALL,
                    latched: crate::FaultFlags::STALL,
                },
            ),
        )
        .unwrap();
        for i in 0..frame.len() - 1 {
            for bit in 0..8 {
                let mut bytes = frame.clone();
                bytes[i] ^= 1 << bit;
                let mut d = DeviceDeframer::new();
                collect(&mut d, &bytes);
                let s = d.stats();
                assert_eq!(
                    s.frames_ok + s.decode_errors,
                    0,
                    "byte {i} bit {bit}: {s:?}"
                );
            }
        }
    }

    #[test]
    fn overflow_drops_the_long_frame_only() {
        let mut d: Deframer<DeviceMessage, 16> = Deframer::new();
        let mut bytes = vec![0x11u8; 40];
        bytes.push(0);
        bytes.extend(encode_frame_vec(9, &DeviceMessage::ack(1)).unwrap());
        let mut results = Vec::new();
        d.push(&bytes, |r| results.push(r));
        assert_eq!(
            results,
            vec![
                Err(Error::Overflow),
                Ok(Frame {
                    seq: 9,
                    msg: DeviceMessage::ack(1)
                })
            ]
        );
        assert_eq!(d.stats().overflow_errors, 1);
        assert_eq!(d.pending(), 0);
    }

    #[test]
    fn largest_frame_fits_the_host_deframer() {
        assert_eq!(MAX_DEVICE_FRAME_SIZE, MAX_FRAME_SIZE);
        let chunk = crate::golden::examples::worst_case_chunk();
        let frame = encode_frame_vec(u16::MAX, &DeviceMessage::CaptureChunk(chunk)).unwrap();
        assert!(frame.len() <= MAX_DEVICE_FRAME_SIZE);
        let mut d = DeviceDeframer::new();
        assert!(matches!(collect(&mut d, &frame)[..], [Ok(_)]));
    }

    #[test]
    fn idle_delimiters_are_ignored_and_garbage_resyncs() {
        let mut d = DeviceDeframer::new();
        let mut bytes = vec![0, 0, 0x37, 0x99, 0x12, 0, 0];
        bytes.extend(encode_frame_vec(4, &DeviceMessage::ack(4)).unwrap());
        let results = collect(&mut d, &bytes);
        assert_eq!(results.len(), 2);
        assert!(results[0].is_err());
        assert!(results[1].is_ok());
        assert_eq!(d.stats().errors(), 1);
    }

    #[test]
    fn noise_right_before_a_frame_costs_nothing() {
        // No delimiter in the noise: the frame's own opening delimiter ends it.
        let mut d = DeviceDeframer::new();
        let mut bytes = encode_frame_vec(1, &DeviceMessage::ack(1)).unwrap();
        bytes.extend([0x37, 0x99, 0x12]);
        bytes.extend(encode_frame_vec(2, &DeviceMessage::ack(2)).unwrap());
        let results = collect(&mut d, &bytes);
        assert_eq!(
            results,
            vec![
                Ok(Frame {
                    seq: 1,
                    msg: DeviceMessage::ack(1)
                }),
                Err(Error::Framing),
                Ok(Frame {
                    seq: 2,
                    msg: DeviceMessage::ack(2)
                }),
            ]
        );
    }

    #[test]
    fn last_body_is_the_checked_body_until_the_next_byte() {
        let mut d = DeviceDeframer::new();
        let frame = encode_frame_vec(5, &DeviceMessage::ack(6)).unwrap();
        let mut expected = frame.clone();
        let expected = crate::frame_body(&mut expected).unwrap().to_vec();
        let mut last = None;
        for &b in &frame {
            if d.push_byte(b).is_some() {
                last = d.last_body().map(<[u8]>::to_vec);
            }
        }
        assert_eq!(last, Some(expected));
        d.push_byte(0x11);
        assert_eq!(d.last_body(), None);
        // A CRC failure leaves no body.
        let mut bad = frame.clone();
        bad[3] ^= 0x40;
        for &b in &bad {
            if let Some(r) = d.push_byte(b) {
                assert!(r.is_err());
                assert_eq!(d.last_body(), None);
            }
        }
    }
}
