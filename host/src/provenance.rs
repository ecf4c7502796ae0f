//! The provenance header of a measured CSV: the `#` lines before the column names that say
//! which command measured the rows, when, with which host, firmware, calibration, averaging
//! window and plan, and the drive's decay mode (`rig explain` reads it). Written once
//! ([`Provenance::header`]) and read once ([`Header::parse`]) here; the device's identity
//! is one line shared with `rig bringup` ([`identity`]).

use std::path::Path;
use std::time::SystemTime;

use protocol::{DeviceInfo, RigParameters};
use rigfile::plan::Plan;

/// The line that carries the plan, as one line of JSON ([`Plan::one_line`]).
const PLAN_PREFIX: &str = "# plan: ";
/// The line that carries the drive's decay mode.
const DRIVE_PREFIX: &str = "# drive: regenerative_decay = ";

/// The device's identity in one line: `0.1.0 build 1a2b3c4 board nucleo-g474re protocol 3
/// capabilities OUTPUT_ENCODER` (`none` without capabilities).
pub fn identity(info: &DeviceInfo) -> String {
    let fw = info.firmware_version;
    format!(
        "{}.{}.{} build {} board {} protocol {} capabilities {}",
        fw.major,
        fw.minor,
        fw.patch,
        info.firmware_build.as_str(),
        info.board.as_str(),
        info.protocol_version,
        if info.capabilities.is_empty() {
            "none".to_string()
        } else {
            info.capabilities.to_string()
        },
    )
}

/// What a measurement's provenance states.
#[derive(Debug, Clone)]
pub struct Provenance<'a> {
    /// The procedure that measured (`rig experiment torque-sweep`).
    pub procedure: &'a str,
    /// The command line.
    pub command: &'a str,
    /// When the measurement started.
    pub date: SystemTime,
    /// The device, as it answered `Hello`.
    pub info: &'a DeviceInfo,
    /// The device's calibration.
    pub calibration: &'a RigParameters,
    /// The averaging window, in words.
    pub window: &'a str,
    /// The plan.
    pub plan: &'a Plan,
    /// Whether the drive decays regeneratively (the board setting the firmware is built
    /// with and the virtual rig follows).
    pub regenerative: bool,
}

impl Provenance<'_> {
    /// The header: `#` lines, each ending in a newline, that CSV readers skip.
    pub fn header(&self) -> String {
        format!(
            "{}# window: {}\n{PLAN_PREFIX}{}\n{}",
            device_header(
                self.procedure,
                self.command,
                self.date,
                self.info,
                self.calibration
            ),
            self.window,
            self.plan.one_line(),
            drive_line(self.regenerative),
        )
    }
}

/// The first lines of every measured file's header: the procedure and command line, the
/// date, the host tool, the device's identity and its calibration, each a `#` line ending
/// in a newline ([`Provenance::header`] and `rig record`'s files go on from here).
pub fn device_header(
    procedure: &str,
    command: &str,
    date: SystemTime,
    info: &DeviceInfo,
    calibration: &RigParameters,
) -> String {
    format!(
        "# {procedure} ({command})\n# date: {}\n# host: rig {}\n# firmware: {}\n# calibration ({}): {}\n",
        reporting::UtcTime::of(date).iso(),
        env!("CARGO_PKG_VERSION"),
        identity(info),
        info.parameters_status.name(),
        serde_json::to_string(calibration).unwrap_or_default(),
    )
}

impl Provenance<'_> {}

/// The provenance header of a sweep measured on the simulated rig in virtual time (`rig sim
/// torque-sweep`, `rig demo`): what ran it and the drive the plant ran, so `rig explain`
/// builds its base model on that drive. `details` says which preset, model and seed.
pub fn simulated_header(procedure: &str, details: &str) -> String {
    format!(
        "# {procedure} ({details})\n# host: rig {}\n# firmware: simulated (the firmware core on the virtual plant, virtual time)\n{}",
        env!("CARGO_PKG_VERSION"),
        drive_line(model::hardware::board::REGENERATIVE_DECAY),
    )
}

/// `rig` with the drive of the measured CSV at `path` in its base model: the drive its
/// provenance states; else, unless the rig file already fits the inertia term, the rig's
/// drive (`[drive] decay`, the board's braking drive by default), with a warning that says which
/// base was assumed and what changes with the other drive (returned second). Eq. (10) alone
/// is neither drive, so a base without one would name the drive's own return as a missing
/// effect.
pub fn with_stated_drive(rig: rigfile::RigFile, path: &Path) -> (rigfile::RigFile, Option<String>) {
    if let Some(regenerative) = Header::read(path).regenerative {
        return (rig.with_drive_decay(regenerative), None);
    }
    // The rig file's drive: `[drive] decay`, the board's braking drive unless it says otherwise.
    let assumed = rig.drive.decay.returns_power();
    let with = rig.with_drive_decay(assumed);
    if with == rig {
        return (rig, None);
    }
    let (kappa, other) = (
        model::effects::drive_kappa(assumed),
        model::effects::drive_kappa(!assumed),
    );
    let warning = format!(
        "{} states no drive (no `{}` line): the base model assumes the rig's drive ([drive] decay = \"{}\"), regenerative_decay = {assumed} (inertia term with kappa = {kappa}); with the other drive (regenerative_decay = {}, kappa = {other}) the base's inertia term changes by {} of Eq. (10)'s, and an inertia-rectification named with kappa near {other} is that drive's own return, not a missing effect: add the line `{}` to the CSV's header to explain it on that drive",
        path.display(),
        DRIVE_PREFIX.trim_end(),
        rig.drive.decay.name(),
        !assumed,
        reporting::human((other - kappa).abs()),
        drive_line(!assumed).trim_end()
    );
    (with, Some(warning))
}

/// The provenance line of the drive's decay mode, which `rig explain` reads
/// ([`Header::regenerative`]).
pub fn drive_line(regenerative: bool) -> String {
    format!(
        "{DRIVE_PREFIX}{regenerative} (inertia-rectification kappa = {})\n",
        model::effects::drive_kappa(regenerative)
    )
}

/// What a file's provenance says, from its leading `#` lines only (a `#` line among the
/// rows is a comment, not provenance).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Header {
    /// The plan line's JSON, as written ([`Plan::one_line`]; `--resume` compares it).
    pub plan_line: Option<String>,
    /// The drive's decay mode, when stated.
    pub regenerative: Option<bool>,
}

impl Header {
    /// The provenance of `text` (a whole CSV, or its start).
    pub fn parse(text: &str) -> Self {
        let mut h = Self::default();
        for line in text.lines().take_while(|l| l.starts_with('#')) {
            if let Some(plan) = line.strip_prefix(PLAN_PREFIX) {
                h.plan_line.get_or_insert_with(|| plan.to_string());
            } else if let Some(rest) = line.strip_prefix(DRIVE_PREFIX) {
                let stated = match rest.split_whitespace().next() {
                    Some("true") => Some(true),
                    Some("false") => Some(false),
                    _ => None,
                };
                h.regenerative = h.regenerative.or(stated);
            }
        }
        h
    }

    /// The provenance of the file at `path` (none when it cannot be read).
    pub fn read(path: &Path) -> Self {
        use std::io::BufRead;
        let Ok(file) = std::fs::File::open(path) else {
            return Self::default();
        };
        let head: Vec<String> = std::io::BufReader::new(file)
            .lines()
            .map_while(Result::ok)
            .take_while(|l| l.starts_with('#'))
            .collect();
        Self::parse(&head.join("\n"))
    }

    /// The plan, when stated and readable.
    pub fn plan(&self) -> Option<Plan> {
        serde_json::from_str(self.plan_line.as_deref()?).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> DeviceInfo {
        DeviceInfo {
            protocol_version: 3,
            schema_hash: 0xDEAD_BEEF,
            firmware_version: protocol::FirmwareVersion {
                major: 0,
                minor: 1,
                patch: 2,
            },
            firmware_build: "1a2b3c4d5e6f-dirty".try_into().unwrap(),
            board: "nucleo-g474re".try_into().unwrap(),
            parameters_status: protocol::ParametersStatus::Defaults,
            reset_cause: protocol::ResetCause::Watchdog,
            uptime_s: 3_600,
            capabilities: protocol::Capabilities::OUTPUT_ENCODER,
            time_scale: 1.0,
            max_baud: protocol::DEFAULT_BAUD_RATE,
        }
    }

    /// What the header writes, the parser reads back: the plan and the drive.
    #[test]
    fn the_header_reads_back() {
        let (info, cal, plan) = (info(), RigParameters::paper(), Plan::quick());
        for regenerative in [false, true] {
            let p = Provenance {
                procedure: "rig experiment torque-sweep",
                command: "rig experiment torque-sweep --quick",
                date: std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_795_910_400),
                info: &info,
                calibration: &cal,
                window: "start of constant cam rotation",
                plan: &plan,
                regenerative,
            };
            let text = p.header() + "point,i_in_a\n0,1.0\n";
            assert!(text.contains("# date: 2026-11-29T00:00:00Z\n"), "{text}");
            assert!(text.contains(
                "# firmware: 0.1.2 build 1a2b3c4d5e6f-dirty board nucleo-g474re protocol 3 capabilities OUTPUT_ENCODER\n"
            ));
            let h = Header::parse(&text);
            assert_eq!(h.regenerative, Some(regenerative));
            assert_eq!(h.plan_line.as_deref(), Some(plan.one_line().as_str()));
            assert_eq!(h.plan(), Some(plan.clone()));
        }
    }

    #[test]
    fn the_drive_line_is_read_back_from_the_provenance_only() {
        let dir = tempfile::tempdir().unwrap();
        for regenerative in [false, true] {
            let path = dir.path().join(format!("d{regenerative}.csv"));
            let text = format!(
                "# plan: {{}}\n{}point,i_in_a\n0,1.0\n",
                drive_line(regenerative)
            );
            std::fs::write(&path, text).unwrap();
            assert_eq!(Header::read(&path).regenerative, Some(regenerative));
        }
        // Not in the leading comments (or absent): unknown, the paper's Eq. (10) stays.
        let path = dir.path().join("late.csv");
        std::fs::write(&path, format!("point,i_in_a\n{}0,1.0\n", drive_line(true))).unwrap();
        assert_eq!(Header::read(&path), Header::default());
        assert!(drive_line(false).contains("kappa = -0.5"));
    }
}
