//! The one error type of the file layer.

use std::path::PathBuf;

/// What can go wrong reading or writing a file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The operating system refused (missing file, permissions, full disk).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not what its format requires; `message` says what and where (line, section).
    #[error("{}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
    /// The file is well formed but its content is refused by the engine (open mesh, NaN, ...).
    #[error("{}: {source}", path.display())]
    Model {
        /// The file.
        path: PathBuf,
        /// The engine's reason.
        source: medial_core::Error,
    },
}

/// Result alias of the file layer.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A format error for `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            message: message.into(),
        }
    }

    /// An I/O error for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// An engine error about the content of `path`.
    pub fn model(path: impl Into<PathBuf>, source: medial_core::Error) -> Self {
        Error::Model {
            path: path.into(),
            source,
        }
    }
}
