//! Raw high-rate captures: recorded in the device's buffer, uploaded in chunks, checked for
//! continuity here, and converted to amps and radians with the board's scale factors.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use model::plant::SensorParams;
use protocol::{CaptureSample, DeviceMessage, Request};

use super::Client;
use crate::RigError;

/// The paper's logging rate (Elmos RAI-16), Hz.
pub const CAPTURE_RATE_HZ: u16 = 10_000;

/// How long an upload may stall between chunks before the capture is given up, wall clock.
const CHUNK_STALL: Duration = Duration::from_secs(2);

/// How often a capture looks at its stop flag while it waits, wall clock.
const STOP_POLL: Duration = Duration::from_millis(20);

/// The board's sensor chain, the one place its scale factors live: ACS714 at 185 mV/A with
/// its zero at Vcc/2 of 5 V, a 2/3 divider into the 3.3 V 12-bit ADC, and the AMT102-V
/// encoder at 2048 pulses (8192 quadrature counts) per cam turn. The firmware and the
/// simulated plant use the same [`SensorParams`].
pub fn board_sensors() -> SensorParams {
    SensorParams::default()
}

/// Motor current for a raw ADC code, A (nominal zero at mid-supply, no re-zero offset).
pub fn current_amps(adc: u16) -> f64 {
    board_sensors().adc_to_current(adc)
}

/// Cam angle for a quadrature count, rad.
pub fn cam_angle_rad(counts: i32) -> f64 {
    f64::from(counts) / f64::from(board_sensors().counts_per_rev()) * std::f64::consts::TAU
}

/// Output-shaft angle for an output-encoder count, rad: the board's output encoder is an
/// AMT102-V at 2048 pulses per revolution as on the cam (`firmware::board::OUTPUT_ENCODER`,
/// and the virtual rig's), so the same counts per revolution; the monitor's `output_rad`
/// has the same unit.
pub fn output_angle_rad(counts: i32) -> f64 {
    f64::from(counts) / f64::from(model::hardware::amt102::COUNTS_PER_REV) * std::f64::consts::TAU
}

/// Upload progress of a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureProgress {
    /// Samples received so far.
    pub received: u32,
    /// Samples the device recorded (the request until the first chunk says otherwise).
    pub total: u32,
}

/// A received capture.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Capture {
    /// The device's id of this capture.
    pub capture_id: u16,
    /// Sample rate the device recorded at, Hz.
    pub sample_rate_hz: u16,
    /// Samples asked for.
    pub requested: u32,
    /// Samples the device recorded (fewer than asked when its buffer is smaller).
    pub total_samples: u32,
    /// Samples received, with their index in the capture, in order.
    #[serde(skip)]
    pub samples: Vec<(u32, CaptureSample)>,
    /// Samples that never arrived (gaps between chunks and a missing tail).
    pub dropped: u32,
    /// Number of gaps.
    pub gaps: u32,
    /// Samples received twice (overlapping chunks), kept once.
    pub duplicates: u32,
    /// Whether the device's `CaptureDone` arrived.
    pub completed: bool,
}

impl Capture {
    /// Duration of the recording, s.
    pub fn duration_s(&self) -> f64 {
        f64::from(self.total_samples) / f64::from(self.sample_rate_hz.max(1))
    }

    /// Mean current of the received samples, A.
    pub fn mean_current_a(&self) -> Option<f64> {
        let n = self.samples.len();
        (n > 0).then(|| {
            self.samples
                .iter()
                .map(|(_, s)| current_amps(s.current_adc))
                .sum::<f64>()
                / n as f64
        })
    }

    /// Mean cam speed from the first and last received encoder counts, rad/s.
    pub fn mean_cam_speed_rad_s(&self) -> Option<f64> {
        let (i0, first) = self.samples.first()?;
        let (i1, last) = self.samples.last()?;
        (i1 > i0).then(|| {
            let dt = f64::from(i1 - i0) / f64::from(self.sample_rate_hz.max(1));
            (cam_angle_rad(last.encoder_count) - cam_angle_rad(first.encoder_count)) / dt
        })
    }

    /// Mean output-shaft speed from the first and last received output counts, rad/s
    /// (`None` without an output encoder).
    pub fn mean_output_speed_rad_s(&self) -> Option<f64> {
        let (i0, first) = self.samples.first()?;
        let (i1, last) = self.samples.last()?;
        let (c0, c1) = (first.output_count?, last.output_count?);
        (i1 > i0).then(|| {
            let dt = f64::from(i1 - i0) / f64::from(self.sample_rate_hz.max(1));
            (output_angle_rad(c1) - output_angle_rad(c0)) / dt
        })
    }

    /// Writes the samples as CSV:
    /// `index,t_s,current_adc,current_a,encoder_count,cam_angle_rad,output_count,output_angle_rad`.
    /// The output columns (counts and rad since the capture started, read at a control
    /// step and held) are empty when the device has no output encoder.
    pub fn write_csv<W: Write>(&self, out: W) -> Result<(), csv::Error> {
        let mut w = csv::Writer::from_writer(out);
        w.write_record([
            "index",
            "t_s",
            "current_adc",
            "current_a",
            "encoder_count",
            "cam_angle_rad",
            "output_count",
            "output_angle_rad",
        ])?;
        let rate = f64::from(self.sample_rate_hz.max(1));
        for (i, s) in &self.samples {
            w.write_record([
                i.to_string(),
                format!("{:.6}", f64::from(*i) / rate),
                s.current_adc.to_string(),
                format!("{:.5}", current_amps(s.current_adc)),
                s.encoder_count.to_string(),
                format!("{:.6}", cam_angle_rad(s.encoder_count)),
                s.output_count.map(|c| c.to_string()).unwrap_or_default(),
                s.output_count
                    .map(|c| format!("{:.6}", output_angle_rad(c)))
                    .unwrap_or_default(),
            ])?;
        }
        w.flush()?;
        Ok(())
    }
}

/// Continuity bookkeeping while chunks arrive.
#[derive(Debug)]
struct Assembly {
    capture: Capture,
    next: u32,
    id: Option<u16>,
}

impl Assembly {
    fn add(&mut self, chunk: protocol::CaptureChunk) {
        if *self.id.get_or_insert(chunk.capture_id) != chunk.capture_id {
            return; // a chunk of another capture (an old upload still draining)
        }
        let c = &mut self.capture;
        c.capture_id = chunk.capture_id;
        c.total_samples = chunk.total_samples;
        if chunk.first_sample > self.next {
            c.dropped += chunk.first_sample - self.next;
            c.gaps += 1;
        }
        for (index, sample) in (chunk.first_sample..).zip(chunk.samples) {
            if index < self.next {
                c.duplicates += 1;
            } else {
                c.samples.push((index, sample));
                self.next = index + 1;
            }
        }
    }

    fn finish(mut self, total: Option<u32>, rate: Option<u16>) -> Capture {
        let c = &mut self.capture;
        if let Some(total) = total {
            c.total_samples = total;
            c.completed = true;
        }
        if let Some(rate) = rate {
            c.sample_rate_hz = rate;
        }
        if c.total_samples > self.next {
            c.dropped += c.total_samples - self.next;
            c.gaps += 1;
        }
        self.capture
    }
}

impl<T: Read + Write> Client<T> {
    /// Records `samples` samples at `sample_rate_hz` on the device and uploads them,
    /// reporting upload progress. Gaps are counted in [`Capture::dropped`], not errors; a
    /// capture that never starts or stalls is an error.
    pub fn capture(
        &mut self,
        sample_rate_hz: u16,
        samples: u32,
        progress: impl FnMut(CaptureProgress),
    ) -> Result<Capture, RigError> {
        self.capture_until(sample_rate_hz, samples, progress, &AtomicBool::new(false))
    }

    /// As [`Client::capture`], stopped by `stop` (a signal's flag): once it is raised the
    /// gear is locked at once (`Release(off)`: vibration off) and the upload goes on, so
    /// every sample the device recorded, the lock's transient included, is kept.
    pub fn capture_until(
        &mut self,
        sample_rate_hz: u16,
        samples: u32,
        mut progress: impl FnMut(CaptureProgress),
        stop: &AtomicBool,
    ) -> Result<Capture, RigError> {
        self.ack(&Request::StartCapture {
            sample_rate_hz,
            samples,
        })?;
        let recording = f64::from(samples) / f64::from(sample_rate_hz.max(1));
        let mut deadline = Instant::now()
            + crate::limits::wall_duration(recording, self.options().time_scale.max(1e-3))
            + CHUNK_STALL
            + self.options().reply_timeout;
        let mut assembly = Assembly {
            capture: Capture {
                capture_id: 0,
                sample_rate_hz,
                requested: samples,
                total_samples: samples,
                samples: Vec::with_capacity(samples as usize),
                dropped: 0,
                gaps: 0,
                duplicates: 0,
                completed: false,
            },
            next: 0,
            id: None,
        };
        let mut locked = false;
        loop {
            if !locked && stop.load(Ordering::SeqCst) {
                locked = true;
                self.release(false, 0.0)?;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            // Short waits, so a raised `stop` locks the gear within one of them.
            let wait = left.min(STOP_POLL);
            match self.recv(wait)? {
                Some(DeviceMessage::CaptureChunk(chunk)) => {
                    assembly.add(chunk);
                    deadline = Instant::now() + CHUNK_STALL;
                    progress(CaptureProgress {
                        received: assembly.capture.samples.len() as u32,
                        total: assembly.capture.total_samples,
                    });
                }
                Some(DeviceMessage::CaptureDone {
                    capture_id,
                    total_samples,
                    sample_rate_hz,
                }) if assembly.id.is_none_or(|id| id == capture_id) => {
                    return Ok(assembly.finish(Some(total_samples), Some(sample_rate_hz)));
                }
                Some(_) => {}
                None if wait < left => {}
                None if assembly.id.is_some() => {
                    // The upload stalled: keep what came, the missing tail counts as dropped.
                    return Ok(assembly.finish(None, None));
                }
                None => {
                    return Err(RigError::NoReply {
                        port: self.options().port_name.clone(),
                        request: "StartCapture",
                        waited_ms: (recording * 1000.0) as u64 + CHUNK_STALL.as_millis() as u64,
                        tries: 1,
                        hint: "the device acknowledged the capture but sent no samples: check `rig faults`".into(),
                    });
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::CaptureChunk;

    fn chunk(first: u32, n: u32, total: u32) -> CaptureChunk {
        CaptureChunk {
            capture_id: 3,
            first_sample: first,
            total_samples: total,
            samples: (0..n)
                .map(|i| CaptureSample {
                    current_adc: 2068,
                    encoder_count: (first + i) as i32,
                    output_count: (first < 40).then_some(-((first + i) as i32)),
                })
                .collect(),
        }
    }

    #[test]
    fn gaps_overlaps_and_tails_are_counted() {
        let mut a = Assembly {
            capture: Capture {
                capture_id: 0,
                sample_rate_hz: 10_000,
                requested: 100,
                total_samples: 100,
                samples: Vec::new(),
                dropped: 0,
                gaps: 0,
                duplicates: 0,
                completed: false,
            },
            next: 0,
            id: None,
        };
        a.add(chunk(0, 10, 100));
        a.add(chunk(10, 10, 100));
        a.add(chunk(20, 7, 100));
        a.add(chunk(35, 10, 100)); // 8 lost
        a.add(chunk(45, 10, 100));
        a.add(chunk(55, 10, 100));
        a.add(chunk(63, 10, 100)); // 2 overlap
        let c = a.finish(Some(100), Some(10_000));
        assert_eq!(c.samples.len(), 27 + 30 + 8);
        assert_eq!(c.dropped, 8 + 27);
        assert_eq!(c.gaps, 2);
        assert_eq!(c.duplicates, 2);
        assert!(c.completed);
        // One count per sample at 10 kHz: 2 pi / 8192 * 10_000 rad/s.
        let w = c.mean_cam_speed_rad_s().unwrap();
        assert!((w - std::f64::consts::TAU / 8192.0 * 10_000.0).abs() < 1e-9);
        assert!(c.mean_current_a().unwrap().abs() < 0.01);
        // The last chunks have no output count: no output speed rather than a made-up one.
        assert_eq!(c.mean_output_speed_rad_s(), None);
    }

    #[test]
    fn output_columns_come_last_and_are_empty_without_an_encoder() {
        let mut c = Capture {
            capture_id: 1,
            sample_rate_hz: 1000,
            requested: 3,
            total_samples: 3,
            samples: Vec::new(),
            dropped: 0,
            gaps: 0,
            duplicates: 0,
            completed: true,
        };
        for (i, output_count) in [Some(0), Some(-2048), None].into_iter().enumerate() {
            let s = CaptureSample {
                current_adc: 2068,
                encoder_count: 0,
                output_count,
            };
            c.samples.push((i as u32, s));
        }
        let mut out = Vec::new();
        c.write_csv(&mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            "index,t_s,current_adc,current_a,encoder_count,cam_angle_rad,output_count,output_angle_rad"
        );
        // A quarter turn back: -2048 of 8192 counts is -pi/2.
        assert!(lines[2].ends_with(",-2048,-1.570796"), "{}", lines[2]);
        assert!(lines[3].ends_with(",0.000000,,"), "{}", lines[3]);
        c.samples.truncate(2);
        // -pi/2 in 1 ms.
        let w = c.mean_output_speed_rad_s().unwrap();
        assert!(
            (w + std::f64::consts::FRAC_PI_2 * 1000.0).abs() < 1e-9,
            "{w}"
        );
    }

    #[test]
    fn board_scale_matches_the_sensor_chain() {
        // 2.5 V * 2/3 = 1.667 V of 3.3 V: mid-scale code 2068 is zero current.
        assert!(current_amps(2068).abs() < 0.004);
        // One LSB: 3.3 / 4095 / (2/3) / 0.185 A.
        use model::hardware::{acs714, adc, amt102, divider};
        let lsb = current_amps(2069) - current_amps(2068);
        let expected =
            adc::VREF_V / f64::from(adc::FULL_SCALE) / divider::RATIO / acs714::SENSITIVITY_V_PER_A;
        assert!((lsb - expected).abs() < 1e-9);
        let turn = amt102::COUNTS_PER_REV as i32;
        assert!((cam_angle_rad(turn) - std::f64::consts::TAU).abs() < 1e-12);
    }
}
