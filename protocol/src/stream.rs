//! The continuous stream (issue 35): every control step's raw data at up to the ADC rate,
//! for as long as the host asks, in [`StreamBlock`]s of [`STREAM_BLOCK_SAMPLES`]
//! consecutive samples.
//!
//! A block carries the sequence number of its first sample and its samples packed as
//! deltas in zig-zag varints ([`StreamBlock::pack`], `LAYOUT.md` "Stream blocks"): the
//! first sample absolute, so each block decodes on its own and a lost frame costs only its
//! own samples. The host's [`StreamDecoder`] (feature `std`) checks the sequence numbers
//! end to end and reports exactly which samples were lost ([`StreamEvent::Lost`]).

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::sizes::{U16, U32, varint_len};

/// Samples per [`StreamBlock`]: at 10 kHz one block per control step (1,000 blocks/s).
/// The one place this size is stated.
pub const STREAM_BLOCK_SAMPLES: usize = 10;

/// The highest stream rate, Hz: the ADC rate, ten samples per 1 kHz control step. The
/// device streams at this rate divided by a whole number (10,000, 5,000, 2,500, 2,000,
/// 1,250, 1,000, ... 1 Hz) and refuses any other with [`crate::NackCode::StreamRate`].
pub const MAX_STREAM_RATE_HZ: u16 = 10_000;

/// [`StreamSample::duty`] per unit duty: 1 is 10,000 (0.01 % resolution).
pub const STREAM_DUTY_SCALE: f32 = 10_000.0;

/// [`StreamSample::tau_cam`] per N m: 1 count is 0.1 mN m (range +-3.2767 N m).
pub const STREAM_TAU_SCALE: f32 = 10_000.0;

/// Set in [`StreamSample::state`] while a fault is latched; the low bits are the
/// [`crate::SupervisorState`] variant index.
pub const STREAM_STATE_FAULTED: u8 = 0x80;

/// The highest rate at or below `rate_hz` that the stream supports (10 kHz divided by a
/// whole number); `None` for 0. What [`crate::NackCode::StreamRate`] names.
pub fn stream_rate_that_fits(rate_hz: u16) -> Option<u16> {
    if rate_hz == 0 {
        return None;
    }
    let asked = rate_hz.min(MAX_STREAM_RATE_HZ);
    // The smallest divisor d with 10 kHz / d <= asked, then up to the next exact divisor.
    let mut d = MAX_STREAM_RATE_HZ.div_ceil(asked);
    while !MAX_STREAM_RATE_HZ.is_multiple_of(d) {
        d += 1;
    }
    Some(MAX_STREAM_RATE_HZ / d)
}

/// One raw sample of the stream: what one ADC sample and its control step saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct StreamSample {
    /// Current-sensor ADC code, raw counts (12-bit; the host scales it with the board's
    /// sensor, as for a capture).
    pub current_adc: u16,
    /// Cam (vibrator) encoder, the low 16 bits of the unwrapped count: read at each control
    /// step and linearly interpolated between steps, as in a capture.
    pub cam_count: u16,
    /// Output-shaft encoder, the low 16 bits of its count, held per control step (0 without
    /// an output encoder: `Capabilities::OUTPUT_ENCODER` clear).
    pub output_count: u16,
    /// PWM duty of the step, times [`STREAM_DUTY_SCALE`] (sign: direction).
    pub duty: i16,
    /// The last revolution's tau_cam estimate, times [`STREAM_TAU_SCALE`] (0 before the
    /// first; saturates at the i16 range).
    pub tau_cam: i16,
    /// [`crate::StatusFlags`] bits of the step.
    pub status: u16,
    /// [`crate::SupervisorState`] index, plus [`STREAM_STATE_FAULTED`] with a fault latched.
    pub state: u8,
}

/// Bits of the mask byte of a sample whose held fields changed.
const CHANGED_OUTPUT: u8 = 1 << 0;
const CHANGED_DUTY: u8 = 1 << 1;
const CHANGED_TAU: u8 = 1 << 2;
const CHANGED_STATUS: u8 = 1 << 3;
const CHANGED_STATE: u8 = 1 << 4;
const CHANGED_ALL: u8 = 0x1F;
/// Bits of a sample's head varint below the current delta.
const HEAD_CAM: u32 = 1 << 1;
const HEAD_HELD: u32 = 1 << 0;

/// Largest first sample: three u16 varints, two zig-zag i16s, a u16 varint, the state byte.
const FIRST_SAMPLE_MAX: usize = 3 * U16 + 2 * U16 + U16 + 1;
/// Largest later sample: the head (a zig-zag i16 shifted by 2: 18 bits), the cam delta,
/// the mask byte, the output delta, two zig-zag deltas of i16s (17 bits), the status and the
/// state byte.
const LATER_SAMPLE_MAX: usize = varint_len(0x3_FFFF) + U16 + 1 + U16 + 2 * U16 + U16 + 1;

/// Largest packed block, bytes.
pub const STREAM_PACKED_MAX: usize =
    FIRST_SAMPLE_MAX + (STREAM_BLOCK_SAMPLES - 1) * LATER_SAMPLE_MAX;

/// [`STREAM_BLOCK_SAMPLES`] consecutive stream samples (fewer only in a stream's last
/// block), packed (see the module and `LAYOUT.md`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamBlock {
    /// Sequence number of the first sample: samples are numbered from 0 at `StartStream`,
    /// one per sample at the stream's rate, so a gap says exactly which samples were lost.
    pub first_seq: u32,
    /// The samples, packed by [`StreamBlock::pack`]: the first absolute, then deltas.
    pub packed: Vec<u8, STREAM_PACKED_MAX>,
}

/// Why a block's packed bytes do not decode (a sender bug: the frame's CRC was good).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnpackError;

impl core::fmt::Display for UnpackError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("a stream block's packed samples are truncated or too many")
    }
}

fn zigzag(v: i32) -> u32 {
    (v << 1).cast_unsigned() ^ (v >> 31).cast_unsigned()
}

fn unzigzag(v: u32) -> i32 {
    (v >> 1).cast_signed() ^ -((v & 1).cast_signed())
}

/// The signed difference `now - before` of two wrapping 16-bit counters.
fn wrapping_delta(now: u16, before: u16) -> i32 {
    i32::from(now.wrapping_sub(before).cast_signed())
}

struct Writer<'a>(&'a mut Vec<u8, STREAM_PACKED_MAX>);

impl Writer<'_> {
    fn byte(&mut self, b: u8) {
        // Cannot fail: the buffer holds the worst case (`STREAM_PACKED_MAX`).
        let _ = self.0.push(b);
    }

    fn varint(&mut self, mut v: u32) {
        while v >= 0x80 {
            self.byte(v.to_le_bytes()[0] | 0x80);
            v >>= 7;
        }
        self.byte(v.to_le_bytes()[0]);
    }
}

struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn byte(&mut self) -> Result<u8, UnpackError> {
        let (&b, rest) = self.0.split_first().ok_or(UnpackError)?;
        self.0 = rest;
        Ok(b)
    }

    /// A varint of at most 32 bits (5 bytes).
    fn varint(&mut self) -> Result<u32, UnpackError> {
        let mut v: u32 = 0;
        for shift in (0..35).step_by(7) {
            let b = self.byte()?;
            v |= u32::from(b & 0x7F).checked_shl(shift).ok_or(UnpackError)?;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(UnpackError)
    }

    fn u16(&mut self) -> Result<u16, UnpackError> {
        u16::try_from(self.varint()?).map_err(|_| UnpackError)
    }

    fn i16(&mut self) -> Result<i16, UnpackError> {
        i16::try_from(unzigzag(self.varint()?)).map_err(|_| UnpackError)
    }

    fn delta(&mut self) -> Result<i32, UnpackError> {
        Ok(unzigzag(self.varint()?))
    }
}

impl StreamBlock {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = U32 + varint_len(STREAM_PACKED_MAX as u64) + STREAM_PACKED_MAX;

    /// Packs `samples` (at most [`STREAM_BLOCK_SAMPLES`]; more are left out) whose first
    /// has sequence number `first_seq`.
    ///
    /// The first sample is absolute: `current_adc`, `cam_count`, `output_count` as
    /// varints, `duty`, `tau_cam` zig-zag, `status` a varint, `state` one byte. Each later
    /// sample is a head varint `zigzag(d_current) << 2 | cam << 1 | held`; then, when `cam`
    /// is set, the cam count's zig-zag (wrapping 16-bit) delta; when `held` is set, a mask
    /// byte (bit 0 output, 1 duty, 2 tau_cam, 3 status, 4 state) and, for each bit set, the
    /// output's wrapping delta, duty's and tau_cam's zig-zag deltas, the new status varint,
    /// the new state byte. Fields that did not change cost nothing: at 10 kHz a vibrating
    /// sample is 2 bytes.
    pub fn pack(first_seq: u32, samples: &[StreamSample]) -> Self {
        let mut packed = Vec::new();
        let mut w = Writer(&mut packed);
        let samples = &samples[..samples.len().min(STREAM_BLOCK_SAMPLES)];
        if let Some(first) = samples.first() {
            w.varint(u32::from(first.current_adc));
            w.varint(u32::from(first.cam_count));
            w.varint(u32::from(first.output_count));
            w.varint(zigzag(i32::from(first.duty)));
            w.varint(zigzag(i32::from(first.tau_cam)));
            w.varint(u32::from(first.status));
            w.byte(first.state);
        }
        for pair in samples.windows(2) {
            let (prev, s) = (&pair[0], &pair[1]);
            let d_current = wrapping_delta(s.current_adc, prev.current_adc);
            let d_cam = wrapping_delta(s.cam_count, prev.cam_count);
            let mut mask = 0;
            if s.output_count != prev.output_count {
                mask |= CHANGED_OUTPUT;
            }
            if s.duty != prev.duty {
                mask |= CHANGED_DUTY;
            }
            if s.tau_cam != prev.tau_cam {
                mask |= CHANGED_TAU;
            }
            if s.status != prev.status {
                mask |= CHANGED_STATUS;
            }
            if s.state != prev.state {
                mask |= CHANGED_STATE;
            }
            let mut head = zigzag(d_current) << 2;
            if d_cam != 0 {
                head |= HEAD_CAM;
            }
            if mask != 0 {
                head |= HEAD_HELD;
            }
            w.varint(head);
            if d_cam != 0 {
                w.varint(zigzag(d_cam));
            }
            if mask != 0 {
                w.byte(mask);
                if mask & CHANGED_OUTPUT != 0 {
                    w.varint(zigzag(wrapping_delta(s.output_count, prev.output_count)));
                }
                if mask & CHANGED_DUTY != 0 {
                    w.varint(zigzag(i32::from(s.duty) - i32::from(prev.duty)));
                }
                if mask & CHANGED_TAU != 0 {
                    w.varint(zigzag(i32::from(s.tau_cam) - i32::from(prev.tau_cam)));
                }
                if mask & CHANGED_STATUS != 0 {
                    w.varint(u32::from(s.status));
                }
                if mask & CHANGED_STATE != 0 {
                    w.byte(s.state);
                }
            }
        }
        Self { first_seq, packed }
    }

    /// The samples, decoded; an error when the packed bytes are truncated, hold more than
    /// [`STREAM_BLOCK_SAMPLES`] samples or a value outside its field.
    pub fn unpack(&self) -> Result<Vec<StreamSample, STREAM_BLOCK_SAMPLES>, UnpackError> {
        let mut out = Vec::new();
        let mut r = Reader(&self.packed);
        if r.0.is_empty() {
            return Ok(out);
        }
        let mut s = StreamSample {
            current_adc: r.u16()?,
            cam_count: r.u16()?,
            output_count: r.u16()?,
            duty: r.i16()?,
            tau_cam: r.i16()?,
            status: r.u16()?,
            state: r.byte()?,
        };
        out.push(s).map_err(|_| UnpackError)?;
        while !r.0.is_empty() {
            let head = r.varint()?;
            s.current_adc = add_wrapping(s.current_adc, unzigzag(head >> 2))?;
            if head & HEAD_CAM != 0 {
                s.cam_count = add_wrapping(s.cam_count, r.delta()?)?;
            }
            if head & HEAD_HELD != 0 {
                let mask = r.byte()?;
                if mask & !CHANGED_ALL != 0 {
                    return Err(UnpackError);
                }
                if mask & CHANGED_OUTPUT != 0 {
                    s.output_count = add_wrapping(s.output_count, r.delta()?)?;
                }
                if mask & CHANGED_DUTY != 0 {
                    s.duty = add_i16(s.duty, r.delta()?)?;
                }
                if mask & CHANGED_TAU != 0 {
                    s.tau_cam = add_i16(s.tau_cam, r.delta()?)?;
                }
                if mask & CHANGED_STATUS != 0 {
                    s.status = r.u16()?;
                }
                if mask & CHANGED_STATE != 0 {
                    s.state = r.byte()?;
                }
            }
            out.push(s).map_err(|_| UnpackError)?;
        }
        Ok(out)
    }
}

/// A wrapping 16-bit counter moved by `delta` (which must be a 16-bit difference).
fn add_wrapping(v: u16, delta: i32) -> Result<u16, UnpackError> {
    let d = i16::try_from(delta).map_err(|_| UnpackError)?;
    Ok(v.wrapping_add_signed(d))
}

fn add_i16(v: i16, delta: i32) -> Result<i16, UnpackError> {
    i16::try_from(i32::from(v) + delta).map_err(|_| UnpackError)
}

/// What the [`StreamDecoder`] found in a block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamEvent {
    /// A sample and its sequence number.
    Sample {
        /// The sample's sequence number.
        seq: u32,
        /// The sample.
        sample: StreamSample,
    },
    /// Samples `first_seq .. first_seq + count` never arrived (their frame was lost or
    /// corrupted on the line, or the device's queue was full).
    Lost {
        /// The first lost sample's sequence number.
        first_seq: u32,
        /// How many consecutive samples were lost.
        count: u32,
    },
}

/// The host's end of the stream: checks the sample sequence numbers of successive
/// [`StreamBlock`]s and yields every sample, or a [`StreamEvent::Lost`] naming exactly the
/// samples that never arrived. Loss is seen when the next block arrives; samples lost at
/// the very end of a stream show as [`StreamDecoder::expected_seq`] short of the count the
/// host expected.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StreamDecoder {
    next_seq: Option<u32>,
    /// Samples yielded.
    pub samples: u64,
    /// Samples reported lost.
    pub lost: u64,
    /// Blocks whose packed bytes did not decode (their samples are reported lost when the
    /// next block arrives).
    pub bad_blocks: u64,
    /// Times the sequence went backwards: the device started a new stream.
    pub restarts: u64,
}

impl StreamDecoder {
    /// A decoder for a new stream (sample numbers start at the first block's).
    pub const fn new() -> Self {
        Self {
            next_seq: None,
            samples: 0,
            lost: 0,
            bad_blocks: 0,
            restarts: 0,
        }
    }

    /// The sequence number the next sample should have (`None` before the first block).
    pub const fn expected_seq(&self) -> Option<u32> {
        self.next_seq
    }

    /// Takes the next block received: `emit` gets a `Lost` event for a gap before it,
    /// then its samples in order. A block that does not unpack yields nothing (counted in
    /// `bad_blocks`; the next block reports its samples lost).
    pub fn push(&mut self, block: &StreamBlock, mut emit: impl FnMut(StreamEvent)) {
        let Ok(samples) = block.unpack() else {
            self.bad_blocks += 1;
            return;
        };
        if let Some(expected) = self.next_seq {
            let gap = block.first_seq.wrapping_sub(expected);
            if gap >= 1 << 31 {
                // Behind the stream: the device started anew.
                self.restarts += 1;
            } else if gap > 0 {
                self.lost += u64::from(gap);
                emit(StreamEvent::Lost {
                    first_seq: expected,
                    count: gap,
                });
            }
        }
        let mut seq = block.first_seq;
        for sample in samples {
            emit(StreamEvent::Sample { seq, sample });
            seq = seq.wrapping_add(1);
            self.samples += 1;
        }
        self.next_seq = Some(seq);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_that_fit() {
        let fits = |r| stream_rate_that_fits(r);
        assert_eq!(fits(0), None);
        assert_eq!(fits(10_000), Some(10_000));
        assert_eq!(fits(65_535), Some(10_000));
        assert_eq!(fits(9_999), Some(5_000));
        assert_eq!(fits(3_000), Some(2_500));
        assert_eq!(fits(1_500), Some(1_250));
        assert_eq!(fits(1_000), Some(1_000));
        assert_eq!(fits(999), Some(625));
        assert_eq!(fits(3), Some(2));
        assert_eq!(fits(1), Some(1));
        for r in 1..=MAX_STREAM_RATE_HZ {
            let f = fits(r).unwrap();
            assert!(f <= r && MAX_STREAM_RATE_HZ.is_multiple_of(f), "{r}");
            assert_eq!(f == r, MAX_STREAM_RATE_HZ.is_multiple_of(r), "{r}");
        }
    }

    #[test]
    fn zigzag_matches_postcard() {
        for v in [
            0,
            -1,
            1,
            -2,
            i32::from(i16::MIN),
            i32::from(i16::MAX),
            65_535,
            -65_535,
        ] {
            assert_eq!(unzigzag(zigzag(v)), v);
            let mut buf = [0u8; 8];
            let mut p: Vec<u8, STREAM_PACKED_MAX> = Vec::new();
            Writer(&mut p).varint(zigzag(v));
            assert_eq!(postcard::to_slice(&v, &mut buf).unwrap(), &p[..], "{v}");
        }
    }

    #[test]
    fn worst_case_block_is_the_bound() {
        let (samples, block) = crate::golden::examples::worst_case_stream_block();
        assert_eq!(block.packed.len(), STREAM_PACKED_MAX);
        assert_eq!(block.unpack().unwrap(), &samples[..]);
        let mut buf = [0u8; 512];
        let bytes = postcard::to_slice(&block, &mut buf).unwrap();
        assert_eq!(bytes.len(), StreamBlock::MAX_WIRE_SIZE);
    }

    #[test]
    fn malformed_packing_is_refused() {
        let s = StreamSample::default();
        let mut block = StreamBlock::pack(0, &[s; STREAM_BLOCK_SAMPLES]);
        // An eleventh sample.
        block.packed.push(0).unwrap();
        assert_eq!(block.unpack(), Err(UnpackError));
        // A truncated first sample.
        let block = StreamBlock {
            first_seq: 0,
            packed: Vec::from_slice(&[1, 2]).unwrap(),
        };
        assert_eq!(block.unpack(), Err(UnpackError));
        // An unknown mask bit.
        let block = StreamBlock {
            first_seq: 0,
            packed: Vec::from_slice(&[0, 0, 0, 0, 0, 0, 0, 1, 0x20]).unwrap(),
        };
        assert_eq!(block.unpack(), Err(UnpackError));
        // An empty block has no samples.
        assert_eq!(StreamBlock::pack(5, &[]).unpack().unwrap().len(), 0);
    }

    #[test]
    fn decoder_names_lost_samples() {
        let s = StreamSample::default();
        let mut d = StreamDecoder::new();
        let mut events = std::vec::Vec::new();
        for first in [0u32, 10, 30, 40, 5] {
            d.push(&StreamBlock::pack(first, &[s; 10]), |e| events.push(e));
        }
        let lost: std::vec::Vec<_> = events
            .iter()
            .filter(|e| matches!(e, StreamEvent::Lost { .. }))
            .collect();
        assert_eq!(
            lost,
            [&StreamEvent::Lost {
                first_seq: 20,
                count: 10
            }]
        );
        assert_eq!((d.samples, d.lost, d.restarts), (50, 10, 1));
        assert_eq!(d.expected_seq(), Some(15));
    }
}
