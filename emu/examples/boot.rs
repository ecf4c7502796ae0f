//! Boots an image and prints what it did.
fn main() {
    let elf = std::env::args().nth(1).expect("usage: boot ELF [seconds]");
    let secs: f64 = std::env::args().nth(2).map_or(0.05, |s| s.parse().unwrap());
    let gear = model::GearSet::paper(model::paper::RIG_Z).unwrap();
    let plant = model::plant::PlantParams::paper(gear, model::plant::Load::Torque(0.0));
    let mut b = emu::Board::new(emu::BoardConfig {
        elf: elf.into(),
        plant,
        seed: 1,
        time_scale: None,
    })
    .unwrap();
    let t = std::time::Instant::now();
    let r = b.advance(secs);
    let m = b.machine();
    let regs = m.registers();
    println!(
        "{r:?} after {:?}: device {:.4} s, pc {}",
        t.elapsed(),
        b.time(),
        m.where_is(regs[15])
    );
    println!(
        "exceptions {:?}, resets {:?}, lockup {:?}",
        m.exceptions_taken, m.resets, m.lockup
    );
    for f in m.faults.iter().take(5) {
        println!("fault {f:?}");
    }
    for (a, (pc, w)) in m.unmodelled() {
        println!(
            "unmodelled {a:#010x} {} at {}",
            if *w { "write" } else { "read" },
            m.where_is(*pc)
        );
    }
    let mut out = Vec::new();
    b.from_device(&mut out);
    println!("uart out {} bytes", out.len());
    println!("lowest sp {:#x}", b.machine().lowest_sp());
}
