//! The release firmware image on the emulated board: it boots, runs its control loop
//! from the ADC, and answers on its UART.
//!
//! These tests need the image (`cargo xtask firmware`) and the Unicorn engine (`cargo
//! xtask setup`); `cargo xtask test` provides both and sets `RIG_REQUIRE_EMULATOR`, which
//! turns their absence into a failure. Run by hand without them, they skip with a message.

use std::path::PathBuf;

use model::plant::{Load, PlantParams};
use protocol::{Deframer, DeviceMessage, Reply, Request};

fn image() -> Option<PathBuf> {
    let elf = std::env::var_os("RIG_FIRMWARE_ELF")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../target/thumbv7em-none-eabihf/release/firmware")
        });
    let missing = if !elf.exists() {
        Some(format!(
            "no firmware image at {} (cargo xtask firmware)",
            elf.display()
        ))
    } else {
        emu::emulator().err().map(|e| e.to_string())
    };
    match missing {
        None => Some(elf),
        Some(why) if std::env::var_os("RIG_REQUIRE_EMULATOR").is_some() => panic!("{why}"),
        Some(why) => {
            eprintln!("skipped: {why}");
            None
        }
    }
}

fn board(elf: PathBuf) -> emu::Board {
    let gear = model::GearSet::paper(model::paper::RIG_Z).unwrap();
    emu::Board::new(emu::BoardConfig {
        elf,
        plant: PlantParams::paper(gear, Load::Torque(0.0)),
        seed: 1,
        time_scale: None,
    })
    .unwrap()
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
fn the_release_image_boots_runs_its_control_loop_and_answers_hello() {
    let Some(elf) = image() else { return };
    let mut b = board(elf);
    b.advance(0.05).unwrap();
    let m = b.machine();
    assert!(m.faults.is_empty(), "faults at boot: {:?}", m.faults);
    assert!(m.resets.is_empty(), "resets at boot: {:?}", m.resets);
    assert!(
        m.unmodelled().is_empty(),
        "the image touched unmodelled addresses: {:x?}",
        m.unmodelled()
    );
    // The control executor (UART4's vector, IRQ 52) runs once per 1 ms ADC block.
    let steps = m.exceptions_taken.get(&(16 + 52)).copied().unwrap_or(0);
    assert!((40..=55).contains(&steps), "{steps} control steps in 50 ms");
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
        panic!("Hello answered {reply:?}")
    };
    assert_eq!(info.protocol_version, protocol::PROTOCOL_VERSION);
    assert_eq!(info.board.as_str(), "nucleo-g474re");
}
