//! What every command shares for its results: JSON on stdout and in files, the VTK encoding,
//! the summary of a template (the engine's), and engine errors about a file.

use crate::error::CliError;
pub use medial_core::model::TemplateSummary;
use medial_io::vtk::{Encoding, WriteOptions};
use serde::Serialize;
use std::io::Write as _;
use std::path::Path;

/// An engine error about the contents of `path`.
pub fn model_error(path: &Path, e: medial_core::Error) -> CliError {
    medial_io::Error::model(path, e).into()
}

/// ASCII or binary legacy VTK.
pub fn write_options(binary: bool) -> WriteOptions {
    WriteOptions {
        encoding: if binary {
            Encoding::Binary
        } else {
            Encoding::Ascii
        },
        ..WriteOptions::default()
    }
}

/// Prints `value` as pretty JSON on stdout. A closed pipe (`medial … | head`) is not an error;
/// any other write failure is.
pub fn print_json(value: &impl Serialize) -> Result<(), CliError> {
    let text = serde_json::to_string_pretty(value).expect("summaries serialise");
    match writeln!(std::io::stdout(), "{text}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(CliError::io(Path::new("<stdout>"), e))
        }
        _ => Ok(()),
    }
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), CliError> {
    medial_io::atomic::write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })?;
    Ok(())
}

/// Writes `text` to `path` atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), CliError> {
    Ok(medial_io::atomic::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
    })?)
}
