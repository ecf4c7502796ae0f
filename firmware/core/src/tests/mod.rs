//! Closed-loop tests of the whole core against `model::plant::Plant`, through the wire
//! protocol, as the binary and the host drive it.

mod faults;
mod persist;
mod server;
mod stream;
mod supervisor;

use model::GearSet;
use model::plant::{Drive, Load, Plant, PlantParams};
use protocol::{
    DeviceDeframer, DeviceMessage, FaultFlags, MAX_FRAME_SIZE, NackCode, Reply, Request,
    RigParameters, SupervisorState, encode_frame,
};

use crate::{BootInfo, Core, CoreConfig, Inputs, Outputs, Status};

#[test]
fn core_fits_its_ram_share() {
    // 40 000 bytes of capture plus ~3 KB of state; the board has 64 KiB for statics.
    let size = core::mem::size_of::<Core>();
    assert!((40_000..48_000).contains(&size), "{size} bytes");
}

#[test]
fn the_binary_s_three_reads_agree_with_the_status_snapshot() {
    let mut rig = Rig::new(0.5);
    let agree = |rig: &Rig| {
        let s = rig.core.status();
        assert_eq!(rig.core.state(), s.state);
        assert_eq!(rig.core.latched_faults(), s.latched_faults);
        let zero = (!s.zeroing).then_some(s.current_zero_adc);
        assert_eq!(rig.core.current_zero_adc(), zero);
    };
    // Zeroing at boot: no zero to hand to the trip yet.
    rig.step();
    agree(&rig);
    assert_eq!(rig.core.current_zero_adc(), None);
    rig.run_ms(1_000);
    agree(&rig);
    assert!(rig.core.current_zero_adc().is_some_and(|z| z > 1000.0));
    // Vibrating, then a fault latched.
    rig.vibrate(10.0);
    agree(&rig);
    assert_eq!(rig.core.state(), SupervisorState::Vibrating);
    rig.adc_offset = 2000;
    rig.run_ms(50);
    agree(&rig);
    assert!(!rig.core.latched_faults().is_empty());
}

/// The paper's (49, 51, 50, 50) gear set.
pub(crate) const PAPER_Z: [u32; 4] = model::paper::RIG_Z;

/// Core + plant + a host end of the link, in virtual time (1 ms steps).
pub(crate) struct Rig {
    pub core: Core,
    pub plant: Plant,
    pub now_us: u64,
    drive: Drive,
    host_seq: u16,
    host: DeviceDeframer,
    /// Every device message received, in order.
    pub received: Vec<DeviceMessage>,
    /// The release button.
    pub button: bool,
    /// Added to every current ADC sample (sensor offset or a fault injection).
    pub adc_offset: i32,
    /// Report the encoder count frozen at this value (encoder lost).
    pub encoder_frozen: Option<u16>,
    /// Report the encoder counting backwards (A and B swapped).
    pub encoder_reversed: bool,
    /// How the "binary" answers a flash write (None: never answers).
    pub persist_answer: Option<bool>,
    /// Parameter records handed out for writing.
    pub persisted: Vec<RigParameters>,
    /// Most bytes the link moves per step, a UART's pace (None: everything at once).
    pub link_budget: Option<usize>,
}

impl Rig {
    pub fn new(load_nm: f64) -> Self {
        Self::with(BootInfo::default(), load_nm, |_| {})
    }

    /// A rig with `boot` and a plant built from the paper's with `tweak` applied.
    pub fn with(boot: BootInfo, load_nm: f64, tweak: impl FnOnce(&mut PlantParams)) -> Self {
        Self::with_config(CoreConfig::default(), boot, load_nm, tweak)
    }

    /// As [`Rig::with`], with a core configuration.
    pub fn with_config(
        config: CoreConfig,
        boot: BootInfo,
        load_nm: f64,
        tweak: impl FnOnce(&mut PlantParams),
    ) -> Self {
        let gear = GearSet::paper(PAPER_Z).unwrap();
        let mut params = PlantParams::paper(gear, Load::Torque(load_nm));
        tweak(&mut params);
        Self {
            core: Core::new(config, boot),
            plant: Plant::new(params, 11),
            now_us: 0,
            drive: Drive::default(),
            host_seq: 0,
            host: DeviceDeframer::new(),
            received: Vec::new(),
            button: false,
            adc_offset: 0,
            encoder_frozen: None,
            encoder_reversed: false,
            persist_answer: Some(true),
            persisted: Vec::new(),
            link_budget: None,
        }
    }

    /// One 1 ms control step (the plant advances at 10 kHz in between).
    pub fn step(&mut self) -> Outputs {
        let mut adc = [0u16; 10];
        for a in adc.iter_mut() {
            self.plant.step(1e-4, self.drive);
            *a = (i32::from(self.plant.current_adc()) + self.adc_offset)
                .clamp(0, i32::from(model::hardware::adc::FULL_SCALE)) as u16;
        }
        self.now_us += 1000;
        let out = self.step_with(&adc);
        self.drive = Drive {
            duty: f64::from(out.duty),
            enabled: out.enable,
        };
        out
    }

    /// Steps the core only, with these samples, at the rig's current time.
    pub fn step_with(&mut self, adc: &[u16]) -> Outputs {
        let mut encoder_count = self
            .encoder_frozen
            .unwrap_or_else(|| self.plant.encoder_count());
        if self.encoder_reversed {
            encoder_count = encoder_count.wrapping_neg();
        }
        let out = self.core.step(&Inputs {
            now_us: self.now_us,
            current_adc: adc,
            encoder_count,
            release_button: self.button,
        });
        assert!((-1.0..=1.0).contains(&out.duty));
        if !out.enable {
            assert_eq!(out.duty, 0.0, "a disabled bridge has no duty");
        }
        if let Some(c) = out.persist {
            self.persisted.push(c);
            if let Some(ok) = self.persist_answer {
                self.core.persist_result(ok);
            }
        }
        self.pump();
        out
    }

    /// Moves the core's outgoing bytes to the host end, in small pieces.
    pub fn pump(&mut self) {
        let mut buf = [0u8; 61];
        let mut budget = self.link_budget.unwrap_or(usize::MAX);
        while budget > 0 {
            let take = budget.min(buf.len());
            budget -= take;
            let n = self.core.transmit(&mut buf[..take]);
            if n == 0 {
                break;
            }
            let received = &mut self.received;
            self.host
                .push(&buf[..n], |frame| received.push(frame.unwrap().msg));
        }
    }

    pub fn run_ms(&mut self, ms: u64) {
        for _ in 0..ms {
            self.step();
        }
    }

    /// Runs with a heartbeat every 150 ms, as the host keeps a release alive.
    pub fn run_ms_alive(&mut self, ms: u64) {
        for k in 0..ms {
            if k % 150 == 0 {
                self.send(&Request::Heartbeat { session: 0 });
            }
            self.step();
        }
    }

    /// Runs until `done` or `ms` pass (alive or not); returns the time taken, ms.
    pub fn run_until(
        &mut self,
        ms: u64,
        alive: bool,
        done: impl Fn(&Status) -> bool,
    ) -> Option<u64> {
        for k in 0..ms {
            if alive && k % 150 == 0 {
                self.send(&Request::Heartbeat { session: 0 });
            }
            self.step();
            if done(&self.core.status()) {
                return Some(k + 1);
            }
        }
        None
    }

    /// Requests sent so far (the next request's seq).
    pub fn sent_count(&self) -> u16 {
        self.host_seq
    }

    /// Sends a request (bytes fed one at a time); returns its seq.
    pub fn send(&mut self, request: &Request) -> u16 {
        let seq = self.host_seq;
        self.host_seq = self.host_seq.wrapping_add(1);
        let mut buf = [0u8; MAX_FRAME_SIZE];
        let frame = encode_frame(seq, request, &mut buf).unwrap();
        for b in frame {
            self.core.receive(self.now_us, core::slice::from_ref(b));
        }
        // A paced link sends the reply with the next step's bytes.
        if self.link_budget.is_none() {
            self.pump();
        }
        seq
    }

    /// Sends a request and returns the messages that arrived in reply.
    pub fn request(&mut self, request: &Request) -> Vec<DeviceMessage> {
        let before = self.received.len();
        self.send(request);
        self.received[before..].to_vec()
    }

    /// The single reply to `request`, matched by its seq.
    pub fn reply(&mut self, request: &Request) -> Reply {
        let seq = self.host_seq;
        let replies = self.request(request);
        let answers: Vec<_> = replies
            .iter()
            .filter(|m| m.reply_to() == Some(seq))
            .filter_map(DeviceMessage::as_reply)
            .collect();
        assert_eq!(answers.len(), 1, "{request:?}: {replies:?}");
        answers[0].clone()
    }

    /// The single `Ack`/`Nack` answer to `request`: `Ok(())` or the Nack code.
    pub fn ack(&mut self, request: &Request) -> Result<(), NackCode> {
        match self.reply(request) {
            Reply::Ack => Ok(()),
            Reply::Nack(code) => Err(code),
            other => panic!(
                "{} answered {}, not Ack or Nack",
                request.name(),
                other.name()
            ),
        }
    }

    /// Whether a reply to request `seq` with `pred` has arrived.
    pub fn answered(&self, seq: u16, pred: impl Fn(&Reply) -> bool) -> bool {
        self.received
            .iter()
            .any(|m| m.reply_to() == Some(seq) && m.as_reply().is_some_and(&pred))
    }

    pub fn state(&self) -> SupervisorState {
        self.core.status().state
    }

    pub fn latched(&self) -> FaultFlags {
        self.core.status().latched_faults
    }

    /// Boots (zero measured) and asks for a 10 Hz host release; returns when vibrating.
    pub fn vibrate(&mut self, hz: f32) -> u64 {
        self.run_ms(150);
        assert_eq!(
            self.ack(&Request::Release {
                on: true,
                target_hz: hz,
                session: 0
            }),
            Ok(())
        );
        self.run_until(3000, true, |s| s.state == SupervisorState::Vibrating)
            .expect("reaches Vibrating")
    }

    /// Messages of one kind received so far.
    pub fn count(&self, pred: impl Fn(&DeviceMessage) -> bool) -> usize {
        self.received.iter().filter(|m| pred(m)).count()
    }
}
