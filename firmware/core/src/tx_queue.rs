//! Outgoing frames: a byte ring of encoded COBS frames with the device's frame counter.
//!
//! Frames enter whole or not at all, so the host never sees a torn frame. Callers keep
//! room free for the frames that matter most: a reply needs only its own size, telemetry
//! leaves [`REPLY_RESERVE`] free, capture chunks also stop at [`CAPTURE_IN_FLIGHT`] bytes
//! queued so telemetry and replies wait behind at most that much.

use protocol::{MAX_DEVICE_FRAME_SIZE, encode_frame};
use serde::Serialize;

/// Queue size, bytes.
pub const TX_QUEUE_LEN: usize = 1024;
/// Bytes kept free for replies and fault events when queueing telemetry or capture data.
pub const REPLY_RESERVE: usize = 128;
/// Most capture bytes queued at once (about 2.8 ms at 921 600 Bd).
pub const CAPTURE_IN_FLIGHT: usize = 256;

/// The byte ring.
#[derive(Debug, Clone)]
pub struct TxQueue {
    buf: [u8; TX_QUEUE_LEN],
    head: usize,
    len: usize,
    next_seq: u16,
    dropped: u32,
}

impl TxQueue {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            buf: [0; TX_QUEUE_LEN],
            head: 0,
            len: 0,
            next_seq: 0,
            dropped: 0,
        }
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing waits.
    #[cfg(test)]
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

    /// Counts a frame that was never offered (a stream sample superseded before framing).
    pub fn note_dropped(&mut self) {
        self.dropped = self.dropped.saturating_add(1);
    }

    /// Encodes `msg` (a [`protocol::DeviceMessage`], or a legacy message such as
    /// [`protocol::LegacyV1Nack`]) and queues it if it fits with `reserve` bytes to spare.
    pub fn push<M: Serialize + ?Sized>(&mut self, msg: &M, reserve: usize) -> bool {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let mut scratch = [0u8; MAX_DEVICE_FRAME_SIZE];
        let fits = match encode_frame(seq, msg, &mut scratch) {
            Ok(frame) if frame.len() + reserve <= self.free() => {
                // At most two contiguous copies: up to the ring's end, then from its start.
                let tail = (self.head + self.len) % TX_QUEUE_LEN;
                let first = frame.len().min(TX_QUEUE_LEN - tail);
                let (a, b) = frame.split_at(first);
                self.buf[tail..tail + first].copy_from_slice(a);
                self.buf[..b.len()].copy_from_slice(b);
                self.len += frame.len();
                true
            }
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
        n
    }
}

impl Default for TxQueue {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
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
