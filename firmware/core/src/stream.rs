//! The continuous stream (issue 35): every ADC sample and its control step's state, sent
//! as `StreamBlock`s for as long as the host asks.
//!
//! The control step only copies its raw readings into a small ring of step records
//! ([`Stream::record`]: ten ADC codes and a few words, no packing); [`crate::Core::transmit`]
//! takes the records, decimates them to the stream's rate, interpolates the cam count
//! between steps (as the capture does), packs blocks and frames them ([`Stream::next_block`]),
//! outside the step. When the link falls behind and the ring is full, a step's samples
//! are skipped but still numbered, so the host sees exactly which samples were lost.

use protocol::{
    MAX_STREAM_RATE_HZ, NackCode, STREAM_BLOCK_SAMPLES, STREAM_DUTY_SCALE, STREAM_TAU_SCALE,
    StreamBlock, StreamSample, stream_rate_that_fits,
};

/// Control steps the ring holds between the step and the transmit path (4 ms of data:
/// the UART task asks for bytes far more often than that while the link is busy).
pub const STREAM_RING_STEPS: usize = 4;

/// [`STREAM_BLOCK_SAMPLES`] as a sample count (10: exact).
#[allow(
    clippy::cast_possible_truncation,
    reason = "checked below: the block size fits a byte"
)]
const BLOCK_SEQS: u32 = STREAM_BLOCK_SAMPLES as u32;
const _: () = assert!(STREAM_BLOCK_SAMPLES < 256);

/// ADC codes a step record keeps (the board takes ten per 1 ms step at 10 kHz); more in
/// one step are counted as skipped.
pub const STREAM_STEP_SAMPLES: usize = 10;

/// One control step's raw readings, as the step hands them over.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct StepRecord {
    /// The step's ADC codes, oldest first (`len` of them).
    pub(crate) adc: [u16; STREAM_STEP_SAMPLES],
    pub(crate) len: u8,
    /// Cam encoder (low 16 bits) at the previous step and at this one.
    pub(crate) cam_prev: u16,
    pub(crate) cam_now: u16,
    /// Output encoder (low 16 bits; 0 without one).
    pub(crate) output: u16,
    /// The duty commanded, -1..=1.
    pub(crate) duty: f32,
    /// The last revolution's tau_cam, N m (0 before the first).
    pub(crate) tau_cam_nm: f32,
    /// `StatusFlags` bits.
    pub(crate) status: u16,
    /// `SupervisorState` index, plus `STREAM_STATE_FAULTED`.
    pub(crate) state: u8,
    /// ADC samples skipped (ring full) just before this step's (set by `Stream::record`).
    pub(crate) skipped_before: u32,
}

/// The stream's state: the rate, the ring the step fills, and the block being packed.
#[derive(Debug, Clone)]
pub(crate) struct Stream {
    /// ADC samples per stream sample; 0: off.
    decimation: u32,
    rate_hz: u16,
    ring: [StepRecord; STREAM_RING_STEPS],
    ring_first: usize,
    ring_len: usize,
    /// ADC samples skipped since the last stored record.
    skipped: u32,
    /// ADC samples skipped since the stream started (for `Status`).
    skipped_total: u32,
    /// Pack side: the next ADC code of the oldest record, ADC samples to pass over before
    /// the next stream sample, the next sample's number, and the block so far.
    position: usize,
    countdown: u32,
    next_seq: u32,
    block: [StreamSample; STREAM_BLOCK_SAMPLES],
    block_len: usize,
    /// Device time of the last accepted request (the stream's heartbeat).
    last_request_us: u64,
}

impl Default for Stream {
    fn default() -> Self {
        Self {
            decimation: 0,
            rate_hz: 0,
            ring: [StepRecord::default(); STREAM_RING_STEPS],
            ring_first: 0,
            ring_len: 0,
            skipped: 0,
            skipped_total: 0,
            position: 0,
            countdown: 0,
            next_seq: 0,
            block: [StreamSample::default(); STREAM_BLOCK_SAMPLES],
            block_len: 0,
            last_request_us: 0,
        }
    }
}

/// The answer to `StartStream { rate_hz }` on a core sampling at `adc_hz`: the decimation
/// (ADC samples per stream sample), or the refusal. The stream's rates are 10 kHz divided
/// by a whole number (`BadArgument` for 0, `StreamRate` naming the rate that fits
/// otherwise); a core whose ADC rate is not a multiple of the rate asked refuses it with
/// `BadArgument` (the board's is 10 kHz: never).
pub(crate) fn stream_decimation(adc_hz: u32, rate_hz: u16) -> Result<u32, NackCode> {
    let fits = stream_rate_that_fits(rate_hz).ok_or(NackCode::BadArgument)?;
    if fits != rate_hz {
        return Err(NackCode::StreamRate { fits_hz: fits });
    }
    let rate = u32::from(rate_hz);
    if rate > adc_hz || !adc_hz.is_multiple_of(rate) || rate > u32::from(MAX_STREAM_RATE_HZ) {
        return Err(NackCode::BadArgument);
    }
    Ok(adc_hz / rate)
}

impl Stream {
    /// Whether the stream runs.
    pub(crate) const fn on(&self) -> bool {
        self.decimation > 0
    }

    /// The stream's rate, Hz (0: off).
    pub(crate) const fn rate_hz(&self) -> u16 {
        self.rate_hz
    }

    /// ADC samples skipped (ring full) since the stream started.
    pub(crate) const fn skipped_total(&self) -> u32 {
        self.skipped_total
    }

    /// Starts at `rate_hz` (`decimation` ADC samples per sample), numbering from 0; the
    /// running rate again changes nothing but the heartbeat.
    pub(crate) fn start(&mut self, rate_hz: u16, decimation: u32, now_us: u64) {
        if self.on() && self.rate_hz == rate_hz {
            self.last_request_us = now_us;
            return;
        }
        *self = Self {
            decimation,
            rate_hz,
            last_request_us: now_us,
            ..Self::default()
        };
    }

    /// Stops and forgets everything not yet sent.
    pub(crate) fn stop(&mut self) {
        *self = Self::default();
    }

    /// An accepted request at `now_us` keeps the stream alive.
    pub(crate) fn refresh(&mut self, now_us: u64) {
        self.last_request_us = now_us;
    }

    /// Stops the stream when no request was accepted for `timeout_us` (a host that went
    /// away); whether it stopped.
    pub(crate) fn check_timeout(&mut self, now_us: u64, timeout_us: u64) -> bool {
        if self.on() && now_us.saturating_sub(self.last_request_us) > timeout_us {
            self.stop();
            return true;
        }
        false
    }

    /// The control step's part: copies the step's readings into the ring (the ADC codes
    /// and the record's fields; nothing is packed here). A full ring skips the step's
    /// samples, which keep their numbers (the host sees them lost).
    pub(crate) fn record(&mut self, adc: &[u16], mut record: StepRecord) {
        if !self.on() {
            return;
        }
        let n = adc.len().min(STREAM_STEP_SAMPLES);
        let extra = u32::try_from(adc.len() - n).unwrap_or(u32::MAX);
        if self.ring_len == STREAM_RING_STEPS {
            let all = u32::try_from(adc.len()).unwrap_or(u32::MAX);
            self.skipped = self.skipped.saturating_add(all);
            self.skipped_total = self.skipped_total.saturating_add(all);
            return;
        }
        record.adc[..n].copy_from_slice(&adc[..n]);
        record.len = u8::try_from(n).unwrap_or(0);
        record.skipped_before = self.skipped;
        self.skipped = extra;
        self.skipped_total = self.skipped_total.saturating_add(extra);
        let slot = (self.ring_first + self.ring_len) % STREAM_RING_STEPS;
        self.ring[slot] = record;
        self.ring_len += 1;
    }

    /// The transmit path's part: the next full block from the records the steps left,
    /// or `None` when they do not fill one yet (the samples so far wait for the next
    /// call). At most one block per call: the work stays bounded.
    pub(crate) fn next_block(&mut self) -> Option<StreamBlock> {
        if !self.on() {
            return None;
        }
        while self.ring_len > 0 {
            let rec = self.ring[self.ring_first];
            if self.position == 0 && rec.skipped_before > 0 {
                self.pass_over(rec.skipped_before);
                self.ring[self.ring_first].skipped_before = 0;
            }
            let n = usize::from(rec.len);
            while self.position < n {
                let j = self.position;
                self.position += 1;
                if self.countdown > 0 {
                    self.countdown -= 1;
                    continue;
                }
                self.countdown = self.decimation - 1;
                self.block[self.block_len] = sample(&rec, j, n);
                self.block_len += 1;
                self.next_seq = self.next_seq.wrapping_add(1);
                if self.block_len == STREAM_BLOCK_SAMPLES {
                    self.block_len = 0;
                    let first = self.next_seq.wrapping_sub(BLOCK_SEQS);
                    return Some(StreamBlock::pack(first, &self.block));
                }
            }
            self.position = 0;
            self.ring_first = (self.ring_first + 1) % STREAM_RING_STEPS;
            self.ring_len -= 1;
        }
        None
    }

    /// Numbers `skipped` ADC samples that never reached the ring: the stream samples among
    /// them, and the block begun before them, are lost (the next block's number shows it).
    fn pass_over(&mut self, skipped: u32) {
        self.block_len = 0;
        if skipped <= self.countdown {
            self.countdown -= skipped;
            return;
        }
        let rest = skipped - self.countdown - 1;
        let lost = 1 + rest / self.decimation;
        self.countdown = self.decimation - 1 - rest % self.decimation;
        self.next_seq = self.next_seq.wrapping_add(lost);
    }
}

/// Stream sample `j` of the `n` in step record `rec`: the cam count interpolated linearly
/// from the previous step's reading, as in a capture.
fn sample(rec: &StepRecord, j: usize, n: usize) -> StreamSample {
    let delta = i32::from(rec.cam_now.wrapping_sub(rec.cam_prev).cast_signed());
    // j < n <= 10: exact in i32.
    let (j, n) = (
        i32::try_from(j + 1).unwrap_or(1),
        i32::try_from(n).unwrap_or(1),
    );
    let step = i16::try_from(delta * j / n).unwrap_or(0);
    StreamSample {
        current_adc: rec.adc[usize::try_from(j - 1).unwrap_or(0)],
        cam_count: rec.cam_prev.wrapping_add_signed(step),
        output_count: rec.output,
        duty: scaled(rec.duty, STREAM_DUTY_SCALE),
        tau_cam: scaled(rec.tau_cam_nm, STREAM_TAU_SCALE),
        status: rec.status,
        state: rec.state,
    }
}

/// `value * scale` rounded to the nearest i16, saturating (NaN: 0).
#[allow(
    clippy::cast_possible_truncation,
    reason = "float-to-int `as` saturates (NaN to 0), which is the intent"
)]
fn scaled(value: f32, scale: f32) -> i16 {
    let v = value * scale;
    (v + if v < 0.0 { -0.5 } else { 0.5 }) as i16
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    reason = "test fixtures: values in range by construction"
)]
mod tests {
    use super::*;

    fn record(step: u16) -> StepRecord {
        StepRecord {
            cam_prev: step.wrapping_mul(160),
            cam_now: step.wrapping_add(1).wrapping_mul(160),
            output: step,
            duty: 0.25,
            tau_cam_nm: -0.0312,
            status: 4,
            state: 2,
            ..StepRecord::default()
        }
    }

    fn adc(step: u16) -> [u16; 10] {
        core::array::from_fn(|j| 2000 + 10 * step + j as u16)
    }

    /// Runs `steps` steps through the stream, draining after each; the blocks sent.
    fn run(stream: &mut Stream, steps: core::ops::Range<u16>, drain: bool) -> Vec<StreamBlock> {
        let mut out = Vec::new();
        for k in steps {
            stream.record(&adc(k), record(k));
            while drain && let Some(b) = stream.next_block() {
                out.push(b);
            }
        }
        out
    }

    #[test]
    fn every_sample_at_10_khz_with_the_cam_interpolated() {
        let mut s = Stream::default();
        s.start(10_000, 1, 0);
        let blocks = run(&mut s, 0..3, true);
        assert_eq!(blocks.len(), 3);
        for (k, b) in blocks.iter().enumerate() {
            assert_eq!(b.first_seq, 10 * k as u32);
            let samples = b.unpack().unwrap();
            for (j, x) in samples.iter().enumerate() {
                assert_eq!(x.current_adc, 2000 + 10 * k as u16 + j as u16);
                // 160 counts a step: 16 a sample, the last sample at the step's reading.
                assert_eq!(x.cam_count, 160 * k as u16 + 16 * (j as u16 + 1));
                assert_eq!(x.output_count, k as u16);
                assert_eq!((x.duty, x.tau_cam, x.status, x.state), (2500, -312, 4, 2));
            }
        }
    }

    #[test]
    fn lower_rates_take_every_nth_sample_across_steps() {
        let mut s = Stream::default();
        // 2,500 Hz: every fourth ADC sample, the phase running on across steps.
        s.start(2_500, 4, 0);
        let blocks = run(&mut s, 0..8, true);
        assert_eq!(blocks.len(), 2);
        let adc_index: Vec<u16> = blocks
            .iter()
            .flat_map(|b| b.unpack().unwrap())
            .map(|x| x.current_adc - 2000)
            .collect();
        // ADC sample j of step k reads 2000 + 10 k + j: the stream's ADC samples 0, 4, 8,
        // 12 (step 1, j 2), ... read 2000 + their index.
        let expected: Vec<u16> = (0..20u16).map(|m| 4 * m).collect();
        assert_eq!(adc_index, expected);
        assert_eq!(blocks[1].first_seq, 10);
    }

    #[test]
    fn a_full_ring_skips_steps_and_the_numbers_say_so() {
        let mut s = Stream::default();
        s.start(10_000, 1, 0);
        // The link takes nothing for 6 steps: 4 are kept, 2 skipped.
        run(&mut s, 0..6, false);
        assert_eq!(s.skipped_total(), 20);
        let mut blocks = Vec::new();
        while let Some(b) = s.next_block() {
            blocks.push(b);
        }
        blocks.extend(run(&mut s, 6..8, true));
        let firsts: Vec<u32> = blocks.iter().map(|b| b.first_seq).collect();
        // Steps 0-3 sent, 4 and 5 (samples 40..60) lost, 6 and 7 sent as 60 and 70.
        assert_eq!(firsts, [0, 10, 20, 30, 60, 70]);
        assert_eq!(blocks[4].unpack().unwrap()[0].current_adc, 2060);
    }

    #[test]
    fn skipped_samples_keep_the_decimation_phase() {
        let mut s = Stream::default();
        s.start(1_250, 8, 0);
        s.countdown = 3;
        s.block_len = 4;
        s.next_seq = 4;
        // ADC samples 0-2 passed over, 3 taken (seq 4), 4-10 passed, 11 taken (seq 5),
        // 12 passed: 6 more to pass before the next; the 4 samples of the block lost.
        s.pass_over(13);
        assert_eq!((s.next_seq, s.countdown, s.block_len), (6, 6, 0));
        s.pass_over(2);
        assert_eq!((s.next_seq, s.countdown), (6, 4));
    }

    #[test]
    fn rates_are_checked() {
        assert_eq!(stream_decimation(10_000, 10_000), Ok(1));
        assert_eq!(stream_decimation(10_000, 1), Ok(10_000));
        assert_eq!(stream_decimation(10_000, 625), Ok(16));
        assert_eq!(stream_decimation(10_000, 0), Err(NackCode::BadArgument));
        assert_eq!(
            stream_decimation(10_000, 3_000),
            Err(NackCode::StreamRate { fits_hz: 2_500 })
        );
        assert_eq!(
            stream_decimation(10_000, 20_000),
            Err(NackCode::StreamRate { fits_hz: 10_000 })
        );
        assert_eq!(stream_decimation(5_000, 10_000), Err(NackCode::BadArgument));
    }

    #[test]
    fn scaling_rounds_and_saturates() {
        assert_eq!(scaled(0.25, STREAM_DUTY_SCALE), 2_500);
        assert_eq!(scaled(-0.00005, STREAM_DUTY_SCALE), -1);
        assert_eq!(scaled(9.0, STREAM_TAU_SCALE), i16::MAX);
        assert_eq!(scaled(f32::NAN, STREAM_TAU_SCALE), 0);
    }
}
