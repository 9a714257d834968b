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

/// A JSON request as `T`, or an `InvalidError` naming the keyword argument (the
/// field's path in the request, less the nesting the Python half adds: `scene.`,
/// `view.`, `accel.`, `input.load.`) and serde's message.
pub fn parse_request<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    what: &str,
    json: &str,
) -> PyResult<T> {
    let mut de = serde_json::Deserializer::from_str(json);
    serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.inner().to_string();
        // serde's own position in the generated JSON means nothing to the caller.
        let inner = inner
            .split(" at line ")
            .next()
            .unwrap_or(&inner)
            .to_string();
        let mut field = path.as_str();
        for prefix in ["scene.", "view.", "accel.", "input.load.", "input."] {
            field = field.strip_prefix(prefix).unwrap_or(field);
        }
        let message = if field.is_empty() || field == "." || inner.starts_with("unknown field") {
            format!("invalid {what}: {inner}")
        } else {
            format!("invalid {what} `{field}`: {inner}")
        };
        raise(py, "InvalidError", &message)
    })
}
