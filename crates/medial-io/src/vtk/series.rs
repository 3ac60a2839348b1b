//! ParaView's index of a time series of files (`NAME.vtk.series`): JSON naming each file with
//! its time, so that ParaView opens the files as one data set with a time axis at the real times
//! (rather than at the file indices, as it does for a `name_000.vtk`, `name_001.vtk`, … group).
//!
//! ```json
//! {
//!   "file-series-version": "1.0",
//!   "files": [
//!     { "name": "boundary_t000.vtk", "time": 0.0 },
//!     { "name": "boundary_t001.vtk", "time": 0.05 }
//!   ]
//! }
//! ```

use std::path::Path;

use crate::atomic::write_atomic;
use crate::{Error, Result};

/// One file of a series.
#[derive(Clone, Debug, PartialEq)]
pub struct SeriesFile {
    /// The file's name, relative to the folder of the `.series` file.
    pub name: String,
    /// Its time (for a flow: `t = n / N` of time point `n`).
    pub time: f64,
}

/// The JSON text of a series (see the module documentation), files in the given order.
///
/// Errors (as text): a time that is not finite (JSON has no NaN), or times that do not
/// increase.
pub fn series_json(files: &[SeriesFile]) -> std::result::Result<String, String> {
    if let Some(f) = files.iter().find(|f| !f.time.is_finite()) {
        return Err(format!("file '{}' has time {}", f.name, f.time));
    }
    if let Some(w) = files.windows(2).find(|w| w[1].time <= w[0].time) {
        return Err(format!(
            "the times do not increase: '{}' at {} follows '{}' at {}",
            w[1].name, w[1].time, w[0].name, w[0].time
        ));
    }
    let files: Vec<serde_json::Value> = files
        .iter()
        .map(|f| serde_json::json!({ "name": f.name, "time": f.time }))
        .collect();
    let root = serde_json::json!({ "file-series-version": "1.0", "files": files });
    Ok(serde_json::to_string_pretty(&root).expect("JSON values serialise"))
}

/// Writes a `.vtk.series` file atomically (see [`series_json`]).
///
/// Errors: [`Error::Format`] for times [`series_json`] refuses (nothing is written),
/// [`Error::Io`] when the file cannot be written.
pub fn write_series(path: &Path, files: &[SeriesFile]) -> Result<()> {
    let text = series_json(files)
        .map_err(|m| Error::format(path, format!("cannot write the series: {m}")))?;
    write_atomic(path, |w| writeln!(w, "{text}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(name: &str, time: f64) -> SeriesFile {
        SeriesFile {
            name: name.into(),
            time,
        }
    }

    #[test]
    fn json_names_each_file_with_its_time() {
        let text = series_json(&[file("a_t000.vtk", 0.0), file("a_t002.vtk", 0.5)]).unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(
            value,
            serde_json::json!({
                "file-series-version": "1.0",
                "files": [
                    { "name": "a_t000.vtk", "time": 0.0 },
                    { "name": "a_t002.vtk", "time": 0.5 }
                ]
            })
        );
    }

    #[test]
    fn refuses_times_that_are_not_increasing_or_finite() {
        let err = series_json(&[file("a", 0.5), file("b", 0.5)]).unwrap_err();
        assert!(err.contains("do not increase"), "{err}");
        let err = series_json(&[file("a", f64::NAN)]).unwrap_err();
        assert!(err.contains("'a' has time NaN"), "{err}");
    }
}
