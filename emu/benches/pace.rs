//! The emulated board's speed as a ratio to real time on this machine: the release image
//! booted, then run with the gear locked and during a 10 Hz release (heartbeats sent as a
//! host would), one core. Needs the image (`cargo xtask firmware`) and the emulator
//! (`cargo xtask setup`). `cargo bench -p emu --bench pace`.

use std::path::PathBuf;
use std::time::Instant;

use protocol::Request;

fn board() -> emu::Board {
    let elf = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../target/thumbv7em-none-eabihf/release/firmware-brake");
    emu::Board::new(emu::BoardConfig::paper(elf)).unwrap_or_else(|e| panic!("{e}"))
}

fn send(b: &mut emu::Board, seq: u16, req: &Request) {
    b.to_device(&protocol::encode_frame_vec(seq, req).unwrap());
}

/// Device seconds per wall second over `seconds` of device time, heartbeats every 0.1 s
/// when `release`.
fn ratio(b: &mut emu::Board, seconds: f64, release: bool, seq: &mut u16) -> f64 {
    let start = Instant::now();
    let steps = (seconds / 0.1).round() as usize;
    for _ in 0..steps {
        if release {
            *seq += 1;
            send(b, *seq, &Request::Heartbeat { session: 1 });
        }
        b.advance(0.1).unwrap();
        let mut out = Vec::new();
        b.from_device(&mut out);
    }
    seconds / start.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    if emu::emulator().is_err() {
        eprintln!("pace: skipped, {}", emu::emulator().unwrap_err());
        return;
    }
    let mut b = board();
    let mut seq = 0u16;
    b.advance(0.2).unwrap();
    let locked: Vec<f64> = (0..5)
        .map(|_| ratio(&mut b, 1.0, false, &mut seq))
        .collect();
    seq += 1;
    send(
        &mut b,
        seq,
        &Request::Hello {
            protocol_version: protocol::PROTOCOL_VERSION,
            schema_hash: protocol::SCHEMA_HASH,
        },
    );
    b.advance(0.01).unwrap();
    seq += 1;
    send(
        &mut b,
        seq,
        &Request::Release {
            on: true,
            target_hz: 10.0,
            session: 1,
        },
    );
    // Spin-up, then the measured runs.
    ratio(&mut b, 2.0, true, &mut seq);
    let released: Vec<f64> = (0..5).map(|_| ratio(&mut b, 1.0, true, &mut seq)).collect();
    assert!(
        b.bridge().enable,
        "the release stayed live (heartbeats kept it)"
    );
    let show = |v: &[f64]| {
        format!(
            "min {:.2}x, median {:.2}x, max {:.2}x",
            v.iter().copied().fold(f64::INFINITY, f64::min),
            median(v.to_vec()),
            v.iter().copied().fold(0.0, f64::max)
        )
    };
    println!(
        "emulated board, gear locked:      {} real time (5 runs of 1 s)",
        show(&locked)
    );
    println!(
        "emulated board, 10 Hz release:    {} real time (5 runs of 1 s)",
        show(&released)
    );
}
