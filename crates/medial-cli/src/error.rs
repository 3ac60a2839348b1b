//! The one error type of the command-line tool. Every message says what went wrong and where;
//! `main` prints it and exits with a non-zero code.

use crate::signals::Signal;
use medial_core::mesh::Bounds;
use std::path::{Path, PathBuf};

/// What can stop a command.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] medial_io::Error),
    /// The engine refused the input or failed (its memory refusals become [`CliError::Memory`]).
    #[error(transparent)]
    Engine(medial_core::Error),
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
    /// The subject table of `medial batch` is wrong (a missing or unknown column, a subject
    /// name that is not a safe folder name or repeats, a file that does not exist).
    #[error("{}: {message}", path.display())]
    Subjects {
        /// The subject table.
        path: PathBuf,
        /// What is wrong, with its line.
        message: String,
    },
    /// Fits of `medial batch` failed; the other subjects were fitted and the cohort gathered.
    #[error(
        "{count} of {subjects} subjects failed ({failed}): each one's error is in \
         {}/SUBJECT/failed.json and its row of {}/cohort.csv",
        dir.display(),
        dir.display()
    )]
    SubjectsFailed {
        /// The failed subjects, comma-separated.
        failed: String,
        /// How many failed.
        count: usize,
        /// Subjects in the table.
        subjects: usize,
        /// The cohort folder.
        dir: PathBuf,
    },
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
    /// The fit's model missed a part of its target image or surface (more than 2 % of it
    /// farther from the model than two voxels or mean edges, or the flow's σ); the results were
    /// written, marked as such. Exit code 6.
    #[error("{0}")]
    MissesTarget(String),
    /// `medial template`: the template leaves out part of the shape (a wall whose medial points
    /// do not reach the rest); it was written with its figures. Exit code 1.
    #[error("{0}")]
    Incomplete(String),
    /// `medial check`: the medial points are not the centres of inscribed balls (the sheet
    /// atoms' mean residual passes `--max-residual`); the figures were printed. Exit code 5.
    #[error("{0}")]
    NotMedial(String),
    /// The memory estimate of a run passes the limit (`--max-memory`).
    #[error(
        "{what} would need {estimate}, more than the memory limit of {} (--max-memory GIB; \
         default: the machine's total memory)",
        medial_core::memory::human(*limit)
    )]
    Memory {
        /// What would need it.
        what: String,
        /// The estimate.
        estimate: String,
        /// The limit, bytes.
        limit: f64,
    },
    /// A Dice stage's image foreground lies where no sample of the template's interior sees
    /// it: the fit would have no data gradient and end at once with a Dice of 0.
    #[error(
        "stage '{stage}': the image {} does not overlap the template: its foreground spans {} \
         mm, the template's boundary {} mm (world coordinates); check the image's origin and \
         orientation against the template's coordinates",
        image.display(),
        foreground.span(),
        template.span()
    )]
    NoOverlap {
        /// The stage.
        stage: String,
        /// The image file.
        image: PathBuf,
        /// World bounding box of the image's foreground voxels, mm (boxed, like `template`,
        /// to keep the error type small).
        foreground: Box<Bounds>,
        /// World bounding box of the template's boundary points, mm.
        template: Box<Bounds>,
    },
    /// An SSD stage's `transform` is singular or reflects (determinant of its linear part
    /// `≤ 0` or not finite): its targets would be the template flattened or turned inside out.
    #[error(
        "stage '{stage}': transform {} has determinant {determinant}: it must be positive \
         (a singular matrix flattens the template, a negative one reflects it, turning it inside \
         out)",
        path.display()
    )]
    Transform {
        /// The stage.
        stage: String,
        /// The matrix file.
        path: PathBuf,
        /// Determinant of the 3×3 linear part.
        determinant: f64,
    },
    /// The `--target` points do not correspond to the template's boundary points one for one:
    /// the best similarity between the two accounts for too little of the points' spread.
    #[error(
        "{}: the points do not seem to correspond to the template boundary's, point for point: \
         the best similarity between them accounts for {:.0} % of the points' spread (at least \
         {:.0} % expected); a mesh without correspondence goes in --surface",
        path.display(),
        100.0 * explained,
        100.0 * minimum
    )]
    NoCorrespondence {
        /// The target points.
        path: PathBuf,
        /// The fraction of their spread explained (`medial_core::fit::explained_spread`).
        explained: f64,
        /// The least fraction accepted.
        minimum: f64,
    },
    /// A figure of the report could not be drawn.
    #[error("report figure '{figure}': {message}")]
    Figure {
        /// The figure.
        figure: String,
        /// The plotting library's message.
        message: String,
    },
    /// A checkpoint cannot be resumed (missing, damaged, of another version, or written for
    /// another config or other input files).
    #[error("{}: {message}", path.display())]
    Checkpoint {
        /// The checkpoint file.
        path: PathBuf,
        /// Why it cannot be resumed.
        message: String,
    },
    /// SIGINT or SIGTERM stopped the fit; its checkpoint and results so far were written.
    /// Exit code `128 + the signal's number` (130, 143).
    #[error("{message}")]
    Interrupted {
        /// The signal.
        signal: Signal,
        /// Where it stopped and what was written.
        message: String,
    },
    /// Another `medial` process is writing a result set into the same folder (its staging
    /// folder is there and the process runs).
    #[error(
        "{}: another medial process (pid {pid}) is writing its results here; wait for it or \
         give another output folder",
        dir.display()
    )]
    Busy {
        /// The output folder.
        dir: PathBuf,
        /// The other process.
        pid: u32,
    },
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
    /// met, 6 for a fit whose model missed a part of its target (all with results written), 5
    /// for `medial check` finding a model not medial,
    /// 130 / 143 for a fit stopped by SIGINT / SIGTERM (with its checkpoint), 1 for every other
    /// failure (2, a wrong command line, is clap's).
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Unsound(_) => 3,
            CliError::ConstraintsNotMet(_) => 4,
            CliError::MissesTarget(_) => 6,
            CliError::NotMedial(_) => 5,
            CliError::Interrupted { signal, .. } => signal.exit_code(),
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

impl From<medial_core::Error> for CliError {
    /// The engine's error, its memory refusals with the command line's `--max-memory` hint.
    fn from(e: medial_core::Error) -> Self {
        match e {
            medial_core::Error::Memory {
                what,
                estimate,
                limit,
            } => CliError::Memory {
                what,
                estimate,
                limit,
            },
            e => CliError::Engine(e),
        }
    }
}
