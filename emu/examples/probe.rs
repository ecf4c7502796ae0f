//! Runs an image and samples a RAM byte every 10 ms (debugging aid).
fn main() {
    let elf = std::env::args().nth(1).unwrap();
    let addr = u32::from_str_radix(
        std::env::args().nth(2).unwrap().trim_start_matches("0x"),
        16,
    )
    .unwrap();
    let gear = model::GearSet::paper(model::paper::RIG_Z).unwrap();
    let plant = model::plant::PlantParams::paper(gear, model::plant::Load::Torque(0.0));
    let mut b = emu::Board::new(emu::BoardConfig {
        elf: elf.into(),
        plant,
        seed: 1,
        time_scale: None,
    })
    .unwrap();
    b.advance(2.2).unwrap();
    for k in 0..40 {
        b.advance(0.01).unwrap();
        let mut v = [0u8; 4];
        b.machine().mem().read(addr, &mut v);
        let m = b.machine_mut();
        let now = m.cycles();
        println!(
            "iwdg reloads {} now {} resets {:?} usart cr1 {:x} cr3 {:x} dma3 ccr {:x} rem {} faults {:?}",
            m.bus.iwdg.reloads,
            now,
            m.resets,
            m.bus.usart.read(0).unwrap(),
            m.bus.usart.cr3,
            m.bus.dma.ch[2].ccr,
            m.bus.dma.ch[2].remaining,
            m.faults
        );
        println!(
            "{k}: {:02x?} tim2 cnt {} sr {:x} dier {:x} ccr2 {:?} exc {:?}",
            v,
            m.bus.tim2.cnt(now, 0),
            m.bus.tim2.sr,
            m.bus.tim2.dier,
            m.bus.tim2.read(0x38, now, 0),
            m.exceptions_taken
        );
    }
}
