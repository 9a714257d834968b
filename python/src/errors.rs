//! Library errors as Python exceptions: the classes live in `voxlab/_errors.py`
//! (where they can derive from both `VoxlabError` and `ValueError`/`OSError`); this
//! file picks the class for each [`voxlab::Error`] and keeps the library's message.

use pyo3::prelude::*;
use voxlab::error::Error;

/// The `voxlab._errors` class named `class`, called with `message`.
pub fn raise(py: Python<'_>, class: &str, message: &str) -> PyErr {
    let made = py
        .import("voxlab._errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1((message,)));
    match made {
        Ok(v) => PyErr::from_value(v),
        Err(e) => e,
    }
}

/// The exception class of a library error.
fn class_of(e: &Error) -> &'static str {
    match e {
        Error::Io { .. } => "FileError",
        Error::Format { .. } => "FormatError",
        Error::Invalid { .. } => "InvalidError",
        Error::TooLarge { .. } => "TooLargeError",
        Error::NonFinite { .. } => "NonFiniteError",
        Error::NoAdapter(_) => "NoGpuError",
        Error::Gpu(_) => "GpuError",
        Error::Unsupported { .. } => "UnsupportedError",
        Error::Cancelled => "CancelledError",
        #[allow(unreachable_patterns)]
        _ => "VoxlabError",
    }
}

/// A library error as the matching `voxlab` exception, with the CLI's message.
pub fn to_py(py: Python<'_>, e: &Error) -> PyErr {
    raise(py, class_of(e), &e.to_string())
}

/// A panic's payload as `voxlab.InternalError`.
pub fn panic_to_py(py: Python<'_>, payload: &(dyn std::any::Any + Send)) -> PyErr {
    let text = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into());
    raise(
        py,
        "InternalError",
        &format!("voxlab panicked (a bug; please report it): {text}"),
    )
}

/// A request that does not parse: the serde message names the field.
pub fn bad_request(py: Python<'_>, what: &str, e: &serde_json::Error) -> PyErr {
    raise(py, "InvalidError", &format!("invalid {what}: {e}"))
}
