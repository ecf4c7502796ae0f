//! The paper's experiments and the fault drills as scenarios on the simulated rig. Each
//! returns a result type that serialises to the JSON the `rig sim` verb prints.

pub mod faults;
pub mod fig5;
pub mod sweep;
pub mod table1;

use protocol::{Reply, Request};

use crate::SimError;
use crate::SimLink;

pub use crate::riglink::HEARTBEAT_S;

/// Output rotation (rad) that counts as "the load moved": 0.1 mm of rope on the paper's
/// 75 mm pulley.
pub const MOTION_RAD: f64 = 0.1e-3 / model::paper::R_OUT;

/// Sends `req` and requires an `Ack`.
pub fn expect_ack(link: &mut SimLink, req: &Request) -> Result<(), SimError> {
    match link.request(req)? {
        Reply::Ack => Ok(()),
        other => Err(crate::riglink::unexpected(req, &other)),
    }
}

/// Opens the session (hello) as the host tool does, checking the device's version.
pub fn hello(link: &mut SimLink) -> Result<(), SimError> {
    let hello = protocol::session::Session::hello();
    let reply = link.request(&hello)?;
    match protocol::session::hello_outcome(&reply) {
        Some(Ok(_)) => Ok(()),
        Some(Err(e)) => Err(SimError::Protocol(e.to_string())),
        None => Err(crate::riglink::unexpected(&hello, &reply)),
    }
}

/// Requests a release at `hz` and keeps it alive with heartbeats.
pub fn release(link: &mut SimLink, hz: f32) -> Result<(), SimError> {
    crate::riglink::release(link, hz)
}

/// Ends the release and stops the heartbeats.
pub fn lock(link: &mut SimLink) -> Result<(), SimError> {
    crate::riglink::lock(link)
}

/// Whether the output has moved since it was last reset.
pub fn output_moved(link: &SimLink) -> bool {
    link.rig.plant().state().output_angle.abs() > MOTION_RAD
}
