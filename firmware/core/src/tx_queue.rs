//! Outgoing frames: a byte ring of encoded COBS frames with the device's frame counter.
//!
//! Frames enter whole or not at all, so the host never sees a torn frame. Replies take
//! precedence over the streams by room: telemetry, health and capture data leave
//! [`REPLY_RESERVE`] free, enough for [`protocol::REQUEST_WINDOW`] replies of the largest
//! size plus the `Busy` answers and fault events that may come with them, so a host that
//! keeps within the window gets every reply whatever the streams do. Capture chunks also
//! stop at [`CAPTURE_IN_FLIGHT`] bytes queued so telemetry and replies wait behind at most
//! that much. The queue counts the replies still waiting ([`TxQueue::queued_replies`]):
//! the server answers `Busy` to a request beyond the window.

use protocol::{MAX_DEVICE_FRAME_SIZE, MAX_REPLY_FRAME_SIZE, REQUEST_WINDOW, encode_frame};
use serde::Serialize;

/// Bytes of a `Nack(Busy)` or `FaultEvent` frame at most (a short reply or event).
const SHORT_FRAME: usize = 24;

/// Bytes kept free for replies, `Busy` answers and fault events when queueing telemetry
/// or capture data: a full window of the largest replies, then as many short frames.
pub const REPLY_RESERVE: usize =
    REQUEST_WINDOW * (MAX_REPLY_FRAME_SIZE + SHORT_FRAME) + SHORT_FRAME;
/// Most capture bytes queued at once (about 2.8 ms at 921 600 Bd).
pub const CAPTURE_IN_FLIGHT: usize = 256;
/// Queue size, bytes: the reply reserve, a capture chunk in flight and a telemetry and a
/// health frame beside it.
pub const TX_QUEUE_LEN: usize = REPLY_RESERVE + CAPTURE_IN_FLIGHT + 2 * MAX_DEVICE_FRAME_SIZE;

/// Replies whose end the queue remembers (the window, and as many `Busy` answers).
const REPLY_SLOTS: usize = 2 * REQUEST_WINDOW;

// A stream frame never takes the reply reserve, and a capture chunk still fits beside it.
const _: () = assert!(TX_QUEUE_LEN >= REPLY_RESERVE + MAX_DEVICE_FRAME_SIZE + CAPTURE_IN_FLIGHT);

/// The byte ring.
#[derive(Debug, Clone)]
pub struct TxQueue {
    buf: [u8; TX_QUEUE_LEN],
    /// Where a frame is encoded when the free space after the tail is too short for one
    /// (kept between pushes: never zeroed, `encode_frame` overwrites what it uses).
    scratch: [u8; MAX_DEVICE_FRAME_SIZE],
    head: usize,
    len: usize,
    next_seq: u16,
    dropped: u32,
    /// Bytes queued since boot and bytes drained since boot (both wrapping).
    pushed_total: u32,
    drained_total: u32,
    /// Where each reply still queued ends, in `pushed_total` units, oldest first.
    reply_ends: [u32; REPLY_SLOTS],
    reply_first: usize,
    reply_count: usize,
}

impl TxQueue {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            buf: [0; TX_QUEUE_LEN],
            scratch: [0; MAX_DEVICE_FRAME_SIZE],
            head: 0,
            len: 0,
            next_seq: 0,
            dropped: 0,
            pushed_total: 0,
            drained_total: 0,
            reply_ends: [0; REPLY_SLOTS],
            reply_first: 0,
            reply_count: 0,
        }
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes free.
    pub fn free(&self) -> usize {
        TX_QUEUE_LEN - self.len
    }

    /// Frames dropped for lack of room (their sequence numbers are skipped, so the host
    /// counts them as lost).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Replies queued and not yet handed to the link (the server answers `Busy` to a
    /// request that finds [`protocol::REQUEST_WINDOW`] of them).
    pub fn queued_replies(&self) -> usize {
        self.reply_count
    }

    /// Queues a reply (`msg` answers a request) with no reserve, remembering where it ends
    /// so [`TxQueue::queued_replies`] counts it until it is drained.
    pub fn push_reply<M: Serialize + ?Sized>(&mut self, msg: &M) -> bool {
        let queued = self.push(msg, 0);
        if queued && self.reply_count < REPLY_SLOTS {
            let slot = (self.reply_first + self.reply_count) % REPLY_SLOTS;
            self.reply_ends[slot] = self.pushed_total;
            self.reply_count += 1;
        }
        queued
    }

    /// Counts a frame that was never offered (a stream sample superseded before framing).
    pub fn note_dropped(&mut self) {
        self.dropped = self.dropped.saturating_add(1);
    }

    /// Encodes `msg` (a [`protocol::DeviceMessage`], or a legacy message such as
    /// [`protocol::LegacyV1Nack`]) and queues it if it fits with `reserve` bytes to spare.
    pub fn push<M: Serialize + ?Sized>(&mut self, msg: &M, reserve: usize) -> bool {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let free = self.free();
        let tail = (self.head + self.len) % TX_QUEUE_LEN;
        // Free bytes from the tail on without wrapping: encoded there directly when any
        // frame fits, else in `scratch` and copied in.
        let contiguous = (TX_QUEUE_LEN - tail).min(free);
        let direct = contiguous >= MAX_DEVICE_FRAME_SIZE;
        let out = if direct {
            &mut self.buf[tail..tail + contiguous]
        } else {
            &mut self.scratch[..]
        };
        let fits = match encode_frame(seq, msg, out) {
            Ok(frame) if frame.len() + reserve <= free => {
                let n = frame.len();
                if !direct {
                    // At most two contiguous copies: up to the ring's end, then from its start.
                    let first = n.min(TX_QUEUE_LEN - tail);
                    let (a, b) = self.scratch[..n].split_at(first);
                    self.buf[tail..tail + first].copy_from_slice(a);
                    self.buf[..b.len()].copy_from_slice(b);
                }
                self.len += n;
                #[allow(
                    clippy::cast_possible_truncation,
                    reason = "a frame is at most MAX_DEVICE_FRAME_SIZE bytes"
                )]
                {
                    self.pushed_total = self.pushed_total.wrapping_add(n as u32);
                }
                true
            }
            // A frame written straight into the free space and refused stays unqueued.
            _ => false,
        };
        if !fits {
            self.dropped = self.dropped.saturating_add(1);
        }
        fits
    }

    /// Moves queued bytes into `out`; returns how many.
    pub fn drain(&mut self, out: &mut [u8]) -> usize {
        let n = out.len().min(self.len);
        let first = n.min(TX_QUEUE_LEN - self.head);
        out[..first].copy_from_slice(&self.buf[self.head..self.head + first]);
        out[first..n].copy_from_slice(&self.buf[..n - first]);
        self.head = (self.head + n) % TX_QUEUE_LEN;
        self.len -= n;
        #[allow(
            clippy::cast_possible_truncation,
            reason = "at most TX_QUEUE_LEN bytes"
        )]
        {
            self.drained_total = self.drained_total.wrapping_add(n as u32);
        }
        // Replies whose last byte has gone out no longer count.
        while self.reply_count > 0 {
            let end = self.reply_ends[self.reply_first];
            if self.pushed_total.wrapping_sub(end)
                >= self.pushed_total.wrapping_sub(self.drained_total)
            {
                self.reply_first = (self.reply_first + 1) % REPLY_SLOTS;
                self.reply_count -= 1;
            } else {
                break;
            }
        }
        n
    }
}

impl Default for TxQueue {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests {
    use super::*;
    use protocol::{DeviceDeframer, DeviceMessage, Frame};

    #[test]
    fn frames_wrap_around_and_decode_in_order() {
        let mut q = TxQueue::new();
        let mut d = DeviceDeframer::new();
        let mut got = Vec::new();
        let mut out = [0u8; 7];
        for round in 0..200u16 {
            assert!(q.push(&DeviceMessage::ack(round), 0));
            while q.len() > 20 {
                let n = q.drain(&mut out);
                d.push(&out[..n], |f| got.push(f.unwrap()));
            }
        }
        while !q.is_empty() {
            let n = q.drain(&mut out);
            d.push(&out[..n], |f| got.push(f.unwrap()));
        }
        assert_eq!(got.len(), 200);
        for (k, Frame { seq, msg }) in got.into_iter().enumerate() {
            assert_eq!(seq, k as u16);
            assert_eq!(msg, DeviceMessage::ack(k as u16));
        }
    }

    #[test]
    fn replies_count_until_their_last_byte_is_drained() {
        let mut q = TxQueue::new();
        let mut out = [0u8; 3];
        assert!(q.push_reply(&DeviceMessage::ack(1)));
        assert!(q.push(&DeviceMessage::ack(9), REPLY_RESERVE));
        assert!(q.push_reply(&DeviceMessage::ack(2)));
        assert_eq!(q.queued_replies(), 2);
        let first = encode_frame_len(&DeviceMessage::ack(1));
        let mut drained = 0;
        while drained + out.len() < first {
            drained += q.drain(&mut out);
            assert_eq!(q.queued_replies(), 2, "the first reply is not out yet");
        }
        let mut last = [0u8; 1];
        while drained < first {
            drained += q.drain(&mut last);
        }
        assert_eq!(q.queued_replies(), 1);
        let mut rest = [0u8; TX_QUEUE_LEN];
        q.drain(&mut rest);
        assert_eq!(q.queued_replies(), 0);
    }

    #[test]
    fn streams_never_take_the_room_of_a_full_window_of_replies() {
        let mut q = TxQueue::new();
        let big = protocol::DeviceMessage::CaptureChunk(protocol::CaptureChunk {
            capture_id: u16::MAX,
            first_sample: u32::MAX,
            total_samples: u32::MAX,
            samples: heapless::Vec::from_slice(
                &[protocol::CaptureSample {
                    current_adc: u16::MAX,
                    encoder_count: i32::MIN,
                    output_count: Some(i32::MIN),
                }; protocol::CAPTURE_CHUNK_SAMPLES],
            )
            .unwrap(),
        });
        while q.push(&big, REPLY_RESERVE) {}
        let small = DeviceMessage::ack(0);
        while q.push(&small, REPLY_RESERVE) {}
        let params = DeviceMessage::reply(
            3,
            protocol::Reply::Parameters(protocol::RigParameters::paper()),
        );
        for _ in 0..REQUEST_WINDOW {
            assert!(q.push_reply(&params));
        }
        assert_eq!(q.queued_replies(), REQUEST_WINDOW);
        // And a `Busy` for each request beyond the window.
        for _ in 0..REQUEST_WINDOW {
            assert!(q.push_reply(&DeviceMessage::nack(7, protocol::NackCode::Busy)));
        }
    }

    fn encode_frame_len(msg: &DeviceMessage) -> usize {
        let mut buf = [0u8; MAX_DEVICE_FRAME_SIZE];
        encode_frame(0, msg, &mut buf).unwrap().len()
    }

    #[test]
    fn full_queue_drops_whole_frames_and_skips_their_seq() {
        let mut q = TxQueue::new();
        let mut pushed = 0;
        while q.push(&DeviceMessage::ack(1), 0) {
            pushed += 1;
        }
        assert_eq!(q.dropped(), 1);
        assert!(q.free() < 16);
        let mut out = [0u8; TX_QUEUE_LEN];
        let n = q.drain(&mut out);
        let mut d = DeviceDeframer::new();
        let mut seqs = Vec::new();
        d.push(&out[..n], |f| seqs.push(f.unwrap().seq));
        assert_eq!(seqs.len(), pushed);
        assert!(q.push(&DeviceMessage::ack(1), 0));
        let n = q.drain(&mut out);
        let mut last = None;
        d.push(&out[..n], |f| last = f.ok().map(|f| f.seq));
        assert_eq!(last, Some(pushed as u16 + 1));
    }
}
