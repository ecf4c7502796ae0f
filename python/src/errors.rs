//! The host library's errors as Python exceptions, each carrying the CLI's message (the
//! same text `rig` prints after `error:`).

use host::RigError;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _native,
    RigError_,
    PyException,
    "Any error of the rig library; the message is the CLI's."
);
create_exception!(
    _native,
    BadValueError,
    RigError_,
    "A value the device or the library does not take; the message names it and the range."
);
create_exception!(
    _native,
    RefusedError,
    RigError_,
    "The device refused a request (a Nack); the message says why and what to do."
);
create_exception!(
    _native,
    NoReplyError,
    RigError_,
    "The device did not answer (after retries); the message says what to check."
);
create_exception!(
    _native,
    VersionMismatchError,
    RigError_,
    "The device speaks another protocol version or schema; the message says which side to update."
);
create_exception!(
    _native,
    LinkError,
    RigError_,
    "The port could not be opened or failed (busy, gone, not a device)."
);
create_exception!(
    _native,
    DeviceFaultError,
    RigError_,
    "The device latched a fault; the message names it."
);
create_exception!(
    _native,
    RigClosedError,
    RigError_,
    "The rig was closed (its port's thread has ended)."
);

/// The Python exception for `e`, with the CLI's message.
pub fn to_py(e: RigError) -> PyErr {
    let msg = e.to_string();
    match e {
        RigError::BadValue { .. }
        | RigError::Explain(explain::ExplainError::BadValue { .. })
        | RigError::Gear { .. }
        | RigError::CalibrationFile { .. }
        | RigError::RigFile { .. }
        | RigError::RigFileInvalid(_)
        | RigError::Sim(_)
        | RigError::Unmeasurable { .. } => BadValueError::new_err(msg),
        RigError::Refused { .. } => RefusedError::new_err(msg),
        RigError::NoReply { .. } => NoReplyError::new_err(msg),
        RigError::VersionMismatch { .. } => VersionMismatchError::new_err(msg),
        RigError::PortOpen { .. }
        | RigError::PortBusy { .. }
        | RigError::NoDevice
        | RigError::Link { .. } => LinkError::new_err(msg),
        RigError::DeviceFault { .. } => DeviceFaultError::new_err(msg),
        _ => RigError_::new_err(msg),
    }
}

/// The error of a call on a closed rig.
pub fn closed() -> PyErr {
    RigClosedError::new_err("the rig is closed: open it again (Rig.open or Rig.virtual)")
}

/// Adds the exception classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("RigError", py.get_type::<RigError_>())?;
    m.add("BadValueError", py.get_type::<BadValueError>())?;
    m.add("RefusedError", py.get_type::<RefusedError>())?;
    m.add("NoReplyError", py.get_type::<NoReplyError>())?;
    m.add(
        "VersionMismatchError",
        py.get_type::<VersionMismatchError>(),
    )?;
    m.add("LinkError", py.get_type::<LinkError>())?;
    m.add("DeviceFaultError", py.get_type::<DeviceFaultError>())?;
    m.add("RigClosedError", py.get_type::<RigClosedError>())?;
    Ok(())
}
