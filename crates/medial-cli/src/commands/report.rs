//! `medial report`: writes the report, the ParaView series and the animated glTF of a fit
//! folder again from its files ([`crate::report`]).

use crate::error::CliError;
use crate::output::write_json;
use crate::report::is_view;
use crate::results;
use std::path::PathBuf;

/// The arguments of `medial report`.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// A folder written by `medial fit` (summary.json, log.csv, time_points.csv, config.toml,
    /// flow/).
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
}

/// Writes `DIR/report.html`, `DIR/flow.glb` and `DIR/flow/*.vtk.series`: the set the folder
/// shows, checked against its digests ([`results::verify`]), carried into a new set with the
/// views made again (a view that was removed or damaged is simply made again), and committed as a fit commits ([`results::ResultSet`]), so that the
/// folder shows the earlier set or the new one whole whatever happens. A folder of an earlier
/// version, whose summary.json lists no files, gets its views written in place.
pub fn run(args: &ReportArgs) -> Result<(), CliError> {
    let dir = &args.dir;
    let marker = dir.join(MARKER);
    let listed = results::listed_files(&marker);
    if listed.is_empty() {
        crate::report::write(dir, dir)?;
    } else {
        results::verify(dir, MARKER, is_view)?;
        let mut set = results::ResultSet::begin(dir)?;
        for relative in listed.iter().filter(|r| !is_view(r)) {
            set.carry(relative)?;
        }
        let summary = std::fs::read(&marker).map_err(|e| CliError::io(&marker, e))?;
        let mut summary: serde_json::Value = serde_json::from_slice(&summary)
            .map_err(|e| medial_io::Error::format(&marker, e.to_string()))?;
        // A draft the views read; the commit writes the marker again with the listing.
        write_json(&set.staging().join(MARKER), &summary)?;
        for view in crate::report::write(set.staging(), dir)? {
            set.include(&view);
        }
        set.commit(MARKER, |path, listing| {
            summary["files"] = serde_json::json!(listing.files);
            summary["sha256"] = serde_json::json!(listing.sha256);
            write_json(path, &summary)
        })?;
    }
    eprintln!("report in {}", dir.join("report.html").display());
    Ok(())
}

/// The marker of a fit's set of results.
const MARKER: &str = "summary.json";
