//! Raw capture: records the current ADC and the encoder at up to the ADC rate into a fixed
//! buffer, then uploads it as `CaptureChunk`s and a `CaptureDone`.
//!
//! The buffer holds [`CAPTURE_CAPACITY`] samples of 4 bytes (ADC code, low 16 bits of the
//! unwrapped encoder position): 40 000 bytes, 1.0 s at 10 kHz. The encoder is read once
//! per control step; the samples in between get a linear interpolation of it. Sample
//! rates below [`MIN_SAMPLE_RATE_HZ`] are refused so that the 16-bit encoder difference
//! between two samples cannot wrap (150 rad/s moves ~2000 counts in 10 ms).
//!
//! The output encoder (when fitted) costs no memory: a per-sample count would need 20 000
//! more bytes, and even 1 000 readings grew the core's boot-time stack temporary past the
//! stack. It rides in the 4 bits the 12-bit ADC code leaves free: the output is read at a
//! control step and held for a group of samples; the group's first sample has the top bit
//! set and its first [`OUTPUT_GROUP_MIN`] samples carry the 16-bit reading, 3 bits each.
//! A new group starts at the first sample of a control step once the group has
//! [`OUTPUT_GROUP_MIN`] samples: at 10 kHz (ten samples a step) every step, at 1 kHz
//! and below every 6 samples. The last group's reading, which may have fewer samples,
//! is also kept whole. Between two readings the output turns far less than 32 768 counts
//! (20 rad/s, the overspeed limit, is 1 565 counts in the 60 ms of 6 samples at the lowest
//! rate, 100 Hz), so the 16-bit difference cannot wrap.

use protocol::{CAPTURE_CHUNK_SAMPLES, CaptureChunk, CaptureSample, DeviceMessage, NackCode};

/// Samples the capture buffer holds (1.0 s at 10 kHz).
pub const CAPTURE_CAPACITY: usize = 10_000;
/// Lowest capture sample rate, Hz.
pub const MIN_SAMPLE_RATE_HZ: u16 = 100;
/// Fewest samples per output reading (its 16 bits, 3 per sample).
pub const OUTPUT_GROUP_MIN: u32 = 6;
/// ADC code bits of a stored sample (the ADC is 12-bit); the rest carry the output.
const ADC_MASK: u16 = 0x0FFF;
/// Set on the first sample of an output group.
const GROUP_START: u16 = 0x8000;

/// One stored sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[repr(C)]
struct RawSample {
    adc: u16,
    encoder: u16,
}

/// What the capture is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CapturePhase {
    /// Nothing to do.
    Idle,
    /// Filling the buffer from the control steps.
    Recording,
    /// Sending the buffer to the host.
    Uploading,
}

/// A capture accepted by [`Capture::start`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CapturePlan {
    /// Capture id.
    pub id: u16,
    /// Samples it will record (as asked).
    pub samples: u32,
    /// Sample rate, Hz (as asked).
    pub sample_rate_hz: u16,
}

/// The capture recorder and uploader.
#[derive(Debug, Clone)]
pub struct Capture {
    phase: CapturePhase,
    id: u16,
    decimation: u32,
    countdown: u32,
    sample_rate_hz: u16,
    total: u32,
    recorded: u32,
    sent: u32,
    upload_position: i32,
    upload_last_raw: u16,
    buf: [RawSample; CAPTURE_CAPACITY],
    /// First sample of the current output group, and its reading.
    group_start: u32,
    output_hold: u16,
    /// Whether an output encoder was read at the capture's first sample.
    output_fitted: bool,
    upload_output_position: i32,
    upload_output_last_raw: u16,
}

impl Capture {
    /// Writes [`Capture::new`] into `p` in place: the small fields one by one, the buffer
    /// zero-filled where it lies (a [`RawSample`] of zeros is its default), so the 40 000 B
    /// never pass through a stack temporary ([`crate::Core::new_in`]).
    ///
    /// # Safety
    /// `p` must be valid for writes and aligned for a `Capture`; what it held is
    /// overwritten without being dropped.
    #[allow(unsafe_code)]
    pub(crate) unsafe fn init_in(p: *mut Self) {
        use core::ptr::addr_of_mut;
        // SAFETY: the caller's contract; each field is written once through a raw pointer.
        // `RawSample` is two `u16`, for which all-zero bytes are a valid (the default) value.
        unsafe {
            addr_of_mut!((*p).phase).write(CapturePhase::Idle);
            addr_of_mut!((*p).id).write(0);
            addr_of_mut!((*p).decimation).write(1);
            addr_of_mut!((*p).countdown).write(0);
            addr_of_mut!((*p).sample_rate_hz).write(0);
            addr_of_mut!((*p).total).write(0);
            addr_of_mut!((*p).recorded).write(0);
            addr_of_mut!((*p).sent).write(0);
            addr_of_mut!((*p).upload_position).write(0);
            addr_of_mut!((*p).upload_last_raw).write(0);
            addr_of_mut!((*p).buf).write_bytes(0, 1);
            addr_of_mut!((*p).group_start).write(0);
            addr_of_mut!((*p).output_hold).write(0);
            addr_of_mut!((*p).output_fitted).write(false);
            addr_of_mut!((*p).upload_output_position).write(0);
            addr_of_mut!((*p).upload_output_last_raw).write(0);
        }
        // Every field of `Capture`, written above (a compile-time check, never run).
        const _: fn(Capture) = |c| {
            let Capture {
                phase: _,
                id: _,
                decimation: _,
                countdown: _,
                sample_rate_hz: _,
                total: _,
                recorded: _,
                sent: _,
                upload_position: _,
                upload_last_raw: _,
                buf: _,
                group_start: _,
                output_hold: _,
                output_fitted: _,
                upload_output_position: _,
                upload_output_last_raw: _,
            } = c;
        };
    }

    /// An idle capture with an empty buffer.
    pub fn new() -> Self {
        Self {
            phase: CapturePhase::Idle,
            id: 0,
            decimation: 1,
            countdown: 0,
            sample_rate_hz: 0,
            total: 0,
            recorded: 0,
            sent: 0,
            upload_position: 0,
            upload_last_raw: 0,
            buf: [RawSample::default(); CAPTURE_CAPACITY],
            group_start: 0,
            output_hold: 0,
            output_fitted: false,
            upload_output_position: 0,
            upload_output_last_raw: 0,
        }
    }

    /// What the capture is doing.
    pub fn phase(&self) -> CapturePhase {
        self.phase
    }

    /// Starts recording `samples` at `sample_rate_hz`, from an ADC running at `adc_hz`.
    /// Refused with `BadArgument` (never rounded or capped) unless the rate is `adc_hz`
    /// divided by a whole number and at least [`MIN_SAMPLE_RATE_HZ`], and `samples` is
    /// 1..=[`CAPTURE_CAPACITY`]; with `Busy` while a capture records or uploads.
    pub fn start(
        &mut self,
        sample_rate_hz: u16,
        samples: u32,
        adc_hz: u32,
    ) -> Result<CapturePlan, NackCode> {
        if self.phase != CapturePhase::Idle {
            return Err(NackCode::Busy);
        }
        let rate = u32::from(sample_rate_hz);
        let capacity = u32::try_from(CAPTURE_CAPACITY).unwrap_or(u32::MAX);
        if samples == 0
            || samples > capacity
            || sample_rate_hz < MIN_SAMPLE_RATE_HZ
            || rate > adc_hz
            || !adc_hz.is_multiple_of(rate)
        {
            return Err(NackCode::BadArgument);
        }
        self.decimation = adc_hz / rate;
        self.sample_rate_hz = sample_rate_hz;
        self.id = self.id.wrapping_add(1);
        self.total = samples;
        self.recorded = 0;
        self.sent = 0;
        self.countdown = 0;
        self.group_start = 0;
        self.output_fitted = false;
        self.phase = CapturePhase::Recording;
        Ok(CapturePlan {
            id: self.id,
            samples: self.total,
            sample_rate_hz: self.sample_rate_hz,
        })
    }

    /// Records one control step: its ADC samples, the encoder position (low 16 bits of
    /// the unwrapped count) at the previous and at this step, and the output encoder's
    /// position at this step (low 16 bits; `None` without an output encoder).
    pub fn record_step(
        &mut self,
        adc: &[u16],
        encoder_prev: u16,
        encoder_now: u16,
        output_now: Option<u16>,
    ) {
        if self.phase != CapturePhase::Recording || adc.is_empty() {
            return;
        }
        let delta = i32::from(encoder_now.wrapping_sub(encoder_prev).cast_signed());
        let n = i32::try_from(adc.len()).unwrap_or(i32::MAX);
        let mut first_in_step = true;
        for (j, &code) in adc.iter().enumerate() {
            if self.countdown > 0 {
                self.countdown -= 1;
                continue;
            }
            self.countdown = self.decimation - 1;
            let step = delta * i32::try_from(j + 1).unwrap_or(n) / n;
            let i = self.recorded;
            let starts = i == 0 || (first_in_step && i - self.group_start >= OUTPUT_GROUP_MIN);
            first_in_step = false;
            if starts {
                if i == 0 {
                    self.output_fitted = output_now.is_some();
                }
                self.group_start = i;
                self.output_hold = output_now.unwrap_or(0);
            }
            let k = i - self.group_start;
            let bits = if k < OUTPUT_GROUP_MIN {
                ((self.output_hold >> (3 * k)) & 0x7) << 12
            } else {
                0
            };
            self.buf[i as usize] = RawSample {
                adc: (code & ADC_MASK) | bits | if starts { GROUP_START } else { 0 },
                // |step| <= |delta|, an i16.
                encoder: encoder_prev.wrapping_add_signed(i16::try_from(step).unwrap_or(0)),
            };
            self.recorded += 1;
            if self.recorded == self.total {
                self.phase = CapturePhase::Uploading;
                self.upload_position = 0;
                self.upload_last_raw = self.buf[0].encoder;
                self.upload_output_position = 0;
                self.upload_output_last_raw = self.reading_at(0);
                return;
            }
        }
    }

    /// The output reading of the group starting at sample `start`: from its samples, or
    /// kept whole for the last group (which may be shorter).
    fn reading_at(&self, start: u32) -> u16 {
        let end = start + OUTPUT_GROUP_MIN;
        if end > self.total {
            return self.output_hold;
        }
        (0..OUTPUT_GROUP_MIN).fold(0u16, |acc, k| {
            let bits = (self.buf[(start + k) as usize].adc >> 12) & 0x7;
            acc | (bits << (3 * k))
        })
    }

    /// The next upload message (chunks, then `CaptureDone`), or `None` when not uploading.
    pub fn next_message(&mut self) -> Option<DeviceMessage> {
        if self.phase != CapturePhase::Uploading {
            return None;
        }
        if self.sent == self.total {
            self.phase = CapturePhase::Idle;
            return Some(DeviceMessage::CaptureDone {
                capture_id: self.id,
                total_samples: self.total,
                sample_rate_hz: self.sample_rate_hz,
            });
        }
        let mut chunk = CaptureChunk {
            capture_id: self.id,
            first_sample: self.sent,
            total_samples: self.total,
            samples: heapless::Vec::new(),
        };
        let end = (self.sent as usize + CAPTURE_CHUNK_SAMPLES).min(self.total as usize);
        for (index, raw) in (self.sent..).zip(&self.buf[self.sent as usize..end]) {
            let delta = raw.encoder.wrapping_sub(self.upload_last_raw).cast_signed();
            self.upload_last_raw = raw.encoder;
            self.upload_position = self.upload_position.wrapping_add(i32::from(delta));
            if raw.adc & GROUP_START != 0 {
                let now = self.reading_at(index);
                let delta = now.wrapping_sub(self.upload_output_last_raw).cast_signed();
                self.upload_output_last_raw = now;
                self.upload_output_position =
                    self.upload_output_position.wrapping_add(i32::from(delta));
            }
            let output_count = self.output_fitted.then_some(self.upload_output_position);
            // Cannot fail: the chunk holds CAPTURE_CHUNK_SAMPLES and `end` bounds the run.
            let _ = chunk.samples.push(CaptureSample {
                current_adc: raw.adc & ADC_MASK,
                encoder_count: self.upload_position,
                output_count,
            });
        }
        self.sent = u32::try_from(end).unwrap_or(self.total);
        Some(DeviceMessage::CaptureChunk(chunk))
    }
}

impl Default for Capture {
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

    #[test]
    #[allow(unsafe_code)]
    fn a_capture_built_in_place_is_a_new_one_whatever_the_slot_held() {
        // `Core::new_in`'s path: the slot's old bytes (here 0xAA) never show through.
        let mut slot = Box::new(core::mem::MaybeUninit::<Capture>::uninit());
        // SAFETY: a byte fill of the slot's own memory, then `init_in` writes every field.
        let built = unsafe {
            slot.as_mut_ptr().write_bytes(0xAA, 1);
            Capture::init_in(slot.as_mut_ptr());
            slot.assume_init_ref()
        };
        assert_eq!(format!("{built:?}"), format!("{:?}", Capture::new()));
    }

    fn upload(c: &mut Capture) -> (Vec<CaptureSample>, Option<DeviceMessage>) {
        let mut samples = Vec::new();
        loop {
            match c.next_message() {
                Some(DeviceMessage::CaptureChunk(chunk)) => {
                    assert_eq!(chunk.first_sample as usize, samples.len());
                    samples.extend(chunk.samples);
                }
                done => return (samples, done),
            }
        }
    }

    #[test]
    fn records_interpolated_encoder_and_uploads_in_order() {
        let mut c = Capture::new();
        let plan = c.start(10_000, 100, 10_000).unwrap();
        assert_eq!(plan.samples, 100);
        assert_eq!(c.start(10_000, 100, 10_000), Err(NackCode::Busy));
        let mut enc = 65_500u16;
        for k in 0..10u16 {
            let next = enc.wrapping_add(20);
            c.record_step(&[k; 10], enc, next, None);
            enc = next;
        }
        assert_eq!(c.phase(), CapturePhase::Uploading);
        let (samples, done) = upload(&mut c);
        assert_eq!(samples.len(), 100);
        assert_eq!(samples[0].encoder_count, 0);
        // 20 counts per 10 samples: 2 per sample, across the 16-bit wrap.
        assert_eq!(samples[99].encoder_count, 198);
        assert_eq!(samples[55].current_adc, 5);
        assert!(
            samples.iter().all(|s| s.output_count.is_none()),
            "no output encoder"
        );
        assert_eq!(
            done,
            Some(DeviceMessage::CaptureDone {
                capture_id: plan.id,
                total_samples: 100,
                sample_rate_hz: 10_000
            })
        );
        assert_eq!(c.phase(), CapturePhase::Idle);
    }

    #[test]
    fn decimates_and_refuses_what_it_cannot_do_exactly() {
        let mut c = Capture::new();
        assert_eq!(c.start(50, 10, 10_000), Err(NackCode::BadArgument));
        assert_eq!(c.start(1000, 0, 10_000), Err(NackCode::BadArgument));
        // Never rounded to a divisor nor capped to the buffer: refused.
        assert_eq!(c.start(3000, 100, 10_000), Err(NackCode::BadArgument));
        assert_eq!(c.start(20_000, 100, 10_000), Err(NackCode::BadArgument));
        let over = CAPTURE_CAPACITY as u32 + 1;
        assert_eq!(c.start(10_000, over, 10_000), Err(NackCode::BadArgument));
        assert_eq!(c.phase(), CapturePhase::Idle, "a refusal has no effect");
        let plan = c.start(2500, CAPTURE_CAPACITY as u32, 10_000).unwrap();
        assert_eq!(plan.samples, CAPTURE_CAPACITY as u32);
        assert_eq!(plan.sample_rate_hz, 2500);
        let mut c = Capture::new();
        c.start(1000, 5, 10_000).unwrap();
        for k in 0..5u16 {
            c.record_step(&[k * 10, 1, 2, 3, 4, 5, 6, 7, 8, 9], 0, 0, None);
        }
        let (samples, _) = upload(&mut c);
        let adc: Vec<u16> = samples.iter().map(|s| s.current_adc).collect();
        assert_eq!(adc, [0, 10, 20, 30, 40]);
    }

    /// Output counts of `k` steps at `per_step` counts per step from `start`, 16-bit.
    fn output_at(start: u16, per_step: i32, k: u32) -> u16 {
        start.wrapping_add_signed((per_step * k as i32) as i16)
    }

    #[test]
    fn output_is_read_every_step_of_a_full_10_khz_capture_and_held_between() {
        let mut c = Capture::new();
        c.start(10_000, CAPTURE_CAPACITY as u32, 10_000).unwrap();
        // The output turns 3 counts per step backwards, from just above the 16-bit wrap.
        let start = 40u16;
        for k in 0..1000u32 {
            c.record_step(&[7; 10], 0, 0, Some(output_at(start, -3, k)));
        }
        let (samples, _) = upload(&mut c);
        assert_eq!(samples.len(), CAPTURE_CAPACITY);
        for (i, s) in samples.iter().enumerate() {
            // Held over the step's ten samples, counted from the capture's start.
            assert_eq!(s.output_count, Some(-3 * (i as i32 / 10)), "sample {i}");
        }
    }

    #[test]
    fn a_long_capture_reads_the_output_once_per_group_and_a_still_output_is_constant() {
        let mut c = Capture::new();
        // 10 000 samples at 100 Hz: 100 s, one sample per 10 steps, one reading per 6
        // samples (60 steps); the last group (10 000 = 6 x 1666 + 4) is short.
        c.start(100, CAPTURE_CAPACITY as u32, 10_000).unwrap();
        let mut k = 0u32;
        while c.phase() == CapturePhase::Recording {
            c.record_step(&[1; 10], 0, 0, Some(output_at(65_000, 5, k)));
            k += 1;
        }
        // The last sample is taken at step 99 990.
        assert_eq!(k, 99_991);
        let (samples, _) = upload(&mut c);
        for (i, s) in samples.iter().enumerate() {
            // Sample i is taken at step 10 i; its group's reading at step 60 (i / 6).
            assert_eq!(s.output_count, Some(5 * 60 * (i as i32 / 6)), "sample {i}");
        }
        let mut c = Capture::new();
        c.start(1000, 500, 10_000).unwrap();
        for _ in 0..500 {
            c.record_step(&[1; 10], 0, 0, Some(12_345));
        }
        let (samples, _) = upload(&mut c);
        assert_eq!(samples.len(), 500);
        assert!(samples.iter().all(|s| s.output_count == Some(0)));
    }
}
