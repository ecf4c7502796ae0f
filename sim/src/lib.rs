//! The closed-loop virtual rig: the firmware's control core and the plant in closed loop
//! ([`SimRig`], virtual time), a host session over the real wire format ([`SimLink`]),
//! the scenarios that reproduce the paper (`rig sim <scenario>`), and the shared scenarios
//! written against [`RigLink`] that run on the virtual rig and on a real one.
//!
//! One harness: the firmware core's closed-loop tests, the host's `--sim`, `rig sim`, and
//! `hil-tests` all drive this crate.

mod error;
mod link;
pub mod names;
pub mod preset;
mod rig;
pub mod riglink;
pub mod scenarios;
pub mod user_effects;

pub use error::SimError;
pub use link::{LineNoise, SimLink};
pub use preset::{EffectSpec, Preset};
pub use rig::{
    ADC_HZ, BenchSettings, Injections, SimConfig, SimRig, UART_WRITE, VIRTUAL_BOARD,
    board_bytes_per_s,
};
pub use riglink::RigLink;
