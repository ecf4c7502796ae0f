//! Software-in-the-loop simulation: the firmware core and the plant in closed loop
//! ([`SimRig`]), a host session over the real wire format ([`SimLink`]) and the scenarios
//! that reproduce the paper (`rig sim <scenario>`).

mod link;
pub mod plot;
mod rig;
pub mod scenarios;

pub use link::SimLink;
pub use rig::{Injections, PLANT_HZ, SimConfig, SimRig};
