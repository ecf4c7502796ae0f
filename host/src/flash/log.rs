//! `rig log`'s engine: the firmware's defmt frames decoded against its ELF with
//! defmt-decoder, from a saved stream or live from the RTT buffer of a running board.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use defmt_decoder::{DecodeError, Locations, Table};
use probe_rs::Session;
use probe_rs::rtt::{Rtt, ScanRegion};

use super::image::FirmwareImage;
use super::memory::MemoryMap;
use super::probe::{RTT_POLL, chain};
use crate::RigError;

/// One decoded log message.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct LogLine {
    /// The firmware's timestamp as defmt formats it (seconds since boot), when it has one.
    pub timestamp: Option<String>,
    /// `TRACE`, `DEBUG`, `INFO`, `WARN` or `ERROR` (`None` for `println!`).
    pub level: Option<String>,
    /// The message.
    pub message: String,
    /// Source file of the log statement, when the ELF's debug info says.
    pub file: Option<String>,
    /// Line of the log statement.
    pub line: Option<u64>,
}

impl LogLine {
    /// `  12.345678 INFO  message`, with ` (file:line)` when `location`.
    pub fn text(&self, location: bool) -> String {
        let mut s = format!(
            "{:>12} {:<5} {}",
            self.timestamp.as_deref().unwrap_or("-"),
            self.level.as_deref().unwrap_or(""),
            self.message
        );
        if location && let (Some(f), Some(l)) = (&self.file, self.line) {
            s.push_str(&format!("  ({f}:{l})"));
        }
        s
    }
}

/// Counts of a decoding run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DecodeStats {
    /// Frames decoded.
    pub frames: u64,
    /// Damaged frames skipped (bytes lost, or a stream from another build).
    pub malformed: u64,
    /// Bytes received.
    pub bytes: u64,
}

/// The ELF's defmt table and statement locations.
pub struct LogTable {
    table: Table,
    locations: Option<Locations>,
}

impl LogTable {
    /// Reads the defmt table of the ELF `elf` (named `path` in messages).
    pub fn from_elf(elf: &[u8], path: &str) -> Result<Self, RigError> {
        let table = match Table::parse(elf) {
            Ok(Some(t)) => t,
            Ok(None) => {
                return Err(RigError::BadValue {
                    what: format!("--elf {path}"),
                    why: "has no defmt table (.defmt section): give the firmware ELF that runs on the board".into(),
                });
            }
            Err(e) => {
                return Err(RigError::BadValue {
                    what: format!("--elf {path}"),
                    why: format!(
                        "its defmt table cannot be read: {e:#}; rig decodes defmt 1.x streams (the firmware's defmt version)"
                    ),
                });
            }
        };
        // Locations need the debug info; without them the messages still decode.
        let locations = table.get_locations(elf).ok().filter(|l| !l.is_empty());
        Ok(Self { table, locations })
    }

    /// A decoder that takes bytes as they come and hands out whole messages.
    pub fn stream(&self) -> LogStream<'_> {
        LogStream {
            table: self,
            decoder: self.table.new_stream_decoder(),
            stats: DecodeStats::default(),
        }
    }

    /// Decodes a whole saved stream.
    pub fn decode_all(&self, bytes: &[u8]) -> (Vec<LogLine>, DecodeStats) {
        let mut stream = self.stream();
        let mut lines = Vec::new();
        stream.push(bytes, |l| lines.push(l));
        (lines, stream.stats)
    }
}

/// A running decoder (see [`LogTable::stream`]).
pub struct LogStream<'t> {
    table: &'t LogTable,
    decoder: Box<dyn defmt_decoder::StreamDecoder + Send + Sync + 't>,
    stats: DecodeStats,
}

impl LogStream<'_> {
    /// Feeds `bytes`; `sink` gets each message completed by them.
    pub fn push(&mut self, bytes: &[u8], mut sink: impl FnMut(LogLine)) {
        self.stats.bytes += bytes.len() as u64;
        self.decoder.received(bytes);
        loop {
            match self.decoder.decode() {
                Ok(frame) => {
                    self.stats.frames += 1;
                    let location = self
                        .table
                        .locations
                        .as_ref()
                        .and_then(|l| l.get(&frame.index()));
                    sink(LogLine {
                        timestamp: frame.display_timestamp().map(|t| t.to_string()),
                        level: frame.level().map(|l| l.as_str().to_ascii_uppercase()),
                        message: frame.display_message().to_string(),
                        file: location.map(|l| l.file.display().to_string()),
                        line: location.map(|l| l.line),
                    });
                }
                Err(DecodeError::UnexpectedEof) => break,
                Err(DecodeError::Malformed) => {
                    self.stats.malformed += 1;
                    // rzcobs frames resynchronise at the next frame boundary; raw ones (the
                    // firmware's) cannot, but its RTT writes whole frames or none
                    // (defmt-rtt's drop-on-contention), so this means a corrupt stream.
                    if !self.table.table.encoding().can_recover() {
                        break;
                    }
                }
            }
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }
}

/// Where `rig log` writes what it reads.
pub struct LogSinks<'a> {
    /// Decoded messages go here.
    pub out: &'a mut dyn Write,
    /// The raw stream goes here too (`--save`).
    pub raw: Option<&'a mut dyn Write>,
    /// JSON lines instead of text.
    pub json: bool,
    /// Add `(file:line)`.
    pub locations: bool,
}

impl LogSinks<'_> {
    /// Writes one message.
    pub fn line(&mut self, l: &LogLine) -> Result<(), RigError> {
        if self.json {
            serde_json::to_writer(&mut *self.out, l)?;
            writeln!(self.out)?;
        } else {
            writeln!(self.out, "{}", l.text(self.locations))?;
        }
        Ok(())
    }
}

/// Reads the defmt RTT channel of the running firmware until `stop`, without resetting or
/// halting the chip and without changing the channel's mode (a firmware that does not
/// block on a full buffer keeps not blocking). Returns the counts.
pub fn follow(
    session: &mut Session,
    image: &FirmwareImage,
    map: &MemoryMap,
    table: &LogTable,
    sinks: &mut LogSinks<'_>,
    stop: &Arc<AtomicBool>,
) -> Result<DecodeStats, RigError> {
    let mut core = session.core(0).map_err(|e| RigError::BadValue {
        what: "debug probe".into(),
        why: format!("cannot reach the chip's core: {}", chain(&e)),
    })?;
    let mut rtt = match image.rtt_address {
        Some(addr) => Rtt::attach_at(&mut core, u64::from(addr)),
        None => Rtt::attach_region(
            &mut core,
            &ScanRegion::range(u64::from(map.ram.origin)..map.ram.end()),
        ),
    }
    .map_err(|e| RigError::BadValue {
        what: "rig log".into(),
        why: format!(
            "no RTT control block on the chip ({}): the board may not run this firmware yet (rig flash), or it is still starting; try again",
            chain(&e)
        ),
    })?;
    let channel = {
        let ups = rtt.up_channels();
        let index = ups
            .iter()
            .position(|c| c.name() == Some("defmt"))
            .or_else(|| (!ups.is_empty()).then_some(0));
        index.ok_or_else(|| RigError::BadValue {
            what: "rig log".into(),
            why: "the firmware's RTT control block has no up channel (defmt-rtt makes one)".into(),
        })?
    };
    let mut stream = table.stream();
    let mut buf = vec![0u8; 4096];
    while !stop.load(Ordering::SeqCst) {
        let Some(up) = rtt.up_channels().get_mut(channel) else {
            break;
        };
        let n = up
            .read(&mut core, &mut buf)
            .map_err(|e| RigError::BadValue {
                what: "rig log".into(),
                why: format!(
                    "reading the RTT buffer failed: {}; check the probe's cable",
                    chain(&e)
                ),
            })?;
        if n == 0 {
            std::thread::sleep(RTT_POLL);
            continue;
        }
        if let Some(raw) = sinks.raw.as_mut() {
            raw.write_all(&buf[..n])?;
            raw.flush()?;
        }
        let mut lines = Vec::new();
        stream.push(&buf[..n], |l| lines.push(l));
        for l in &lines {
            sinks.line(l)?;
        }
        sinks.out.flush()?;
    }
    Ok(stream.stats())
}
