//! Errors a user can cause. Every condition that bad input, a missing file, an absurd
//! size or a missing GPU can produce has a variant here; programmer errors panic with a
//! documented reason instead.

use std::path::PathBuf;

/// The crate-wide result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong because of input, the file system or the machine.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its contents are not what its format promises.
    #[error("{path}: {field}: {message}")]
    Format {
        path: PathBuf,
        /// The header field or part of the file that is wrong.
        field: String,
        message: String,
    },
    /// A parameter (from the command line, a settings file or an API call) is invalid.
    #[error("invalid {what}: {message}")]
    Invalid { what: String, message: String },
    /// A size that would need more memory than is reasonable, refused before allocating.
    #[error("{what} is too large: {message}")]
    TooLarge { what: String, message: String },
    /// A volume or image contains NaN or infinite values where finite ones are required.
    #[error("{what} contains {count} non-finite value(s) (first at element {first})")]
    NonFinite {
        what: String,
        count: usize,
        first: usize,
    },
    /// No usable GPU adapter was found.
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// A GPU operation failed (shader compilation, out of memory, device lost).
    #[error("GPU error: {0}")]
    Gpu(String),
    /// A job was asked for on a backend that does not implement it (or one of its
    /// features): names the job (or feature) and the backend.
    #[error("{job} does not run on the {backend} backend: {message}")]
    Unsupported {
        job: String,
        backend: String,
        message: String,
    },
    /// The caller asked a job to stop (through its progress callback).
    #[error("cancelled")]
    Cancelled,
    /// A job on several processes failed on one of them (the lowest failing rank's
    /// message; see [`crate::jobs::distributed`]).
    #[error("rank {rank} of {ranks}: {message}")]
    Rank {
        rank: usize,
        ranks: usize,
        message: String,
    },
}

impl Error {
    /// Shorthand for [`Error::Invalid`].
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }

    /// An [`Error::Invalid`] found in a file's contents, as the [`Error::Format`] that
    /// names the file (the field is the invalid value's name); other errors unchanged.
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            Error::Invalid { what, message } => Error::format(path, what, message),
            e => e,
        }
    }

    /// Shorthand for [`Error::Format`].
    pub fn format(
        path: impl Into<PathBuf>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Format {
            path: path.into(),
            field: field.into(),
            message: message.into(),
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Shorthand for [`Error::Unsupported`].
    pub fn unsupported(
        job: impl Into<String>,
        backend: impl std::fmt::Display,
        message: impl Into<String>,
    ) -> Self {
        Error::Unsupported {
            job: job.into(),
            backend: backend.to_string(),
            message: message.into(),
        }
    }

    /// Shorthand for [`Error::TooLarge`].
    pub fn too_large(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::TooLarge {
            what: what.into(),
            message: message.into(),
        }
    }
}

/// `s` with every control character (C0, DEL, C1: terminal escapes, NUL, bell) written
/// as a Rust escape (`\u{1b}`), so that a message quoting a file's bytes cannot drive
/// the terminal. Line feeds and tabs are kept.
pub fn escape_controls(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(|c| c.is_control() && c != '\n' && c != '\t') {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if c.is_control() && c != '\n' && c != '\t' {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn control_characters_are_escaped() {
        let e = super::escape_controls("type: '\u{1b}[2J\u{1b}]0;pwned\u{7}\0'\nnext");
        assert_eq!(e, "type: '\\u{1b}[2J\\u{1b}]0;pwned\\u{7}\\u{0}'\nnext");
        assert!(matches!(
            super::escape_controls("plain"),
            std::borrow::Cow::Borrowed(_)
        ));
    }
}
