//! `rig record`: the continuous stream (every ADC sample and its control step, up to
//! 10 kHz) to a file for as long as asked (`--seconds`) or until Ctrl-C, SIGTERM or SIGHUP,
//! as CSV or as the compact binary that `rig record --decode` turns into CSV
//! ([`crate::recording`]). A progress line on stderr says the rate, the samples, the lost
//! ones and the file's size.

use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant, SystemTime};

use clap::Args;
use protocol::{DeviceMessage, Request};

use super::connect::{DeviceOpts, interrupt_flag};
use crate::recording::{StreamCounts, StreamFormat, StreamWriter, decode_to_csv};
use crate::{RigError, args};

/// Arguments of `rig record`.
#[derive(Debug, Args)]
#[command(after_help = RATES_HELP)]
pub struct RecordArgs {
    /// Samples per second: 10 kHz divided by a whole number (10000, 5000, 2500, 2000,
    /// 1250, 1000, ...). A rate the device cannot stream is refused, naming the rate that
    /// fits.
    #[arg(long, value_name = "HZ", default_value_t = protocol::MAX_STREAM_RATE_HZ, value_parser = clap::value_parser!(u16).range(1..=i64::from(protocol::MAX_STREAM_RATE_HZ)))]
    rate: u16,
    /// Stop after this many seconds of the device's time; default: until Ctrl-C (or
    /// SIGTERM, SIGHUP), after which the file is complete.
    #[arg(long, value_name = "S", value_parser = args::positive, allow_hyphen_values = true)]
    seconds: Option<f64>,
    /// The file to write (a new one; an existing one only with --force).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// csv: one row per sample, units in the column names, a `lost` row per run of lost
    /// samples; bin: the stream's frames behind a header, 3 to 5 bytes a sample (turn it
    /// into CSV with --decode).
    #[arg(long, value_enum, default_value_t = StreamFormat::Csv)]
    format: StreamFormat,
    /// Replace --out if it exists.
    #[arg(long)]
    force: bool,
    /// Turn a binary recording (--format bin) into CSV at --out; no device needed.
    #[arg(long, value_name = "FILE.bin", conflicts_with_all = ["seconds", "format"])]
    decode: Option<PathBuf>,
}

/// The rates each link carries, for `rig record --help` (docs/recording.md says more).
pub const RATES_HELP: &str = "Rates per link (8N1, typical frames): at 921,600 Bd (the default; 92,160 B/s) the 10 kHz stream (about 50 kB/s, 30 kB/s with the cam at rest) fits beside telemetry up to 200 Hz; beside 1 kHz telemetry (55 kB/s) the device refuses it naming 1,250 Hz, the rate that fits; telemetry started after the stream is not refused, and when the link runs full the device skips stream samples, each reported as lost. At 4,000,000 Bd (--baud 4000000; the board's USART runs it at 3,953,488 Bd, 395,348 B/s) everything fits. The virtual rig (--sim, rig sim serve) sends at the same byte rate as a board.";

/// How long the stream may stay silent before the recording gives up, device seconds.
const SILENCE_S: f64 = 2.0;

/// Runs `rig record`.
pub fn run(a: RecordArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    if let Some(bin) = &a.decode {
        return decode(bin, &a.out, a.force);
    }
    let stop = interrupt_flag();
    let file =
        crate::experiment::sweep::create_new(&a.out, a.force).map_err(|e| rename_csv(e, &a.out))?;
    let path = a.out.display().to_string();
    let result = record(&a, dev, file, &stop);
    match result {
        Ok(counts) => {
            println!(
                "recorded {} samples at {} Hz ({} s), {} lost in {} gap(s); {path}: {} bytes",
                counts.samples,
                a.rate,
                reporting::human(counts.samples as f64 / f64::from(a.rate)),
                counts.lost,
                counts.gaps,
                counts.file_bytes
            );
            if stop.load(Ordering::SeqCst) {
                eprintln!(
                    "recording stopped by {}: {path} is complete",
                    crate::signals::interrupt_name()
                );
            }
            Ok(crate::signals::exit_code())
        }
        Err((e, wrote)) => {
            if !wrote {
                // Nothing recorded: no file of a header alone is left behind.
                let _ = std::fs::remove_file(&a.out);
            }
            Err(e)
        }
    }
}

/// `create_new`'s refusal names `--csv`; here the file is `--out`.
fn rename_csv(e: RigError, out: &Path) -> RigError {
    match e {
        RigError::BadValue { .. } => RigError::BadValue {
            what: format!("--out {}", out.display()),
            why: "already exists: it was left unchanged; pass --force to replace it, or give a new file name".into(),
        },
        other => other,
    }
}

/// Records into `file`; the error says whether samples were written before it.
fn record(
    a: &RecordArgs,
    dev: &DeviceOpts,
    file: File,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<StreamCounts, (RigError, bool)> {
    let path = a.out.display().to_string();
    let write_err = |source: std::io::Error| RigError::File {
        action: "write",
        path: path.clone(),
        source,
    };
    let mut s = dev.connect().map_err(|e| (e, false))?;
    let calibration = s.client.calibration().map_err(|e| (e, false))?;
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let provenance = crate::provenance::device_header(
        "rig record",
        &command,
        SystemTime::now(),
        &s.info,
        &calibration,
    );
    let mut w = StreamWriter::new(BufWriter::new(file), a.format, a.rate, &provenance)
        .map_err(|e| (write_err(e), false))?;
    s.client.start_keep_alive();
    s.client
        .ack(&Request::StartStream { rate_hz: a.rate })
        .map_err(|e| (e, false))?;
    eprintln!(
        "recording at {} Hz to {path}; Ctrl-C ends it and the file stays complete",
        a.rate
    );
    let end_seq = a
        .seconds
        .map(|sec| (sec * f64::from(a.rate)).ceil().min(f64::from(u32::MAX)) as u32);
    let terminal = std::io::stderr().is_terminal();
    let silence = Duration::from_secs_f64(SILENCE_S / s.time_scale() + 2.0);
    let mut last_block = Instant::now();
    let mut last_progress = Instant::now();
    let started = Instant::now();
    let result: Result<(), RigError> = loop {
        if stop.load(Ordering::SeqCst) {
            break Ok(());
        }
        if end_seq.is_some_and(|end| w.expected_seq().is_some_and(|next| next >= end)) {
            break Ok(());
        }
        match s.client.recv(Duration::from_millis(50)) {
            Ok(Some(DeviceMessage::StreamBlock(block))) => {
                last_block = Instant::now();
                if end_seq.is_none_or(|end| block.first_seq < end)
                    && let Err(e) = w.block(&block)
                {
                    break Err(write_err(e));
                }
            }
            Ok(_) => {
                if last_block.elapsed() > silence {
                    break Err(RigError::Protocol(format!(
                        "the stream stopped: no samples for {} s from {}; check `rig faults`",
                        SILENCE_S,
                        s.port()
                    )));
                }
            }
            Err(e) => break Err(e),
        }
        if last_progress.elapsed() >= Duration::from_secs(1) {
            last_progress = Instant::now();
            let line = progress_line(&w.counts(), a.rate, started.elapsed());
            if terminal {
                eprint!("\r{line}  ");
            } else {
                eprintln!("{line}");
            }
        }
    };
    // Whatever ended it: the stream stops (a board would stop at the comms timeout).
    let stopped = s.client.ack(&Request::StopStream);
    if terminal {
        eprintln!();
    }
    let end = match (end_seq, &result) {
        (Some(end), Ok(())) if !stop.load(Ordering::SeqCst) => end,
        _ => w.expected_seq().unwrap_or(0),
    };
    let finished = w.finish(end).map_err(write_err);
    let counts = w.counts();
    let wrote = counts.samples > 0;
    result.map_err(|e| (e, wrote))?;
    finished.map_err(|e| (e, wrote))?;
    if !stop.load(Ordering::SeqCst) {
        stopped.map_err(|e| (e, wrote))?;
    }
    eprintln!("{}", progress_line(&counts, a.rate, started.elapsed()));
    Ok(counts)
}

/// `10000 Hz: 52,000 samples, 0 lost, 208.1 kB written, 5.2 s`.
fn progress_line(c: &StreamCounts, rate: u16, elapsed: Duration) -> String {
    format!(
        "{rate} Hz: {} samples, {} lost, {} kB written, {} elapsed",
        c.samples,
        c.lost,
        reporting::human(c.file_bytes as f64 / 1000.0),
        crate::progress::duration_text(elapsed.as_secs_f64())
    )
}

/// `rig record --decode BIN --out CSV`.
fn decode(bin: &Path, out: &Path, force: bool) -> Result<ExitCode, RigError> {
    let input = File::open(bin).map_err(|source| RigError::File {
        action: "read",
        path: bin.display().to_string(),
        source,
    })?;
    let file = crate::experiment::sweep::create_new(out, force).map_err(|e| rename_csv(e, out))?;
    let decoded = match decode_to_csv(
        std::io::BufReader::new(input),
        &bin.display().to_string(),
        BufWriter::new(file),
    ) {
        Ok(d) => d,
        Err(e) => {
            let _ = std::fs::remove_file(out);
            return Err(e);
        }
    };
    let c = decoded.counts;
    println!(
        "decoded {} samples, {} lost in {} gap(s); {}: {} bytes",
        c.samples,
        c.lost,
        c.gaps,
        out.display(),
        c.file_bytes
    );
    if decoded.damaged_frames > 0 {
        eprintln!(
            "warning: {} damaged frame(s) in {}: their samples are `lost` rows",
            decoded.damaged_frames,
            bin.display()
        );
    }
    std::io::stdout().flush()?;
    Ok(ExitCode::SUCCESS)
}
