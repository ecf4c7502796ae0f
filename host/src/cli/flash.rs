//! `rig flash`: check a firmware image, lock the rig, program it through the debug probe
//! (only the sectors it needs: the calibration store stays), reset, and confirm over the
//! serial link that the board runs it.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use protocol::DeviceInfo;
use serde::Serialize;

use super::connect::DeviceOpts;
use crate::RigError;
use crate::flash::identity::Confirmation;
use crate::flash::{self, DEFAULT_CHIP, FirmwareImage, MemoryMap, help, workspace};

/// Arguments of `rig flash`.
#[derive(Debug, Args)]
pub struct FlashArgs {
    /// Firmware ELF to flash. Default: build the workspace's release firmware
    /// (`cargo xtask firmware --no-check`, the image CI measures) and flash that.
    #[arg(long, value_name = "PATH")]
    pub elf: Option<PathBuf>,
    /// The bridge's decay mode the image is built for when no --elf is given: `brake` (the
    /// default, the Pololu G2: PWM low brakes) or `coast` (a bridge that coasts in the
    /// off-time; feature `bridge-coast-decay`).
    #[arg(long, value_name = "MODE", default_value = "brake", conflicts_with = "elf",
          value_parser = ["brake", "coast"])]
    pub decay: String,
    /// Check the image and print what would be done; neither the chip nor the rig is touched.
    #[arg(long)]
    pub dry_run: bool,
    /// The chip on the board, as probe-rs names it.
    #[arg(long, value_name = "CHIP", default_value = DEFAULT_CHIP)]
    pub chip: String,
    /// The debug probe to use when several are plugged in: VID:PID or VID:PID:SERIAL (hex).
    #[arg(long, value_name = "VID:PID[:SERIAL]")]
    pub probe: Option<String>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Print the Linux udev rules that give your user access to debug probes, and exit.
    #[arg(long, exclusive = true)]
    pub udev_rules: bool,
}

/// A range of addresses, `0x08000000..0x0800f5a8`.
fn range(start: u64, end: u64) -> String {
    format!("{start:#010x}..{end:#010x}")
}

/// What `rig flash` prints (`--json`).
#[derive(Debug, Serialize)]
pub struct FlashReport {
    /// The ELF.
    pub elf: String,
    /// The chip.
    pub chip: String,
    /// Only checked, nothing flashed.
    pub dry_run: bool,
    /// Firmware version the image carries.
    pub version: Option<String>,
    /// Build (git commit, `-dirty`) the image carries.
    pub build: Option<String>,
    /// ELF entry point.
    pub entry: String,
    /// Initial stack pointer (vector table word 0).
    pub initial_sp: String,
    /// Reset handler (vector table word 1).
    pub reset_vector: String,
    /// Programmed address range.
    pub image: String,
    /// Bytes programmed.
    pub image_bytes: u64,
    /// Program flash of the board (memory.x FLASH).
    pub flash: String,
    /// Share of program flash the image uses, %.
    pub flash_used_pct: f64,
    /// The calibration store (memory.x STORAGE), never erased.
    pub calibration_store: String,
    /// Flash ranges erased (probe-rs's sectors for this chip); `None` without the `probe` feature.
    pub erase: Option<Vec<String>>,
    /// Number of sectors erased.
    pub erase_sectors: Option<usize>,
    /// Whether the image has an RTT block and a defmt table (`rig log` works).
    pub log_ready: bool,
    /// The steps, done or (dry run) to do.
    pub steps: Vec<String>,
    /// The rig's serial port, when one was used.
    pub port: Option<String>,
    /// How the rig was made safe before flashing.
    pub rig: Option<String>,
    /// The probe used.
    pub probe: Option<String>,
    /// Erase, program, verify and total times, s.
    pub times: Option<crate::flash::FlashTimes>,
    /// The post-flash check over serial.
    pub confirmed: Option<Confirmation>,
}

/// Runs `rig flash`.
pub fn run(a: FlashArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let mut out = std::io::stdout().lock();
    if a.udev_rules {
        write!(out, "{}", help::UDEV_RULES)?;
        return Ok(ExitCode::SUCCESS);
    }
    if dev.sim {
        return Err(RigError::BadValue {
            what: "--sim".into(),
            why: "rig flash programs a real board through a debug probe; the virtual device already runs the firmware core built into rig".into(),
        });
    }
    if !a.dry_run && !cfg!(feature = "probe") {
        return Err(RigError::BadValue {
            what: "rig flash".into(),
            why: format!("{} (`--dry-run` works without it)", help::FEATURE_MISSING),
        });
    }
    let map = flash::board_map()?;
    let elf = match &a.elf {
        Some(p) => p.clone(),
        None => workspace::build_release(&workspace::current_root()?, a.decay == "coast")?,
    };
    let (_bytes, image) = flash::load(&elf, &map)?;
    let mut report = describe(&elf, &a.chip, &image, &map, a.dry_run);
    let plan = erase_plan(&a.chip, &image, &map)?;
    if let Some(p) = &plan {
        report.erase = Some(p.0.clone());
        report.erase_sectors = Some(p.1);
    }
    let erase_text = match &plan {
        Some((ranges, n)) => format!("erase {n} sectors ({}) and program", ranges.join(", ")),
        None => "erase the sectors under the image and program".into(),
    };
    report.steps = vec![
        "lock the rig over serial if one answers (Release off)".into(),
        format!(
            "{erase_text} {} bytes; no chip erase: the calibration store {} is kept",
            report.image_bytes, report.calibration_store
        ),
        "read the image back (verify)".into(),
        "reset the chip".into(),
        "confirm over serial that the board reports the image's version and build".into(),
    ];
    if a.dry_run {
        print_report(&mut out, &report, a.json)?;
        return Ok(ExitCode::SUCCESS);
    }
    flash_board(a, dev, &image, &map, report, &mut out)
}

/// The summary of a checked image.
fn describe(
    elf: &std::path::Path,
    chip: &str,
    image: &FirmwareImage,
    map: &MemoryMap,
    dry_run: bool,
) -> FlashReport {
    FlashReport {
        elf: elf.display().to_string(),
        chip: chip.to_owned(),
        dry_run,
        version: image.identity.as_ref().map(|i| i.version.clone()),
        build: image.identity.as_ref().map(|i| i.build.clone()),
        entry: format!("{:#010x}", image.entry),
        initial_sp: format!("{:#010x}", image.initial_sp),
        reset_vector: format!("{:#010x}", image.reset_vector),
        image: range(u64::from(image.start()), image.end()),
        image_bytes: image.size(),
        flash: map.flash.to_string(),
        flash_used_pct: ((image.end() - u64::from(map.flash.origin)) as f64
            / f64::from(map.flash.length)
            * 1000.0)
            .round()
            / 10.0,
        calibration_store: map.storage.to_string(),
        erase: None,
        erase_sectors: None,
        log_ready: image.rtt_address.is_some() && image.has_defmt,
        steps: Vec::new(),
        port: None,
        rig: None,
        probe: None,
        times: None,
        confirmed: None,
    }
}

/// The erased ranges and sector count from probe-rs's description of the chip (needs the
/// `probe` feature; `None` without it).
#[cfg(feature = "probe")]
fn erase_plan(
    chip: &str,
    image: &FirmwareImage,
    map: &MemoryMap,
) -> Result<Option<(Vec<String>, usize)>, RigError> {
    let target = flash::probe::target(chip)?;
    let plan = flash::probe::erase_plan(&target, image, map)?;
    Ok(Some((
        plan.ranges.iter().map(|&(s, e)| range(s, e)).collect(),
        plan.sectors,
    )))
}

#[cfg(not(feature = "probe"))]
fn erase_plan(
    _chip: &str,
    _image: &FirmwareImage,
    _map: &MemoryMap,
) -> Result<Option<(Vec<String>, usize)>, RigError> {
    Ok(None)
}

/// Prints the report as text or JSON.
fn print_report(out: &mut impl Write, r: &FlashReport, json: bool) -> Result<(), RigError> {
    if json {
        serde_json::to_writer_pretty(&mut *out, r)?;
        writeln!(out)?;
        return Ok(());
    }
    let identity = match (&r.version, &r.build) {
        (Some(v), Some(b)) => format!("firmware {v}, build {b}"),
        _ => "no build identity (an image built before rig flash existed)".into(),
    };
    writeln!(out, "image      {} ({identity})", r.elf)?;
    writeln!(
        out,
        "checked    ARM Thumb (ARMv7E-M) ELF, entry {}, vector table at the start of flash (SP {}, reset {})",
        r.entry, r.initial_sp, r.reset_vector
    )?;
    writeln!(
        out,
        "layout     {} ({} bytes, {:.1} % of program flash {}), below the calibration store {}",
        r.image, r.image_bytes, r.flash_used_pct, r.flash, r.calibration_store
    )?;
    if !r.log_ready {
        writeln!(
            out,
            "note       no RTT block or defmt table: `rig log` will not work with this image"
        )?;
    }
    if r.dry_run {
        writeln!(
            out,
            "dry run: nothing was touched; rig flash would, on {}:",
            r.chip
        )?;
        for (i, s) in r.steps.iter().enumerate() {
            writeln!(out, "  {}. {s}", i + 1)?;
        }
    }
    Ok(())
}

/// What the running firmware reports about itself, as `(version, build)`.
///
/// The version and the build (the git commit `firmware/build.rs` stamped) of `Info`;
/// [`crate::flash::identity::confirm`] compares both with the ELF's.
pub fn reported_identity(info: &DeviceInfo) -> (String, Option<String>) {
    (
        info.firmware_version.to_string(),
        Some(info.firmware_build.to_string()),
    )
}

#[cfg(not(feature = "probe"))]
fn flash_board(
    _a: FlashArgs,
    _dev: &DeviceOpts,
    _image: &FirmwareImage,
    _map: &MemoryMap,
    _report: FlashReport,
    _out: &mut impl Write,
) -> Result<ExitCode, RigError> {
    Err(RigError::BadValue {
        what: "rig flash".into(),
        why: help::FEATURE_MISSING.into(),
    })
}

#[cfg(feature = "probe")]
fn flash_board(
    a: FlashArgs,
    dev: &DeviceOpts,
    image: &FirmwareImage,
    _map: &MemoryMap,
    mut report: FlashReport,
    out: &mut impl Write,
) -> Result<ExitCode, RigError> {
    use std::io::IsTerminal;

    use crate::flash::identity::{self, Reported};
    use crate::flash::probe;

    let say = |text: &str| {
        if !a.json {
            eprintln!("{text}");
        }
    };
    // The probe first: without one nothing else is worth doing.
    let (found, name) = probe::open(a.probe.as_deref())?;
    report.probe = Some(name.clone());
    say(&format!("probe      {name}"));

    let guard = lock::lock_rig(dev)?;
    report.port = guard.port.clone();
    report.rig = Some(guard.how.clone());
    say(&format!("rig        {}", guard.how));

    let mut session = probe::attach(found, &a.chip, &name)?;
    let show = !a.json && std::io::stderr().is_terminal();
    let times = probe::program(&mut session, image, show)?;
    drop(session);
    say(&format!(
        "flashed    {} bytes: erase {:.2} s, program {:.2} s, verify {:.2} s; chip reset",
        report.image_bytes, times.erase_s, times.program_s, times.verify_s
    ));
    report.times = Some(times);

    let port = guard.port.clone();
    drop(guard);
    let outcome = match (&port, &image.identity) {
        (None, _) => {
            say(
                "confirm    skipped: no serial port (give --port or RIG_PORT to check the board runs the new image)",
            );
            Ok(())
        }
        (Some(_), None) => {
            say("confirm    skipped: the image carries no build identity to compare");
            Ok(())
        }
        (Some(port), Some(expected)) => {
            let info = lock::reconnect(dev, port)?;
            let (version, build) = reported_identity(&info);
            match identity::confirm(
                expected,
                Reported {
                    version: &version,
                    build: build.as_deref(),
                },
            ) {
                Ok(c) => {
                    let compared = if c.build_compared {
                        "version and build"
                    } else {
                        "version"
                    };
                    say(&format!(
                        "confirmed  the board runs firmware {expected} ({compared} compared on {port})"
                    ));
                    if let Some(note) = &c.note {
                        say(&format!("note       {note}"));
                    }
                    report.confirmed = Some(c);
                    Ok(())
                }
                Err(e) => Err(e),
            }
        }
    };
    if a.json {
        print_report(out, &report, true)?;
    }
    match outcome {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(e) => Err(RigError::BadValue {
            what: "rig flash".into(),
            why: e.to_string(),
        }),
    }
}

/// Making the rig safe before flashing, and talking to it afterwards.
#[cfg(feature = "probe")]
mod lock {
    use std::time::{Duration, Instant};

    use protocol::{DeviceInfo, SupervisorState};

    use super::DeviceOpts;
    use crate::RigError;
    use crate::cli::connect::Connection;
    use crate::client::{SerialTransport, open_serial};

    /// Holds the rig's port while flashing, so no other program can release it meanwhile.
    pub struct Guard {
        /// The port, when a rig is attached.
        pub port: Option<String>,
        /// What was done, for the user.
        pub how: String,
        _session: Option<Connection>,
        _port: Option<SerialTransport>,
    }

    /// Locks the rig when one answers on its serial port (`--port`, `RIG_PORT`, or the one
    /// ST-LINK port). Refuses when the port cannot be opened (another program may hold a
    /// release) or the rig stays released.
    pub fn lock_rig(dev: &DeviceOpts) -> Result<Guard, RigError> {
        let port = match dev.resolve_port() {
            Ok(p) => p,
            Err(RigError::NoDevice) => {
                return Ok(Guard {
                    port: None,
                    how: "no serial port given or found: not checked (the probe resets the chip, which switches the vibrator off)".into(),
                    _session: None,
                    _port: None,
                });
            }
            Err(e) => return Err(e),
        };
        match dev.connect() {
            Ok(mut s) => {
                s.client.release(false, 0.0)?;
                s.client.open_loop(0.0)?;
                let state = wait_until_stopped(&mut s)?;
                Ok(Guard {
                    port: Some(port.clone()),
                    how: format!("locked over {port} (state {state})"),
                    _session: Some(s),
                    _port: None,
                })
            }
            Err(e @ (RigError::PortOpen { .. } | RigError::PortBusy { .. })) => {
                Err(RigError::BadValue {
                    what: "rig flash".into(),
                    why: format!(
                        "{e}. rig flash locks the rig over its serial port before flashing and will not flash while it cannot (a program holding the port may hold a release)"
                    ),
                })
            }
            Err(e) => {
                // Something that does not speak this protocol (older firmware, none): it
                // cannot hold a release without a host's heartbeat, and we hold the port.
                let held = open_serial(&port, dev.baud).map_err(|oe| RigError::BadValue {
                    what: "rig flash".into(),
                    why: format!(
                        "{oe}; rig flash will not flash while it cannot hold the rig's port"
                    ),
                })?;
                let wait = Duration::from_millis(u64::from(protocol::COMMS_TIMEOUT_MS) + 200);
                std::thread::sleep(wait);
                Ok(Guard {
                    port: Some(port.clone()),
                    how: format!(
                        "the firmware on {port} did not answer as expected ({e}); held the port for {} ms, past its comms timeout, so no release can be live",
                        wait.as_millis()
                    ),
                    _session: None,
                    _port: Some(held),
                })
            }
        }
    }

    /// Waits (up to 3 s) until telemetry shows the vibrator stopped or stopping.
    fn wait_until_stopped(s: &mut Connection) -> Result<&'static str, RigError> {
        s.client.start_telemetry(20)?;
        let deadline = Instant::now() + Duration::from_secs(3);
        let mut last = None;
        while Instant::now() < deadline {
            if let Some(t) = s.client.next_telemetry(Duration::from_millis(100))? {
                last = Some(t.state);
                if !matches!(
                    t.state,
                    SupervisorState::SpinUp | SupervisorState::Vibrating
                ) {
                    break;
                }
            }
        }
        let _ = s.client.stop_telemetry();
        match last {
            Some(SupervisorState::SpinUp | SupervisorState::Vibrating) => Err(RigError::BadValue {
                what: "rig flash".into(),
                why: "the rig is still vibrating after Release off (is the release button held?): not flashing while it is released".into(),
            }),
            Some(state) => Ok(state.name()),
            None => Ok("release off acknowledged"),
        }
    }

    /// Connects again after the reset (the new firmware needs a moment to boot).
    pub fn reconnect(dev: &DeviceOpts, port: &str) -> Result<DeviceInfo, RigError> {
        let mut opts = dev.clone();
        opts.port = Some(port.to_owned());
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            std::thread::sleep(Duration::from_millis(300));
            match opts.connect() {
                Ok(s) => return Ok(s.info),
                Err(e) if Instant::now() >= deadline => {
                    return Err(RigError::BadValue {
                        what: "rig flash".into(),
                        why: format!(
                            "the image is flashed and verified, but the board did not answer on {port} after the reset: {e}; `rig log` shows what the firmware does"
                        ),
                    });
                }
                Err(_) => {}
            }
        }
    }
}
