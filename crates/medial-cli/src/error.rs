//! The one error type of the command-line tool. Every message says what went wrong and where;
//! `main` prints it and exits with a non-zero code.

use std::path::{Path, PathBuf};

/// What can stop a command.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] medial_io::Error),
    /// The engine refused the input or failed.
    #[error(transparent)]
    Engine(#[from] medial_core::Error),
    /// The config file is invalid.
    #[error("{}: {message}", path.display())]
    Config {
        /// The config file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The inputs do not fit together (sizes, stage names, missing arrays).
    #[error("{0}")]
    Input(String),
    /// A command line that clap's rules cannot express is wrong. Exit code 2.
    #[error("{0}")]
    Usage(String),
    /// The fit ended at an unsound iterate (folded, diverged, not finite); the results of the
    /// last sound iterate were written, marked as such. Exit code 3.
    #[error("{0}")]
    Unsound(String),
    /// The fit ended with its medial constraints above their tolerance; the results were
    /// written, marked as such. Exit code 4.
    #[error("{0}")]
    ConstraintsNotMet(String),
    /// An operating-system error outside the file layer (creating the output folder).
    #[error("{}: {source}", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

impl CliError {
    /// The process exit code: 3 for an unsound fit, 4 for a fit whose constraints were not
    /// met (both with results written), 1 for every other failure (2, a wrong command line,
    /// is clap's).
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Unsound(_) => 3,
            CliError::ConstraintsNotMet(_) => 4,
            CliError::Usage(_) => 2,
            _ => 1,
        }
    }

    /// An I/O error for `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        CliError::Io {
            path: path.into(),
            source,
        }
    }
}
