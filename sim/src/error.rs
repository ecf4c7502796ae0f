//! The virtual rig's error type.

use thiserror::Error;

/// What can go wrong on the virtual rig or in a scenario.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum SimError {
    /// Gear parameters that do not make a 2K-H gear.
    #[error("invalid gear set {}: {source}", crate::names::teeth(z))]
    Gear {
        /// The tooth counts given.
        z: [u32; 4],
        /// Why they were rejected.
        source: model::GearError,
    },
    /// A scenario option outside its meaningful range.
    #[error("{what}: {why}")]
    BadValue {
        /// Which value.
        what: String,
        /// What is wrong with it and what to give instead.
        why: String,
    },
    /// The rig (simulated or real) broke the protocol or did not answer.
    #[error("device protocol: {0}")]
    Protocol(String),
    /// The rig refused a request, with the device's reason.
    #[error("device protocol: the rig refused {request}: {code} ({})", code.name())]
    Refused {
        /// The request's name.
        request: &'static str,
        /// The device's reason.
        code: protocol::NackCode,
    },
}
