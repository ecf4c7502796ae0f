//! The host library's errors as Python exceptions, each carrying the CLI's message (the
//! same text `rig` prints after `error:`).

use host::RigError;
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError, PyTimeoutError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

/// One exception class: its name in `backdrive_rig` and its docstring (its bases:
/// [`types`]).
struct Class {
    name: &'static str,
    doc: &'static str,
}

/// The classes, in the order they are made (a base before the classes built on it).
const CLASSES: [Class; 9] = [
    Class {
        name: "RigError",
        doc: "Any error of the rig library; the message is the CLI's. The base of every other.",
    },
    Class {
        name: "BadValueError",
        doc: "A value the device or the library does not take; the message names it and the range. Also a ValueError.",
    },
    Class {
        name: "MissingFileError",
        doc: "A file given does not exist; the message names it. Also a BadValueError and a FileNotFoundError.",
    },
    Class {
        name: "RefusedError",
        doc: "The device refused a request (a Nack); the message says why and what to do.",
    },
    Class {
        name: "NoReplyError",
        doc: "The device did not answer (after retries); the message says what to check. Also a TimeoutError.",
    },
    Class {
        name: "VersionMismatchError",
        doc: "The device speaks another protocol version or schema; the message says which side to update.",
    },
    Class {
        name: "LinkError",
        doc: "The port could not be opened or failed (busy, gone, not a device). Also an OSError.",
    },
    Class {
        name: "DeviceFaultError",
        doc: "The device latched a fault; the message names it.",
    },
    Class {
        name: "RigClosedError",
        doc: "The rig was closed (its port's thread has ended).",
    },
];

/// Index of each class in [`CLASSES`] (and in the made types).
#[derive(Clone, Copy)]
enum Kind {
    Rig = 0,
    BadValue = 1,
    MissingFile = 2,
    Refused = 3,
    NoReply = 4,
    VersionMismatch = 5,
    Link = 6,
    DeviceFault = 7,
    Closed = 8,
}

static TYPES: PyOnceLock<Vec<Py<PyType>>> = PyOnceLock::new();

/// The exception classes, made once: each under the standard exception a Python user
/// catches for it (`except ValueError`, `except OSError`, `except TimeoutError`), with
/// `RigError` the common base, named as `backdrive_rig` exports them.
fn types(py: Python<'_>) -> PyResult<&Vec<Py<PyType>>> {
    TYPES.get_or_try_init(py, || {
        let mut made: Vec<Py<PyType>> = Vec::with_capacity(CLASSES.len());
        for (k, class) in CLASSES.iter().enumerate() {
            let ours = |i: usize| made[i].bind(py).clone().into_any();
            let bases = match k {
                0 => vec![py.get_type::<PyException>().into_any()],
                1 => vec![ours(0), py.get_type::<PyValueError>().into_any()],
                2 => vec![ours(1), py.get_type::<PyFileNotFoundError>().into_any()],
                4 => vec![ours(0), py.get_type::<PyTimeoutError>().into_any()],
                6 => vec![ours(0), py.get_type::<PyOSError>().into_any()],
                _ => vec![ours(0)],
            };
            let namespace = PyDict::new(py);
            namespace.set_item("__module__", "backdrive_rig")?;
            namespace.set_item("__doc__", class.doc)?;
            let ty = py
                .get_type::<PyType>()
                .call1((class.name, PyTuple::new(py, bases)?, namespace))?
                .cast_into::<PyType>()?;
            made.push(ty.unbind());
        }
        Ok(made)
    })
}

/// An exception of class `kind` with message `msg`.
fn raise(kind: Kind, msg: String) -> PyErr {
    Python::attach(|py| match types(py) {
        Ok(t) => PyErr::from_type(t[kind as usize].bind(py).clone(), msg),
        Err(e) => e,
    })
}

/// Whether `e` comes from a file that does not exist (an `io::Error` of kind `NotFound`
/// anywhere in its chain).
fn missing_file(e: &RigError) -> bool {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::NotFound)
        {
            return true;
        }
        cause = c.source();
    }
    false
}

/// The Python exception for `e`, with the CLI's message.
pub fn to_py(e: RigError) -> PyErr {
    let msg = e.to_string();
    let kind = match e {
        _ if missing_file(&e) => Kind::MissingFile,
        RigError::BadValue { .. }
        | RigError::Explain(explain::ExplainError::BadValue { .. })
        | RigError::Gear { .. }
        | RigError::CalibrationFile { .. }
        | RigError::RigFile { .. }
        | RigError::RigFileInvalid(_)
        | RigError::Sim(_)
        | RigError::Unmeasurable { .. } => Kind::BadValue,
        RigError::Refused { .. } => Kind::Refused,
        RigError::NoReply { .. } => Kind::NoReply,
        RigError::VersionMismatch { .. } => Kind::VersionMismatch,
        RigError::PortOpen { .. }
        | RigError::PortBusy { .. }
        | RigError::NoDevice
        | RigError::Link { .. } => Kind::Link,
        RigError::DeviceFault { .. } => Kind::DeviceFault,
        _ => Kind::Rig,
    };
    raise(kind, msg)
}

/// The error of a call on a closed rig.
pub fn closed() -> PyErr {
    raise(
        Kind::Closed,
        "the rig is closed: open it again (Rig.open or Rig.virtual)".into(),
    )
}

/// Adds the exception classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    for (class, ty) in CLASSES.iter().zip(types(py)?) {
        m.add(class.name, ty.bind(py))?;
    }
    Ok(())
}
