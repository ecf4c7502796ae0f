//! The fault drills as scenarios on the simulated rig, and the settings and results of the
//! paper's experiments (Fig. 5, Table 1, Figs. 8-9) in the JSON and CSV `rig sim` prints.
//! The experiments themselves are the procedures of `rig experiment` (`host::experiment`),
//! run on the in-process virtual rig by `host::experiment::paper`: one implementation.

pub mod faults;
pub mod fig5;
pub mod sweep;
pub mod table1;

use crate::SimError;
use crate::SimLink;

pub use crate::riglink::HEARTBEAT_S;

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
