//! The release firmware image on the emulated board: it boots, runs its control loop
//! from the ADC, and answers on its UART.
//!
//! These tests need the image (`cargo xtask firmware`) and the Unicorn engine (`cargo
//! xtask setup`); `cargo xtask test` provides both and sets `RIG_REQUIRE_EMULATOR`, which
//! turns their absence into a failure. Run by hand without them, they skip with a message.

use std::path::PathBuf;

use protocol::{Deframer, DeviceMessage, Reply, Request};

/// Both release images (braking, the default, and coasting) where `cargo xtask firmware
/// --both` kept them, else the last one built; empty (skipped, with a message) when this
/// machine lacks the images or the emulator, unless RIG_REQUIRE_EMULATOR is set.
fn images() -> Vec<PathBuf> {
    let release =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/thumbv7em-none-eabihf/release");
    let mut elfs: Vec<PathBuf> = ["firmware-brake", "firmware-coast"]
        .iter()
        .map(|n| release.join(n))
        .filter(|p| p.exists())
        .collect();
    if elfs.is_empty() && release.join("firmware").exists() {
        elfs.push(release.join("firmware"));
    }
    let missing = if elfs.is_empty() {
        Some(format!(
            "no firmware image in {} (cargo xtask firmware)",
            release.display()
        ))
    } else {
        emu::emulator().err().map(|e| e.to_string())
    };
    match missing {
        None => elfs,
        Some(why) if std::env::var_os("RIG_REQUIRE_EMULATOR").is_some() => panic!("{why}"),
        Some(why) => {
            eprintln!("skipped: {why}");
            Vec::new()
        }
    }
}

fn board(elf: PathBuf) -> emu::Board {
    emu::Board::new(emu::BoardConfig::paper(elf)).unwrap()
}

/// Sends `req` and runs the board until a reply comes (device time, at most `within_s`).
fn ask(b: &mut emu::Board, seq: u16, req: &Request, within_s: f64) -> Reply {
    b.to_device(&protocol::encode_frame_vec(seq, req).unwrap());
    let mut deframer: Deframer<DeviceMessage, 512> = Deframer::default();
    let start = b.time();
    let mut out = Vec::new();
    while b.time() - start < within_s {
        b.advance(1e-3).unwrap();
        out.clear();
        b.from_device(&mut out);
        let mut reply = None;
        deframer.push(&out, |f| {
            if let Ok(f) = f
                && let DeviceMessage::Reply {
                    request_seq,
                    reply: r,
                } = f.msg
                && request_seq == seq
            {
                reply = Some(r);
            }
        });
        if let Some(r) = reply {
            return r;
        }
    }
    panic!("no reply to {req:?} within {within_s} s of device time");
}

#[test]
fn the_release_images_boot_run_their_control_loop_and_answer_hello() {
    for elf in images() {
        let name = elf.display().to_string();
        let mut b = board(elf);
        b.advance(0.05).unwrap();
        let m = b.machine();
        assert!(
            m.faults.is_empty(),
            "{name}: faults at boot: {:?}",
            m.faults
        );
        assert!(
            m.resets.is_empty(),
            "{name}: resets at boot: {:?}",
            m.resets
        );
        assert!(
            m.unmodelled().is_empty(),
            "{name}: the image touched unmodelled addresses: {:x?}",
            m.unmodelled()
        );
        assert!(
            m.bus.lockup_breaks_tim1(),
            "{name}: SYSCFG_CFGR2.CLL clear after boot"
        );
        // The control executor (UART4's vector, IRQ 52) runs once per 1 ms ADC block: 50
        // in 50 ms less the boot's first milliseconds.
        let steps = m.exceptions_taken.get(&(16 + 52)).copied().unwrap_or(0);
        assert!(
            (40..=50).contains(&steps),
            "{name}: {steps} control steps in 50 ms"
        );
        let reply = ask(
            &mut b,
            1,
            &Request::Hello {
                protocol_version: protocol::PROTOCOL_VERSION,
                schema_hash: protocol::SCHEMA_HASH,
            },
            0.1,
        );
        let Reply::Info(info) = reply else {
            panic!("{name}: Hello answered {reply:?}")
        };
        assert_eq!(info.protocol_version, protocol::PROTOCOL_VERSION);
        assert_eq!(info.board.as_str(), "nucleo-g474re");
        assert_eq!(info.time_scale, 1.0, "{name}: a board's own pace");
        let braking = info
            .capabilities
            .contains(protocol::Capabilities::BRAKING_DECAY);
        assert_eq!(
            braking,
            !name.ends_with("coast"),
            "{name}: the image's bridge"
        );
    }
}

#[test]
fn the_pace_the_emulator_writes_is_what_the_image_reports() {
    for elf in images().into_iter().take(1) {
        let mut b = emu::Board::new(emu::BoardConfig {
            time_scale: Some(0.25),
            ..emu::BoardConfig::paper(elf)
        })
        .unwrap();
        b.advance(0.03).unwrap();
        let req = Request::Hello {
            protocol_version: protocol::PROTOCOL_VERSION,
            schema_hash: protocol::SCHEMA_HASH,
        };
        let Reply::Info(info) = ask(&mut b, 7, &req, 0.1) else {
            panic!("no Info")
        };
        assert_eq!(info.time_scale, 0.25);
    }
}
