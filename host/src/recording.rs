//! `rig record`'s files: the continuous stream (issue 35) as CSV, one row per sample with
//! the units in the column names and one `lost` row per run of samples that never arrived
//! ([`STREAM_CSV_COLUMNS`]), or as a compact binary ([`StreamFormat::Bin`]): a small header
//! (magic, version, rate, the provenance) and the `StreamBlock` frames as the wire carries
//! them, which [`decode_to_csv`] (`rig record --decode`) turns into the same CSV with
//! nothing else needed.
//!
//! Samples are numbered by the device from 0 at `StartStream`: a gap in the numbers (a
//! frame lost on the line, or samples the device skipped because the link was full) is a
//! `lost` row in the CSV, and in the binary it is where the numbers jump; neither file
//! drops a sample silently. A recording's end is written as an empty block numbered where
//! the recording ends, so samples lost at the very end are counted too.

use std::io::{self, Read, Write};

use protocol::{
    DeviceDeframer, DeviceMessage, StreamBlock, StreamDecoder, StreamEvent, StreamSample,
    SupervisorState,
};

use crate::RigError;
use crate::client::{cam_angle_rad, current_amps, output_angle_rad};

/// First bytes of a binary recording.
pub const BIN_MAGIC: [u8; 8] = *b"RIGSTRM\n";

/// Layout version of the binary recording (after the magic, a little-endian u16).
pub const BIN_VERSION: u16 = 1;

/// The CSV's columns. `seq` numbers the sample (from 0 at the stream's start), `t_s` is
/// `seq` over the rate; the counts are unwrapped from the wire's 16 bits (continuous from
/// the first sample); `state` is the supervisor's state and `fault_latched` 1 while a
/// fault is latched; `status` the status flags' names joined by `|`. A row with `lost` >
/// 0 stands for that many samples from `seq` on that never arrived; its other fields are
/// empty.
pub const STREAM_CSV_COLUMNS: [&str; 14] = [
    "seq",
    "t_s",
    "current_adc",
    "current_a",
    "cam_count",
    "cam_angle_rad",
    "output_count",
    "output_angle_rad",
    "duty",
    "tau_cam_nm",
    "state",
    "fault_latched",
    "status",
    "lost",
];

/// How a recording is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StreamFormat {
    /// One row per sample (the columns of `STREAM_CSV_COLUMNS`) after the provenance's `#` lines.
    Csv,
    /// The header and the raw `StreamBlock` frames (3 to 5 bytes a sample, fewer while the signals move slowly): `rig record
    /// --decode` turns it into the CSV.
    Bin,
}

/// A 16-bit counter unwrapped to a continuous count (steps of less than half a turn of
/// the counter between two samples read; across a gap of lost samples the same rule is
/// applied).
#[derive(Debug, Clone, Copy, Default)]
struct Unwrap {
    last: Option<u16>,
    count: i64,
}

impl Unwrap {
    fn next(&mut self, raw: u16) -> i64 {
        if let Some(last) = self.last {
            self.count += i64::from(raw.wrapping_sub(last).cast_signed());
        } else {
            self.count = i64::from(raw);
        }
        self.last = Some(raw);
        self.count
    }
}

/// Counts a `Write` passes on.
#[derive(Debug)]
struct Counted<W> {
    inner: W,
    bytes: u64,
}

impl<W: Write> Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// The samples of a recording so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct StreamCounts {
    /// Samples received.
    pub samples: u64,
    /// Samples that never arrived (in `lost` rows).
    pub lost: u64,
    /// Runs of lost samples.
    pub gaps: u64,
    /// Bytes written to the file.
    pub file_bytes: u64,
}

/// A recording being written, in either format.
#[derive(Debug)]
pub struct StreamWriter<W: Write> {
    out: Counted<W>,
    format: StreamFormat,
    rate_hz: u16,
    decoder: StreamDecoder,
    gaps: u64,
    rows: StreamRows,
    frames: u16,
    events: Vec<StreamEvent>,
}

impl<W: Write> StreamWriter<W> {
    /// Starts a recording at `rate_hz` in `format`: `provenance` (`#` lines, each ending in
    /// a newline) first, then the CSV's column names or the binary's header.
    pub fn new(out: W, format: StreamFormat, rate_hz: u16, provenance: &str) -> io::Result<Self> {
        let mut out = Counted {
            inner: out,
            bytes: 0,
        };
        let stream_line =
            format!("# stream: {rate_hz} Hz (samples numbered from 0 at its start)\n");
        match format {
            StreamFormat::Csv => {
                out.write_all(provenance.as_bytes())?;
                out.write_all(stream_line.as_bytes())?;
                out.write_all(csv_line(&STREAM_CSV_COLUMNS.map(String::from)).as_bytes())?;
            }
            StreamFormat::Bin => {
                let text = format!("{provenance}{stream_line}");
                out.write_all(&BIN_MAGIC)?;
                out.write_all(&BIN_VERSION.to_le_bytes())?;
                out.write_all(&rate_hz.to_le_bytes())?;
                let len = u32::try_from(text.len()).map_err(io::Error::other)?;
                out.write_all(&len.to_le_bytes())?;
                out.write_all(text.as_bytes())?;
            }
        }
        // Samples are numbered from 0: samples lost before the first block are counted.
        let mut decoder = StreamDecoder::new();
        decoder.push(&StreamBlock::pack(0, &[]), |_| {});
        Ok(Self {
            out,
            format,
            rate_hz,
            decoder,
            gaps: 0,
            rows: StreamRows::new(rate_hz),
            frames: 0,
            events: Vec::new(),
        })
    }

    /// Writes `block`: its samples (and a `lost` row before them when samples are missing).
    pub fn block(&mut self, block: &StreamBlock) -> io::Result<()> {
        let mut events = std::mem::take(&mut self.events);
        events.clear();
        self.decoder.push(block, |e| events.push(e));
        let result = match self.format {
            StreamFormat::Csv => events.iter().try_for_each(|e| self.csv_row(e)),
            StreamFormat::Bin => {
                self.gaps += events
                    .iter()
                    .filter(|e| matches!(e, StreamEvent::Lost { .. }))
                    .count() as u64;
                let frame = protocol::encode_frame_vec(
                    self.frames,
                    &DeviceMessage::StreamBlock(block.clone()),
                )
                .map_err(|e| io::Error::other(e.to_string()))?;
                self.frames = self.frames.wrapping_add(1);
                self.out.write_all(&frame)
            }
        };
        self.events = events;
        result
    }

    /// Ends the recording at sample `end_seq` (the samples asked for, or what the device
    /// numbered): samples from the last one received up to it are lost (a `lost` row), then
    /// everything is flushed.
    pub fn finish(&mut self, end_seq: u32) -> io::Result<()> {
        let end = StreamBlock::pack(end_seq, &[]);
        if self
            .decoder
            .expected_seq()
            .is_none_or(|next| next < end_seq)
        {
            self.block(&end)?;
        }
        self.out.flush()
    }

    /// Flushes what is written so far to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The samples so far.
    pub fn counts(&self) -> StreamCounts {
        StreamCounts {
            samples: self.decoder.samples,
            lost: self.decoder.lost,
            gaps: self.gaps,
            file_bytes: self.out.bytes,
        }
    }

    /// The next sample number expected (`None` before the first block).
    pub fn expected_seq(&self) -> Option<u32> {
        self.decoder.expected_seq()
    }

    /// The stream's rate, Hz.
    pub fn rate_hz(&self) -> u16 {
        self.rate_hz
    }

    /// The writer, after [`StreamWriter::finish`].
    pub fn into_inner(self) -> W {
        self.out.inner
    }

    fn csv_row(&mut self, event: &StreamEvent) -> io::Result<()> {
        let rate = f64::from(self.rate_hz.max(1));
        let fields = match *event {
            StreamEvent::Lost { first_seq, count } => {
                self.gaps += 1;
                let mut f: Vec<String> = vec![String::new(); STREAM_CSV_COLUMNS.len()];
                f[0] = first_seq.to_string();
                f[1] = format!("{:.6}", f64::from(first_seq) / rate);
                f[STREAM_CSV_COLUMNS.len() - 1] = count.to_string();
                f
            }
            StreamEvent::Sample { seq, sample } => self.sample_fields(seq, &sample),
        };
        self.out.write_all(csv_line(&fields).as_bytes())
    }

    fn sample_fields(&mut self, seq: u32, s: &StreamSample) -> Vec<String> {
        let r = self.rows.row(seq, s);
        vec![
            r.seq.to_string(),
            format!("{:.6}", r.t_s),
            r.current_adc.to_string(),
            format!("{:.5}", r.current_a),
            r.cam_count.to_string(),
            format!("{:.6}", r.cam_angle_rad),
            r.output_count.to_string(),
            format!("{:.6}", r.output_angle_rad),
            format!("{:.4}", r.duty),
            format!("{:.4}", r.tau_cam_nm),
            r.state_name(),
            u8::from(r.fault_latched).to_string(),
            r.status_names(),
            "0".into(),
        ]
    }
}

/// One stream sample in the CSV's units ([`STREAM_CSV_COLUMNS`]): what `rig record` writes
/// and the Python binding hands to numpy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamRow {
    /// The sample's number from the stream's start.
    pub seq: u32,
    /// `seq` over the rate, s.
    pub t_s: f64,
    /// Current-sensor ADC code.
    pub current_adc: u16,
    /// Current, A.
    pub current_a: f64,
    /// Cam encoder count, unwrapped from the first sample.
    pub cam_count: i64,
    /// Cam angle, rad.
    pub cam_angle_rad: f64,
    /// Output encoder count, unwrapped from the first sample.
    pub output_count: i64,
    /// Output angle, rad.
    pub output_angle_rad: f64,
    /// PWM duty, -1..=1.
    pub duty: f32,
    /// The last revolution's tau_cam, N m.
    pub tau_cam_nm: f32,
    /// Supervisor state index (`SupervisorState::from_index`).
    pub state: u8,
    /// Whether a fault is latched.
    pub fault_latched: bool,
    /// Status flag bits.
    pub status: u16,
}

impl StreamRow {
    /// The supervisor state's name (`unknown_N` for one this build does not know).
    pub fn state_name(&self) -> String {
        SupervisorState::from_index(self.state).map_or_else(
            || format!("unknown_{}", self.state),
            |s| s.name().to_owned(),
        )
    }

    /// The status flags' names joined by `|`.
    pub fn status_names(&self) -> String {
        protocol::StatusFlags::from_bits_retain(self.status)
            .names()
            .collect::<Vec<_>>()
            .join("|")
    }
}

/// Turns a stream's samples, in order, into [`StreamRow`]s (the counts unwrapped).
#[derive(Debug, Clone, Copy)]
pub struct StreamRows {
    rate: f64,
    cam: Unwrap,
    output: Unwrap,
}

impl StreamRows {
    /// For a stream at `rate_hz`.
    pub fn new(rate_hz: u16) -> Self {
        Self {
            rate: f64::from(rate_hz.max(1)),
            cam: Unwrap::default(),
            output: Unwrap::default(),
        }
    }

    /// Sample `seq`.
    pub fn row(&mut self, seq: u32, s: &StreamSample) -> StreamRow {
        let cam = self.cam.next(s.cam_count);
        let output = self.output.next(s.output_count);
        // Angles from counts within the i32 range (262,000 cam turns from the first sample).
        let clamp = |c: i64| i32::try_from(c).unwrap_or(if c < 0 { i32::MIN } else { i32::MAX });
        StreamRow {
            seq,
            t_s: f64::from(seq) / self.rate,
            current_adc: s.current_adc,
            current_a: current_amps(s.current_adc),
            cam_count: cam,
            cam_angle_rad: cam_angle_rad(clamp(cam)),
            output_count: output,
            output_angle_rad: output_angle_rad(clamp(output)),
            duty: f32::from(s.duty) / protocol::STREAM_DUTY_SCALE,
            tau_cam_nm: f32::from(s.tau_cam) / protocol::STREAM_TAU_SCALE,
            state: s.state & !protocol::STREAM_STATE_FAULTED,
            fault_latched: s.state & protocol::STREAM_STATE_FAULTED != 0,
            status: s.status,
        }
    }
}

/// `fields` as one CSV line (quoted as the csv crate quotes), newline included.
fn csv_line(fields: &[String]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing to memory cannot fail.
    let _ = w.write_record(fields);
    String::from_utf8_lossy(&w.into_inner().unwrap_or_default()).into_owned()
}

/// What [`decode_to_csv`] found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Decoded {
    /// The samples written and lost, and the CSV's size.
    pub counts: StreamCounts,
    /// Frames of the binary file that did not decode (damage to the file): their samples
    /// are `lost` rows.
    pub damaged_frames: u64,
}

/// Turns a binary recording (`what` names it in errors) into the CSV a CSV recording
/// would have written, provenance included.
pub fn decode_to_csv(
    mut input: impl Read,
    what: &str,
    out: impl Write,
) -> Result<Decoded, RigError> {
    let bad = |why: String| RigError::MeasuredFile {
        file: what.to_owned(),
        why,
    };
    let mut bytes = Vec::new();
    input
        .read_to_end(&mut bytes)
        .map_err(|source| RigError::File {
            action: "read",
            path: what.to_owned(),
            source,
        })?;
    let head = 8 + 2 + 2 + 4;
    if bytes.len() < head || bytes[..8] != BIN_MAGIC {
        return Err(bad(
            "is not a binary `rig record` file (it does not start with RIGSTRM): give a file written by `rig record --format bin`".into(),
        ));
    }
    let version = u16::from_le_bytes([bytes[8], bytes[9]]);
    if version != BIN_VERSION {
        return Err(bad(format!(
            "is a version {version} recording; this tool reads version {BIN_VERSION}: decode it with the rig tool that wrote it"
        )));
    }
    let rate_hz = u16::from_le_bytes([bytes[10], bytes[11]]);
    let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
    let text = bytes
        .get(head..head + len)
        .and_then(|t| std::str::from_utf8(t).ok())
        .ok_or_else(|| bad("its header is cut short or damaged: nothing to decode".into()))?;
    // The header carries the stream line itself; the CSV writer adds its own.
    let provenance: String = text
        .lines()
        .filter(|l| !l.starts_with("# stream: "))
        .map(|l| format!("{l}\n"))
        .collect();
    let write_err = |e: io::Error| RigError::File {
        action: "write",
        path: "the CSV".into(),
        source: e,
    };
    let mut csv =
        StreamWriter::new(out, StreamFormat::Csv, rate_hz, &provenance).map_err(write_err)?;
    let mut deframer = DeviceDeframer::new();
    let mut damaged = 0u64;
    let mut blocks = Vec::new();
    deframer.push(&bytes[head + len..], |frame| match frame {
        Ok(f) => {
            if let DeviceMessage::StreamBlock(b) = f.msg {
                blocks.push(b);
            }
        }
        Err(_) => damaged += 1,
    });
    // The recording's end marker (an empty block) is the last: samples lost at the end
    // are its `lost` row.
    for b in &blocks {
        csv.block(b).map_err(write_err)?;
    }
    csv.flush().map_err(write_err)?;
    Ok(Decoded {
        counts: csv.counts(),
        damaged_frames: damaged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(i: u16) -> StreamSample {
        StreamSample {
            current_adc: 2048 + i,
            // Wraps past 65535 within the recording.
            cam_count: 65_530u16.wrapping_add(i * 3),
            output_count: 7,
            duty: 5_000,
            tau_cam: -123,
            status: 0,
            state: SupervisorState::Vibrating as u8,
        }
    }

    fn blocks() -> Vec<StreamBlock> {
        let s: Vec<StreamSample> = (0..40).map(sample).collect();
        // Blocks 0..10, 10..20 and 30..40: 20..30 lost.
        [0usize, 10, 30]
            .iter()
            .map(|&i| StreamBlock::pack(i as u32, &s[i..i + 10]))
            .collect()
    }

    fn record(format: StreamFormat, end: u32) -> (Vec<u8>, StreamCounts) {
        let mut w = StreamWriter::new(Vec::new(), format, 10_000, "# rig record (test)\n").unwrap();
        for b in blocks() {
            w.block(&b).unwrap();
        }
        w.finish(end).unwrap();
        let counts = w.counts();
        (w.into_inner(), counts)
    }

    #[test]
    fn the_csv_has_a_row_per_sample_and_a_lost_row_per_gap() {
        let (csv, counts) = record(StreamFormat::Csv, 45);
        let text = String::from_utf8(csv).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("# rig record (test)"));
        assert!(lines.next().unwrap().starts_with("# stream: 10000 Hz"));
        assert_eq!(lines.next(), Some(STREAM_CSV_COLUMNS.join(",").as_str()));
        let rows: Vec<&str> = lines.collect();
        // 30 samples, a lost row for 20..30 and one for 40..45 (the end).
        assert_eq!(rows.len(), 32);
        assert_eq!(rows[20], "20,0.002000,,,,,,,,,,,,10");
        assert_eq!(rows[31], "40,0.004000,,,,,,,,,,,,5");
        // The cam count is unwrapped: 65530 + 3 i, continuous past 65535.
        assert!(rows[2].starts_with("2,0.000200,2050,"), "{}", rows[2]);
        assert!(rows[2].contains(",65536,"), "{}", rows[2]);
        assert!(rows[19].contains(",vibrating,0,,0"), "{}", rows[19]);
        assert_eq!(
            counts,
            StreamCounts {
                samples: 30,
                lost: 15,
                gaps: 2,
                file_bytes: text.len() as u64
            }
        );
    }

    #[test]
    fn a_binary_recording_decodes_to_the_same_csv() {
        let (csv, _) = record(StreamFormat::Csv, 45);
        let (bin, counts) = record(StreamFormat::Bin, 45);
        assert!(bin.len() < csv.len() / 3, "{} vs {}", bin.len(), csv.len());
        assert_eq!((counts.samples, counts.lost), (30, 15));
        let mut out = Vec::new();
        let decoded = decode_to_csv(&bin[..], "test.bin", &mut out).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            String::from_utf8(csv).unwrap()
        );
        assert_eq!((decoded.counts.samples, decoded.counts.lost), (30, 15));
        assert_eq!(decoded.damaged_frames, 0);
        // A damaged byte costs only the frame it hits: its samples become a lost row.
        let mut damaged = bin.clone();
        let at = damaged.len() - 20;
        damaged[at] ^= 0x55;
        let decoded = decode_to_csv(&damaged[..], "test.bin", Vec::new()).unwrap();
        assert_eq!(decoded.damaged_frames, 1);
        assert_eq!(decoded.counts.samples + decoded.counts.lost, 45);
        // Not a recording at all: named.
        let e = decode_to_csv(&b"seq,t_s\n"[..], "x.csv", Vec::new()).unwrap_err();
        assert!(e.to_string().contains("rig record --format bin"), "{e}");
    }
}
