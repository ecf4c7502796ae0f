//! `rig sim serve`: the virtual rig on a pseudo-terminal that any serial client can open
//! (`rig --port P ...`, the user's own scripts: docs/examples/rig_client.py), until SIGINT
//! or SIGTERM. One firmware core and one plant live for the whole run, so state lasts
//! between client sessions: a calibration written stays written, a latched fault stays
//! latched until cleared.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

use clap::Args;
use serde::Serialize;

use crate::RigError;
use crate::virtual_device::{FirmwareDevice, VirtualDevice, WallNoise};
use sim::{EffectSpec, Preset, SimConfig};

/// Arguments of `rig sim serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Virtual seconds per wall-clock second (1 = real time; up to 1000).
    #[arg(long, default_value_t = 1.0, value_parser = super::connect::parse_speed)]
    pub speed: f64,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The plant: `paper` behaves as the paper's rig measured (docs/presets.md), `ideal` is the
    /// paper's equations alone.
    #[arg(long, default_value = "paper", value_parser = clap::builder::PossibleValuesParser::new(sim::preset::PRESETS))]
    pub preset: String,
    /// Hide an effect in the plant: NAME[:k=v,...] with `rig explain`'s effect and parameter
    /// names (e.g. load-dependent-friction:exponent=0.3); repeatable. An effect the firmware
    /// cancels (a current-sensor offset: it zeroes the sensor with the motor off) is served
    /// with a warning: no client logging through the firmware can see it.
    #[arg(long = "effect", value_name = "NAME[:k=v,...]")]
    pub effects: Vec<String>,
    /// A rig file: the virtual rig is built from it (gear, friction, calibration stored in
    /// flash) and, when it has a fitted [model], runs with those effects.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Serve the firmware image itself on the emulated STM32G474 (processor in the loop):
    /// the ELF runs instruction by instruction against the same plant: `--firmware=ELF`, or alone the
    /// release image `cargo xtask firmware` builds (target/thumbv7em-none-eabihf/release/firmware).
    /// Needs the Unicorn engine (`cargo xtask setup` installs it). Runs as fast as this
    /// machine allows, at most --speed.
    #[arg(long, value_name = "ELF", num_args = 0..=1, require_equals = true)]
    pub firmware: Option<Option<PathBuf>>,
    /// Print one JSON line with the port when ready.
    #[arg(long)]
    pub json: bool,
    /// Mix this many random bytes per second (wall clock) into each direction of the line,
    /// as a noisy cable would: to test that clients survive it.
    #[arg(long, value_name = "N", default_value_t = 0.0, value_parser = crate::args::non_negative)]
    pub line_noise_bytes_per_s: f64,
}

/// What `rig sim serve --json` prints when ready.
#[derive(Debug, Serialize)]
pub struct Ready {
    /// The pseudo-terminal to open as a serial port.
    pub port: String,
    /// Virtual seconds per wall-clock second.
    pub speed: f64,
    /// The preset.
    pub preset: String,
    /// The effects hidden in the plant (as given).
    pub effects: Vec<String>,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Why an effect hidden cannot show to a client (the firmware cancels it).
    pub warnings: Vec<String>,
}

/// Why each effect of `a` cannot show to a client logging through the firmware.
pub fn unseen_warnings(a: &ServeArgs) -> Vec<String> {
    a.effects
        .iter()
        .filter_map(|e| crate::discover::unseen_effect_note(e))
        .collect()
}

/// The virtual rig the options describe.
pub fn config(a: &ServeArgs) -> Result<SimConfig, RigError> {
    let preset = Preset::by_name(&a.preset)?;
    let mut config = match &a.model {
        // The file's fitted model is the plant; without one, the preset.
        Some(path) => VirtualDevice::rig_file_config(&rigfile::RigFile::load(path)?, &preset)?,
        None => VirtualDevice::paper_config(&preset),
    };
    for e in &a.effects {
        EffectSpec::parse(e)?.apply(&mut config.plant)?;
    }
    config.seed = a.seed;
    Ok(config)
}

/// The random bytes `--line-noise-bytes-per-s` mixes into the line, if any.
fn line_noise(a: &ServeArgs) -> Option<WallNoise> {
    (a.line_noise_bytes_per_s > 0.0).then_some(WallNoise {
        bytes_per_s: a.line_noise_bytes_per_s,
        seed: a.seed,
    })
}

/// The ready line's keys for a rig served on `port` at `speed`, with the warnings (also
/// printed to stderr) about effects no client can see.
fn ready(a: &ServeArgs, port: &str, speed: f64) -> Ready {
    let warnings = unseen_warnings(a);
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    Ready {
        port: port.to_string(),
        speed,
        preset: a.preset.clone(),
        effects: a.effects.clone(),
        seed: a.seed,
        warnings,
    }
}

/// Runs `rig sim serve --firmware`: the image on the emulated board.
fn run_firmware(a: &ServeArgs, config: SimConfig) -> Result<ExitCode, RigError> {
    let stop = super::connect::interrupt_flag();
    let noise = line_noise(a);
    let elf = a.firmware.clone().flatten();
    let dev = FirmwareDevice::start(elf.as_deref(), &config, a.seed, a.speed, noise)?;
    let ready = ready(a, dev.port_name(), dev.pace());
    let mut out = std::io::stdout().lock();
    if a.json {
        let ready = FirmwareReady {
            ready,
            firmware: dev.elf().display().to_string(),
        };
        super::print_json_line(&mut out, &ready)?;
    } else {
        writeln!(
            out,
            "firmware {} on the emulated STM32G474 ({} preset) on {} at {:.2}x real time (this machine runs it at {:.2}x; the image reports the pace in Info); open it with `rig --port {} info`. Ctrl-C stops it.",
            dev.elf().display(),
            a.preset,
            dev.port_name(),
            dev.pace(),
            dev.measured_speed(),
            dev.port_name()
        )?;
    }
    out.flush()?;
    drop(out);
    let started = std::time::Instant::now();
    let mut warned = false;
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(20));
        if let Some(e) = dev.error() {
            return Err(RigError::VirtualDevice(e));
        }
        let wall = started.elapsed().as_secs_f64();
        let achieved = dev.time() / wall.max(1e-9);
        if !warned && wall > 5.0 && achieved < 0.9 * dev.pace() {
            warned = true;
            eprintln!(
                "warning: the emulated board runs at only {achieved:.2}x real time, not the {:.2}x it reports (this machine got busier): clients' heartbeats come sooner in device time, never later",
                dev.pace()
            );
        }
    }
    drop(dev);
    Ok(crate::signals::exit_code())
}

/// What `rig sim serve --firmware --json` prints when ready: [`Ready`]'s keys (`speed`:
/// the pace served at, which `Info` reports) and the image.
#[derive(Debug, Serialize)]
pub struct FirmwareReady {
    /// The keys every served rig prints.
    #[serde(flatten)]
    pub ready: Ready,
    /// The firmware ELF running.
    pub firmware: String,
}

/// Runs `rig sim serve`.
pub fn run(a: ServeArgs) -> Result<ExitCode, RigError> {
    let config = config(&a)?;
    if a.firmware.is_some() {
        return run_firmware(&a, config);
    }
    let stop = super::connect::interrupt_flag();
    let noise = line_noise(&a);
    let dev = VirtualDevice::start_with_noise(config, a.speed, noise)?;
    let ready = ready(&a, dev.port_name(), a.speed);
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json_line(&mut out, &ready)?;
    } else {
        writeln!(
            out,
            "virtual rig ({} preset{}) on {} at {}x real time; open it with `rig --port {} info`. Ctrl-C stops it.",
            a.preset,
            if a.effects.is_empty() {
                String::new()
            } else {
                format!(", effects {}", a.effects.join(" "))
            },
            dev.port_name(),
            a.speed,
            dev.port_name()
        )?;
    }
    out.flush()?;
    drop(out);
    // Say so when this machine cannot run the rig as fast as asked (clients scale their
    // heartbeats by the speed the rig reports; a rig that falls behind is slower still).
    let started = std::time::Instant::now();
    let mut warned = false;
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(20));
        let wall = started.elapsed().as_secs_f64();
        let achieved = (dev.time() / wall.max(1e-9)).min(a.speed);
        if !warned && wall > 2.0 && achieved < 0.9 * a.speed {
            warned = true;
            eprintln!(
                "warning: the virtual rig runs at only {achieved:.1}x real time, not the {}x asked (this machine cannot keep up): use a lower --speed",
                a.speed
            );
        }
    }
    drop(dev);
    // Served until a signal: 128 + its number, as every verb.
    Ok(crate::signals::exit_code())
}
