//! `rig flash` and `rig log` from the outside: the image checks on the real firmware ELF and
//! on wrong ones, the path without a probe, and offline decoding of a recorded defmt stream.
//!
//! The real firmware ELF comes from `RIG_FIRMWARE_ELF` (`cargo xtask test` builds the
//! release firmware first and sets it); without it those tests say they are skipped.

use std::path::{Path, PathBuf};

use assert_cmd::Command;

mod support {
    pub mod tiny_elf;
}
use support::tiny_elf;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").unwrap();
    c.env_remove("RIG_PORT");
    c
}

/// The release firmware ELF, when the test runner was given one.
fn firmware_elf() -> Option<PathBuf> {
    match std::env::var_os("RIG_FIRMWARE_ELF").map(PathBuf::from) {
        Some(p) if p.is_file() => Some(p),
        Some(p) => panic!("RIG_FIRMWARE_ELF={} does not exist", p.display()),
        None => {
            eprintln!(
                "skipped: RIG_FIRMWARE_ELF is not set (cargo xtask test sets it to the release firmware)"
            );
            None
        }
    }
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[cfg_attr(not(feature = "probe"), allow(dead_code))]
fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/defmt")
        .join(name)
}

#[test]
fn dry_run_accepts_the_real_firmware() {
    let Some(elf) = firmware_elf() else { return };
    let out = rig()
        .args(["flash", "--dry-run", "--json", "--elf"])
        .arg(&elf)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["dry_run"], true);
    assert_eq!(r["chip"], "STM32G474RETx");
    assert_eq!(r["version"], env!("CARGO_PKG_VERSION"));
    let build = r["build"].as_str().unwrap();
    assert!(!build.is_empty() && build.len() <= 20, "{build}");
    assert_eq!(r["initial_sp"], "0x20018000");
    assert!(r["image"].as_str().unwrap().starts_with("0x08000000.."));
    assert_eq!(r["calibration_store"], "0x0807c000..0x08080000");
    assert_eq!(r["log_ready"], true);
    // Whole 2 KiB pages from the start of flash, all below the store.
    if let Some(erase) = r["erase"].as_array() {
        for range in erase {
            let end = range.as_str().unwrap().split("..").nth(1).unwrap();
            let end = u64::from_str_radix(end.trim_start_matches("0x"), 16).unwrap();
            assert!(end <= 0x0807_C000 && end % 2048 == 0, "{range}");
        }
    }
    // The text form says what it would do.
    let out = rig()
        .args(["flash", "--dry-run", "--elf"])
        .arg(&elf)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(text.contains("dry run: nothing was touched"), "{text}");
    assert!(
        text.contains("calibration store 0x0807c000..0x08080000 is kept"),
        "{text}"
    );
}

#[test]
fn the_rig_executable_is_not_firmware() {
    for dry in [true, false] {
        let mut c = rig();
        c.arg("flash").arg("--elf").arg(env!("CARGO_BIN_EXE_rig"));
        if dry {
            c.arg("--dry-run");
        }
        let out = c.output().unwrap();
        assert!(!out.status.success());
        let e = stderr(&out);
        assert!(
            e.contains("64-bit") && e.contains("not the firmware"),
            "{e}"
        );
        assert!(e.contains("thumbv7em-none-eabihf"), "{e}");
        assert!(!e.contains("panicked"), "{e}");
    }
}

#[test]
fn an_image_overlapping_the_calibration_store_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let synthetic = dir.path().join("too-long.elf");
    std::fs::write(&synthetic, tiny_elf::cortex_m_into_storage(512)).unwrap();
    let mut images = vec![synthetic];
    // The real firmware with its last flash segment moved so it ends inside the store.
    if let Some(elf) = firmware_elf() {
        let patched = dir.path().join("firmware-moved.elf");
        std::fs::write(
            &patched,
            move_last_segment_into_storage(&std::fs::read(elf).unwrap()),
        )
        .unwrap();
        images.push(patched);
    }
    for image in images {
        let out = rig()
            .args(["flash", "--dry-run", "--elf"])
            .arg(&image)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{}", image.display());
        let e = stderr(&out);
        assert!(
            e.contains("reaches into the calibration store 0x0807c000..0x08080000"),
            "{e}"
        );
        assert!(e.contains("would erase the stored calibration"), "{e}");
    }
}

/// Rewrites the program headers of an ELF32 so that its highest loaded segment starts 64
/// bytes before the calibration store (and so runs into it).
fn move_last_segment_into_storage(elf: &[u8]) -> Vec<u8> {
    let mut out = elf.to_vec();
    let u32_at = |b: &[u8], o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let phoff = u32_at(elf, 28) as usize;
    let phentsize = u16::from_le_bytes([elf[42], elf[43]]) as usize;
    let phnum = u16::from_le_bytes([elf[44], elf[45]]) as usize;
    let last = (0..phnum)
        .map(|i| phoff + i * phentsize)
        .filter(|&h| u32_at(elf, h) == 1 && u32_at(elf, h + 16) > 64) // PT_LOAD with data
        .max_by_key(|&h| u32_at(elf, h + 12))
        .expect("a loadable segment");
    let paddr = tiny_elf::STORAGE - 64;
    out[last + 12..last + 16].copy_from_slice(&paddr.to_le_bytes());
    if u32_at(elf, last + 8) == u32_at(elf, last + 12) {
        out[last + 8..last + 12].copy_from_slice(&paddr.to_le_bytes());
    }
    out
}

#[cfg(feature = "probe")]
#[test]
fn flashing_without_a_probe_names_what_is_missing() {
    let plugged = host::flash::probe::list();
    if !plugged.is_empty() {
        eprintln!("skipped: debug probes are plugged in ({plugged:?}); this test needs none");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.elf");
    std::fs::write(&good, tiny_elf::cortex_m(4096)).unwrap();
    // The image is fine: a dry run passes.
    rig()
        .args(["flash", "--dry-run", "--elf"])
        .arg(&good)
        .assert()
        .success();
    let out = rig().args(["flash", "--elf"]).arg(&good).output().unwrap();
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(e.contains("no debug probe found"), "{e}");
    assert!(e.contains("found: none"), "{e}");
    assert!(e.contains("ST-LINK") && e.contains("CMSIS-DAP"), "{e}");
    assert!(
        e.contains("cable") && e.contains("udevadm control --reload"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
    // rig log needs the probe too.
    let out = rig()
        .args(["log", "--elf"])
        .arg(fixture("capture.elf"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no debug probe found"),
        "{}",
        stderr(&out)
    );
}

#[cfg(not(feature = "probe"))]
#[test]
fn without_the_probe_feature_flash_says_how_to_get_it() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.elf");
    std::fs::write(&good, tiny_elf::cortex_m(4096)).unwrap();
    rig()
        .args(["flash", "--dry-run", "--elf"])
        .arg(&good)
        .assert()
        .success();
    let out = rig().args(["flash", "--elf"]).arg(&good).output().unwrap();
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("--features probe"),
        "{}",
        stderr(&out)
    );
}

#[cfg(feature = "probe")]
#[test]
fn rig_log_decodes_a_recorded_stream_offline() {
    let out = rig()
        .args(["log", "--decode"])
        .arg(fixture("capture.defmt"))
        .arg("--elf")
        .arg(fixture("capture.elf"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    // What capture/src/main.rs logged, in order; the debug! line is filtered by DEFMT_LOG.
    let expected = [
        (
            "0.000000",
            "INFO",
            "rig firmware 0.1.0 build fixture booted; last reset by the watchdog: false",
        ),
        (
            "0.001250",
            "INFO",
            "reset flags: ResetCause { watchdog: false, software: true, pin: true, brown_out: false }",
        ),
        (
            "0.002500",
            "INFO",
            "no calibration stored: the paper's values",
        ),
        (
            "0.003750",
            "INFO",
            "board up: motor off (max duty 8499), encoder at 0, current ADC @ 10000 Hz, host link @ 921600 Bd",
        ),
        ("0.005000", "INFO", "supervisor: vibrating (faults 0x0000)"),
        ("0.006250", "WARN", "watchdog not fed: check-ins 0b101"),
        ("0.007500", "ERROR", "calibration not stored: flash error"),
        ("0.008750", "INFO", "supervisor: fault (faults 0x0004)"),
    ];
    assert_eq!(lines.len(), expected.len(), "{text}");
    for (line, (t, level, msg)) in lines.iter().zip(expected) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(fields[0], t, "{line}");
        assert_eq!(fields[1], level, "{line}");
        assert!(line.ends_with(msg), "{line}");
    }
    // JSON lines with the source location from the ELF's debug info.
    let out = rig()
        .args(["log", "--json", "--decode"])
        .arg(fixture("capture.defmt"))
        .arg("--elf")
        .arg(fixture("capture.elf"))
        .output()
        .unwrap();
    let first: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().next().unwrap()).unwrap();
    assert_eq!(first["level"], "INFO");
    assert_eq!(first["timestamp"], "0.000000");
    assert!(
        first["file"].as_str().unwrap().ends_with("src/main.rs"),
        "{first}"
    );
    assert!(first["line"].as_u64().unwrap() > 0);
}

#[cfg(feature = "probe")]
#[test]
fn a_stream_with_the_wrong_elf_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = dir.path().join("tiny.elf");
    std::fs::write(&tiny, tiny_elf::cortex_m(64)).unwrap();
    let out = rig()
        .args(["log", "--decode"])
        .arg(fixture("capture.defmt"))
        .arg("--elf")
        .arg(&tiny)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("no defmt table"), "{}", stderr(&out));
    // Bytes that are not this table's frames.
    let junk = dir.path().join("junk.defmt");
    std::fs::write(&junk, [0x55u8; 64]).unwrap();
    let out = rig()
        .args(["log", "--decode"])
        .arg(&junk)
        .arg("--elf")
        .arg(fixture("capture.elf"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no message decodes"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn udev_rules_and_sim_are_answered() {
    let out = rig().args(["flash", "--udev-rules"]).output().unwrap();
    assert!(out.status.success());
    let rules = String::from_utf8_lossy(&out.stdout);
    assert!(rules.contains(r#"ATTRS{idProduct}=="374b""#), "{rules}");
    let out = rig()
        .args(["--sim", "flash", "--dry-run"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("real board"), "{}", stderr(&out));
}
