//! `rig log`: the firmware's defmt log, live over the debug probe (attached without a reset,
//! so the running firmware is not disturbed) or decoded from a saved stream.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::connect::DeviceOpts;
use crate::RigError;
use crate::flash::DEFAULT_CHIP;

/// Arguments of `rig log`.
#[derive(Debug, Args)]
pub struct LogArgs {
    /// The firmware ELF that runs on the board (its defmt table decodes the log). Default:
    /// the workspace's release firmware (target/thumbv7em-none-eabihf/release/firmware).
    #[arg(long, value_name = "PATH")]
    pub elf: Option<PathBuf>,
    /// Also write the raw defmt bytes to FILE (decode later with --decode FILE).
    #[arg(long, value_name = "FILE", conflicts_with = "decode")]
    pub save: Option<PathBuf>,
    /// Decode a saved raw stream instead of reading the board (no probe needed).
    #[arg(long, value_name = "FILE")]
    pub decode: Option<PathBuf>,
    /// The chip on the board, as probe-rs names it.
    #[arg(long, value_name = "CHIP", default_value = DEFAULT_CHIP)]
    pub chip: String,
    /// The debug probe to use when several are plugged in: VID:PID or VID:PID:SERIAL (hex).
    #[arg(long, value_name = "VID:PID[:SERIAL]")]
    pub probe: Option<String>,
    /// Add the source location (file:line) of each message.
    #[arg(long)]
    pub locations: bool,
    /// Print one JSON object per message (timestamp, level, message, file, line).
    #[arg(long)]
    pub json: bool,
}

/// Runs `rig log`.
pub fn run(a: LogArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    if dev.sim {
        return Err(RigError::BadValue {
            what: "--sim".into(),
            why: "rig log reads a real board's defmt log through a debug probe; the virtual device has none (rig monitor shows its telemetry)".into(),
        });
    }
    imp::run(a)
}

/// The ELF to decode with: `--elf`, else the workspace's release build.
#[cfg(feature = "probe")]
fn elf_path(a: &LogArgs) -> Result<PathBuf, RigError> {
    if let Some(p) = &a.elf {
        return Ok(p.clone());
    }
    let root = crate::flash::workspace::current_root()?;
    let elf = crate::flash::workspace::release_elf(&root);
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(RigError::BadValue {
            what: "--elf".into(),
            why: format!(
                "not given, and {} does not exist: pass the ELF that runs on the board, or run `rig flash` (it builds and flashes it)",
                elf.display()
            ),
        })
    }
}

#[cfg(not(feature = "probe"))]
mod imp {
    use super::*;

    pub fn run(_a: LogArgs) -> Result<ExitCode, RigError> {
        Err(RigError::BadValue {
            what: "rig log".into(),
            why: crate::flash::help::FEATURE_MISSING.into(),
        })
    }
}

#[cfg(feature = "probe")]
mod imp {
    use std::io::Write;

    use super::*;
    use crate::cli::connect::interrupt_flag;
    use crate::flash::log::{LogSinks, LogTable};
    use crate::flash::{self, identity::BuildIdentity, identity::IDENTITY_SYMBOL, probe};

    /// `rig log --decode FILE`: a saved raw log decoded against the ELF's table.
    fn decode(
        a: &LogArgs,
        table: &LogTable,
        file: &std::path::Path,
        name: &str,
        stdout: &mut std::io::StdoutLock<'_>,
    ) -> Result<ExitCode, RigError> {
        let raw = std::fs::read(file).map_err(|source| RigError::File {
            action: "read the saved log",
            path: file.display().to_string(),
            source,
        })?;
        let (lines, stats) = table.decode_all(&raw);
        let mut sinks = LogSinks {
            out: stdout,
            raw: None,
            json: a.json,
            locations: a.locations,
        };
        for l in &lines {
            sinks.line(l)?;
        }
        if stats.malformed > 0 {
            eprintln!(
                "{} damaged frames skipped: bytes were lost, or the stream is from another build than {name}",
                stats.malformed
            );
        }
        if stats.frames == 0 && !raw.is_empty() {
            return Err(RigError::BadValue {
                what: format!("--decode {}", file.display()),
                why: format!(
                    "no message decodes with the defmt table of {name}: give the ELF of the firmware that wrote the log"
                ),
            });
        }
        Ok(ExitCode::SUCCESS)
    }

    pub fn run(a: LogArgs) -> Result<ExitCode, RigError> {
        let elf = elf_path(&a)?;
        let name = elf.display().to_string();
        let bytes = std::fs::read(&elf).map_err(|source| RigError::File {
            action: "read the firmware ELF",
            path: name.clone(),
            source,
        })?;
        let table = LogTable::from_elf(&bytes, &name)?;
        let mut stdout = std::io::stdout().lock();
        if let Some(file) = &a.decode {
            return decode(&a, &table, file, &name, &mut stdout);
        }

        let map = flash::board_map()?;
        let image = flash::image::validate(&bytes, &map).map_err(|e| RigError::BadValue {
            what: format!("firmware image {name}"),
            why: e.to_string(),
        })?;
        let (found, probe_name) = probe::open(a.probe.as_deref())?;
        let mut session = probe::attach(found, &a.chip, &probe_name)?;
        check_running_image(&mut session, &bytes, &image, &name)?;
        let mut save = match &a.save {
            Some(path) => Some(
                std::fs::File::create(path).map_err(|source| RigError::File {
                    action: "create",
                    path: path.display().to_string(),
                    source,
                })?,
            ),
            None => None,
        };
        let stop = interrupt_flag();
        eprintln!(
            "reading the defmt log of {} through {probe_name} (Ctrl-C ends)",
            a.chip
        );
        let stats = {
            let mut sinks = LogSinks {
                out: &mut stdout,
                raw: save.as_mut().map(|f| f as &mut dyn Write),
                json: a.json,
                locations: a.locations,
            };
            flash::log::follow(&mut session, &image, &map, &table, &mut sinks, &stop)?
        };
        eprintln!(
            "{} messages, {} bytes{}",
            stats.frames,
            stats.bytes,
            if stats.malformed > 0 {
                format!(", {} damaged frames skipped", stats.malformed)
            } else {
                String::new()
            }
        );
        Ok(ExitCode::SUCCESS)
    }

    /// Refuses to decode when the board's flash holds another build than the ELF (the
    /// defmt table would turn its log into nonsense).
    fn check_running_image(
        session: &mut probe_rs::Session,
        elf: &[u8],
        image: &flash::FirmwareImage,
        name: &str,
    ) -> Result<(), RigError> {
        let Some(expected) = &image.identity else {
            return Ok(());
        };
        let Some((address, len)) = identity_location(elf) else {
            return Ok(());
        };
        let on_chip = probe::read_memory(session, address, len)?;
        match BuildIdentity::parse(&on_chip) {
            Some(running) if running == *expected => Ok(()),
            Some(running) => Err(RigError::BadValue {
                what: format!("--elf {name}"),
                why: format!(
                    "is firmware {expected}, but the board runs {running}: pass the ELF of the running firmware, or `rig flash` this one"
                ),
            }),
            None => Err(RigError::BadValue {
                what: format!("--elf {name}"),
                why: format!(
                    "is firmware {expected}, but the board's flash does not hold it: pass the ELF of the running firmware, or `rig flash` this one"
                ),
            }),
        }
    }

    /// Address and size of the identity record in the ELF.
    fn identity_location(elf: &[u8]) -> Option<(u64, usize)> {
        use object::{Object, ObjectSymbol};
        let file = object::File::parse(elf).ok()?;
        let sym = file
            .symbols()
            .find(|s| s.name() == Ok(IDENTITY_SYMBOL) && !s.is_undefined())?;
        Some((sym.address(), usize::try_from(sym.size()).ok()?))
    }
}
