//! The target bench's closed-loop run (`cargo xtask target-bench`): the image on the
//! emulated board, a 10 Hz release held for SECONDS of device time with heartbeats every
//! 0.1 s as a host sends them, then one JSON line: the lowest stack pointer over boot and
//! the run against the MPU guard's top, the resets, faults and unmodelled accesses seen,
//! and whether the bridge still drives (the release stayed live).
//!
//! `cargo run -p emu --example closed_loop -- ELF [SECONDS]`

use protocol::Request;

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(elf) = args.next() else {
        eprintln!("usage: closed_loop ELF [SECONDS]");
        std::process::exit(2);
    };
    let seconds: f64 = args.next().map_or(10.0, |s| s.parse().unwrap_or(10.0));
    let mut b = match emu::Board::new(emu::BoardConfig::paper(&elf)) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("closed_loop: {e}");
            std::process::exit(1);
        }
    };
    let send = |b: &mut emu::Board, seq: u16, req: &Request| {
        b.to_device(&protocol::encode_frame_vec(seq, req).expect("requests encode"));
    };
    let step = |b: &mut emu::Board, s: f64| {
        if let Err(e) = b.advance(s) {
            eprintln!("closed_loop: {e}");
            std::process::exit(1);
        }
        let mut out = Vec::new();
        b.from_device(&mut out);
    };
    step(&mut b, 0.1);
    let hello = Request::Hello {
        protocol_version: protocol::PROTOCOL_VERSION,
        schema_hash: protocol::SCHEMA_HASH,
    };
    send(&mut b, 1, &hello);
    step(&mut b, 0.01);
    send(
        &mut b,
        2,
        &Request::Release {
            on: true,
            target_hz: 10.0,
            session: 1,
        },
    );
    let mut seq = 2u16;
    let ticks = (seconds / 0.1).round() as usize;
    for _ in 0..ticks {
        seq = seq.wrapping_add(1);
        send(&mut b, seq, &Request::Heartbeat { session: 1 });
        step(&mut b, 0.1);
    }
    let m = b.machine();
    let guard_top = m.bus.scs.guard().map(|(base, size)| base + size);
    let margin = guard_top.map(|top| i64::from(m.lowest_sp()) - i64::from(top));
    println!(
        "{{\"seconds\":{seconds},\"lowest_sp\":{},\"guard_top\":{},\"stack_margin_bytes\":{},\"resets\":{},\"faults\":{},\"unmodelled\":{},\"bridge_enabled\":{}}}",
        m.lowest_sp(),
        guard_top.map_or("null".into(), |t| t.to_string()),
        margin.map_or("null".into(), |t| t.to_string()),
        m.resets.len(),
        m.faults.len(),
        m.unmodelled().len(),
        b.bridge().enable
    );
}
