//! The crate's error type. Errors exist only at input boundaries (files, JSON,
//! parameters); the geometric core is infallible.

use std::path::PathBuf;

/// Errors returned by the optimizer library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The input (a scene, a job, a placement) is malformed or out of range.
    /// `what` names the file and, where known, the field.
    #[error("{what}: {message}")]
    BadInput {
        /// The file and field concerned, e.g. `job.json: view_space.min`.
        what: String,
        /// What is wrong with it.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The run was cancelled through [`crate::place::Control::cancel`].
    #[error("cancelled")]
    Cancelled,
    /// A broken internal invariant: a bug, please report it.
    #[error("internal error (a bug): {0}")]
    Internal(String),
}

impl Error {
    /// A bad-input error for `what` (file and field) with a message.
    pub fn bad(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::BadInput {
            what: what.into(),
            message: message.into(),
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// True for errors caused by the input rather than the program or the machine.
    pub fn is_bad_input(&self) -> bool {
        matches!(self, Error::BadInput { .. })
    }
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
