//! The debug probe side of `rig flash` and `rig log`, through the probe-rs library: finding
//! and opening the probe (with messages that say what to check), the chip's flash layout,
//! programming with a progress bar, and attaching to a running target without a reset.

use std::error::Error as StdError;
use std::time::{Duration, Instant};

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use probe_rs::config::{MemoryRegion, Registry, Target};
use probe_rs::flashing::{DownloadOptions, FlashProgress, ProgressEvent, ProgressOperation};
use probe_rs::probe::list::{Accessibility, Lister};
use probe_rs::probe::{DebugProbeSelector, Probe};
use probe_rs::{MemoryInterface, Permissions, Session};

use super::image::FirmwareImage;
use super::memory::MemoryMap;
use super::{DEFAULT_CHIP, help};
use crate::RigError;

/// `what` of the errors about the probe.
const PROBE: &str = "debug probe";

/// An error and its causes on one line.
pub fn chain(e: &dyn StdError) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let more = s.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = s.source();
    }
    text
}

/// Whether the operating system refused access somewhere in `e`'s causes.
fn is_permission_denied(e: &(dyn StdError + 'static)) -> bool {
    let mut cur: Option<&(dyn StdError + 'static)> = Some(e);
    while let Some(err) = cur {
        if let Some(io) = err.downcast_ref::<std::io::Error>()
            && io.kind() == std::io::ErrorKind::PermissionDenied
        {
            return true;
        }
        let text = err.to_string().to_ascii_lowercase();
        if text.contains("permission denied") || text.contains("access denied") {
            return true;
        }
        cur = err.source();
    }
    false
}

/// probe-rs's description of the STM32G4 family (its `targets/STM32G4_Series.yaml`): the
/// chips this rig can have, instead of the built-in targets of every family (3.8 MB).
const STM32G4_FAMILY: &str = include_str!("STM32G4_Series.yaml");

/// The chip descriptions `rig` knows: the STM32G4 family.
pub fn registry() -> Result<Registry, RigError> {
    let mut registry = Registry::new();
    registry
        .add_target_family_from_yaml(STM32G4_FAMILY)
        .map_err(|e| RigError::BadValue {
            what: "rig".into(),
            why: format!(
                "the STM32G4 description built into rig does not load: {}",
                chain(&e)
            ),
        })?;
    Ok(registry)
}

/// The chip's description.
pub fn target(chip: &str) -> Result<Target, RigError> {
    let registry = registry()?;
    registry.get_target_by_name(chip).map_err(|e| {
        let stem: String = chip.chars().take(9).collect();
        let similar = registry.search_chips(&stem);
        let similar = if similar.is_empty() {
            String::new()
        } else {
            format!(
                "; similar names: {}",
                similar.into_iter().take(8).collect::<Vec<_>>().join(", ")
            )
        };
        RigError::BadValue {
            what: format!("--chip {chip}"),
            why: format!(
                "{}{similar} (rig knows the STM32G4 family; the rig's Nucleo-G474RE is {DEFAULT_CHIP})",
                chain(&e)
            ),
        }
    })
}

/// The flash sectors programming an image erases.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct ErasePlan {
    /// The flash algorithm probe-rs uses.
    pub algorithm: String,
    /// Contiguous erased ranges `[start, end)`.
    pub ranges: Vec<(u64, u64)>,
    /// Number of sectors erased.
    pub sectors: usize,
    /// Bytes erased.
    pub bytes: u64,
}

/// The sectors of `target`'s flash that programming `image` erases (probe-rs erases exactly
/// the sectors that receive data, as no chip erase is asked for). Refuses a plan that would
/// touch the calibration store, or data the chip has no flash for.
pub fn erase_plan(
    target: &Target,
    image: &FirmwareImage,
    map: &MemoryMap,
) -> Result<ErasePlan, RigError> {
    let mut sectors: Vec<(u64, u64)> = Vec::new();
    let mut algorithm = String::new();
    for seg in &image.segments {
        let (start, end) = (u64::from(seg.address), seg.end());
        let nvm = target
            .memory_map
            .iter()
            .filter_map(|r| match r {
                MemoryRegion::Nvm(n) if !n.is_alias => Some(n),
                _ => None,
            })
            .find(|n| n.range.start <= start && end <= n.range.end)
            .ok_or_else(|| RigError::BadValue {
                what: format!("--chip {}", target.name),
                why: format!(
                    "has no flash at {start:#010x}..{end:#010x} where the image has data: the image is for another chip"
                ),
            })?;
        let algo = target
            .flash_algorithms
            .iter()
            .filter(|a| {
                let r = &a.flash_properties.address_range;
                r.start <= nvm.range.start && nvm.range.end <= r.end
            })
            .max_by_key(|a| a.default)
            .ok_or_else(|| RigError::BadValue {
                what: format!("--chip {}", target.name),
                why: "probe-rs has no flash algorithm for its flash".into(),
            })?;
        algorithm.clone_from(&algo.name);
        let props = &algo.flash_properties;
        let mut addr = start;
        while addr < end {
            let offset = addr - props.address_range.start;
            let desc = props
                .sectors
                .iter()
                .rev()
                .find(|d| d.address <= offset && d.size > 0)
                .ok_or_else(|| RigError::BadValue {
                    what: format!("--chip {}", target.name),
                    why: format!("probe-rs describes no flash sector at {addr:#010x}"),
                })?;
            let index = (offset - desc.address) / desc.size;
            let sector_start = props.address_range.start + desc.address + index * desc.size;
            let sector_end = sector_start + desc.size;
            if sectors.last() != Some(&(sector_start, sector_end)) {
                sectors.push((sector_start, sector_end));
            }
            addr = sector_end;
        }
    }
    sectors.sort_unstable();
    sectors.dedup();
    if let Some(&(s, e)) = sectors.iter().find(|(s, e)| map.storage.overlaps(*s, *e)) {
        return Err(RigError::BadValue {
            what: "rig flash".into(),
            why: format!(
                "programming this image would erase the flash sector {s:#010x}..{e:#010x}, which holds part of the calibration store {}: refused; make the image smaller",
                map.storage
            ),
        });
    }
    let bytes = sectors.iter().map(|(s, e)| e - s).sum();
    let mut ranges: Vec<(u64, u64)> = Vec::new();
    for &(s, e) in &sectors {
        match ranges.last_mut() {
            Some(last) if last.1 == s => last.1 = e,
            _ => ranges.push((s, e)),
        }
    }
    Ok(ErasePlan {
        algorithm,
        ranges,
        sectors: sectors.len(),
        bytes,
    })
}

/// The probes plugged in, as `name (vid:pid serial)`.
pub fn list() -> Vec<String> {
    Lister::new()
        .list_all_with_access()
        .into_iter()
        .map(|p| {
            let mut s = p.info.to_string();
            if p.accessibility == Accessibility::PermissionDenied {
                s.push_str(" [no permission]");
            }
            s
        })
        .collect()
}

/// Opens the one debug probe plugged in (or the one `selector`, `VID:PID[:SERIAL]`, names).
/// Returns the probe and its description.
pub fn open(selector: Option<&str>) -> Result<(Probe, String), RigError> {
    let lister = Lister::new();
    let selector: Option<DebugProbeSelector> = selector
        .map(|s| {
            s.parse().map_err(|e| RigError::BadValue {
                what: format!("--probe {s}"),
                why: format!(
                    "{} (give VID:PID or VID:PID:SERIAL in hex, e.g. 0483:374b)",
                    chain(&e)
                ),
            })
        })
        .transpose()?;
    let items = lister.list_with_access(selector.as_ref());
    if items.is_empty() {
        let all = list();
        let why = match &selector {
            Some(sel) => format!(
                "no debug probe matches --probe {sel}; plugged in: {}",
                if all.is_empty() {
                    "none".into()
                } else {
                    all.join(", ")
                }
            ),
            None => help::no_probe(&all),
        };
        return Err(RigError::BadValue {
            what: PROBE.into(),
            why,
        });
    }
    let (usable, denied): (Vec<_>, Vec<_>) = items
        .into_iter()
        .partition(|p| p.accessibility == Accessibility::Accessible);
    let info = match usable.as_slice() {
        [] => {
            let names: Vec<_> = denied.iter().map(|p| p.info.to_string()).collect();
            return Err(RigError::BadValue {
                what: PROBE.into(),
                why: help::permission_denied(&names.join(", ")),
            });
        }
        [one] => one.info.clone(),
        many => {
            return Err(RigError::BadValue {
                what: PROBE.into(),
                why: format!(
                    "{} probes are plugged in ({}): choose one with --probe VID:PID:SERIAL",
                    many.len(),
                    many.iter()
                        .map(|p| {
                            let sel = DebugProbeSelector::from(&p.info);
                            format!("{} = --probe {sel}", p.info.identifier)
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
    };
    let name = info.to_string();
    let probe = info.open().map_err(|e| RigError::BadValue {
        what: PROBE.into(),
        why: if is_permission_denied(&e) {
            help::permission_denied(&name)
        } else {
            format!(
                "cannot open {name}: {}; unplug and replug it, and close other programs that use it (probe-rs, OpenOCD, STM32CubeProgrammer)",
                chain(&e)
            )
        },
    })?;
    Ok((probe, name))
}

/// Attaches to the chip without resetting it (a running firmware keeps running).
pub fn attach(probe: Probe, chip: &str, probe_name: &str) -> Result<Session, RigError> {
    let registry = registry()?;
    target(chip)?;
    probe
        .attach_with_registry(chip, Permissions::default(), &registry)
        .map_err(|e| RigError::BadValue {
            what: PROBE.into(),
            why: format!(
                "{probe_name} cannot reach the {chip}: {}; check that the board is powered, that the probe's SWD lines reach the chip (on a Nucleo: the ST-LINK jumpers in their default position) and that --chip names the chip on the board",
                chain(&e)
            ),
        })
}

pub use super::FlashTimes;

/// Programs `image` (only the sectors it touches, no chip erase), reads it back, and resets
/// the chip so the new firmware runs. `show_progress` draws bars on stderr.
pub fn program(
    session: &mut Session,
    image: &FirmwareImage,
    show_progress: bool,
) -> Result<FlashTimes, RigError> {
    let mut loader = session.target().flash_loader();
    for seg in &image.segments {
        loader
            .add_data(u64::from(seg.address), &seg.data)
            .map_err(|e| RigError::BadValue {
                what: "rig flash".into(),
                why: format!("probe-rs refuses the image: {}", chain(&e)),
            })?;
    }
    let bars = Bars::new(show_progress);
    let mut times = FlashTimes {
        erase_s: 0.0,
        program_s: 0.0,
        verify_s: 0.0,
        total_s: 0.0,
    };
    let started = Instant::now();
    let mut phase_start = [None::<Instant>; 4];
    let mut durations = [0.0f64; 4];
    {
        let mut options = DownloadOptions::default();
        options.verify = true;
        options.do_chip_erase = false;
        options.keep_unwritten_bytes = false;
        options.progress = FlashProgress::new(|event| {
            bars.event(&event);
            match event {
                ProgressEvent::Started(op) => phase_start[slot(op)] = Some(Instant::now()),
                ProgressEvent::Finished(op) | ProgressEvent::Failed(op) => {
                    if let Some(t) = phase_start[slot(op)] {
                        durations[slot(op)] += t.elapsed().as_secs_f64();
                    }
                }
                _ => {}
            }
        });
        loader
            .commit(session, options)
            .map_err(|e| RigError::BadValue {
                what: "rig flash".into(),
                why: format!(
                    "programming failed: {}; the chip may hold a partial image now: run rig flash again (the calibration store was not erased)",
                    chain(&e)
                ),
            })?;
    }
    bars.clear();
    session
        .core(0)
        .and_then(|mut core| core.reset())
        .map_err(|e| RigError::BadValue {
            what: "rig flash".into(),
            why: format!(
                "the image is programmed and verified but the reset failed: {}; press the board's reset button (B2)",
                chain(&e)
            ),
        })?;
    times.erase_s = durations[slot(ProgressOperation::Erase)];
    times.program_s = durations[slot(ProgressOperation::Program)];
    times.verify_s = durations[slot(ProgressOperation::Verify)];
    times.total_s = started.elapsed().as_secs_f64();
    Ok(times)
}

/// Index of an operation in the timing arrays.
fn slot(op: ProgressOperation) -> usize {
    match op {
        ProgressOperation::Fill => 0,
        ProgressOperation::Erase => 1,
        ProgressOperation::Program => 2,
        ProgressOperation::Verify => 3,
    }
}

/// One indicatif bar per flashing phase.
struct Bars {
    multi: MultiProgress,
    bars: std::cell::RefCell<[Option<ProgressBar>; 4]>,
}

impl Bars {
    fn new(show: bool) -> Self {
        let target = if show {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        Self {
            multi: MultiProgress::with_draw_target(target),
            bars: Default::default(),
        }
    }

    fn event(&self, event: &ProgressEvent) {
        let mut bars = self.bars.borrow_mut();
        match event {
            ProgressEvent::AddProgressBar { operation, total } => {
                let bar = self.multi.add(ProgressBar::new(total.unwrap_or(0)));
                if let Ok(style) = ProgressStyle::with_template(
                    "{prefix:>9} [{bar:30}] {bytes:>9}/{total_bytes:<9} {msg}",
                ) {
                    bar.set_style(style.progress_chars("=> "));
                }
                bar.set_prefix(match operation {
                    ProgressOperation::Fill => "Reading",
                    ProgressOperation::Erase => "Erasing",
                    ProgressOperation::Program => "Writing",
                    ProgressOperation::Verify => "Verifying",
                });
                bars[slot(*operation)] = Some(bar);
            }
            ProgressEvent::Progress {
                operation, size, ..
            } => {
                if let Some(bar) = &bars[slot(*operation)] {
                    bar.inc(*size);
                }
            }
            ProgressEvent::Finished(op) => {
                if let Some(bar) = &bars[slot(*op)] {
                    bar.finish_with_message("done");
                }
            }
            ProgressEvent::Failed(op) => {
                if let Some(bar) = &bars[slot(*op)] {
                    bar.abandon_with_message("failed");
                }
            }
            _ => {}
        }
    }

    fn clear(&self) {
        let _ = self.multi.clear();
    }
}

/// Reads `len` bytes of the chip's memory at `address` (the core keeps running).
pub fn read_memory(session: &mut Session, address: u64, len: usize) -> Result<Vec<u8>, RigError> {
    let mut buf = vec![0u8; len];
    session
        .core(0)
        .and_then(|mut core| core.read(address, &mut buf))
        .map_err(|e| RigError::BadValue {
            what: PROBE.into(),
            why: format!(
                "cannot read the chip's memory at {address:#010x}: {}",
                chain(&e)
            ),
        })?;
    Ok(buf)
}

/// Time to wait before reading an idle RTT buffer again.
pub const RTT_POLL: Duration = Duration::from_millis(10);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flash::image::Segment;

    fn image(segments: Vec<Segment>) -> FirmwareImage {
        FirmwareImage {
            entry: 0x0800_01d9,
            initial_sp: 0x2001_8000,
            reset_vector: 0x0800_01d9,
            segments,
            identity: None,
            rtt_address: None,
            has_defmt: false,
        }
    }

    #[test]
    fn the_g474re_is_known_and_typos_get_suggestions() {
        let t = target(DEFAULT_CHIP).unwrap();
        assert_eq!(t.name, DEFAULT_CHIP);
        let e = target("STM32G474XYZ").unwrap_err().to_string();
        assert!(e.contains("--chip STM32G474XYZ"), "{e}");
        assert!(e.contains("STM32G474RETx"), "{e}");
        // The whole family is there (the rig could be rebuilt on another G4 Nucleo).
        assert!(target("STM32G431RBTx").is_ok());
    }

    #[test]
    fn only_the_2_kib_pages_under_the_image_are_erased() {
        let t = target(DEFAULT_CHIP).unwrap();
        let map = MemoryMap::board().unwrap();
        // 0x0800_0000..0x0800_0801 spans two pages; 0x0800_4000..0x0800_4010 one more.
        let img = image(vec![
            Segment {
                address: 0x0800_0000,
                data: vec![0; 0x801],
            },
            Segment {
                address: 0x0800_4000,
                data: vec![0; 16],
            },
        ]);
        let plan = erase_plan(&t, &img, &map).unwrap();
        assert_eq!(plan.sectors, 3);
        assert_eq!(plan.bytes, 3 * 2048);
        assert_eq!(
            plan.ranges,
            vec![(0x0800_0000, 0x0800_1000), (0x0800_4000, 0x0800_4800)]
        );
    }

    #[test]
    fn a_plan_touching_the_calibration_store_is_refused() {
        let t = target(DEFAULT_CHIP).unwrap();
        let map = MemoryMap::board().unwrap();
        let img = image(vec![Segment {
            address: 0x0807_BFF0,
            data: vec![0; 0x20],
        }]);
        let e = erase_plan(&t, &img, &map).unwrap_err().to_string();
        assert!(e.contains("calibration store"), "{e}");
        // The last page before the store is fine.
        let img = image(vec![Segment {
            address: 0x0807_B800,
            data: vec![0; 0x800],
        }]);
        assert_eq!(
            erase_plan(&t, &img, &map).unwrap().ranges,
            vec![(0x0807_B800, 0x0807_C000)]
        );
    }

    #[test]
    fn permission_errors_are_recognised_through_causes() {
        #[derive(Debug)]
        struct Outer(std::io::Error);
        impl std::fmt::Display for Outer {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("cannot open the USB device")
            }
        }
        impl StdError for Outer {
            fn source(&self) -> Option<&(dyn StdError + 'static)> {
                Some(&self.0)
            }
        }
        let e = Outer(std::io::Error::from(std::io::ErrorKind::PermissionDenied));
        assert!(is_permission_denied(&e));
        assert!(chain(&e).starts_with("cannot open the USB device: "));
        let e = Outer(std::io::Error::from(std::io::ErrorKind::NotFound));
        assert!(!is_permission_denied(&e));
    }
}
