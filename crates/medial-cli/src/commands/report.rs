//! `medial report`: writes the report, the ParaView series and the animated glTF of a fit
//! folder again from its files ([`crate::report`]).

use crate::error::CliError;
use std::path::PathBuf;

/// The arguments of `medial report`.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// A folder written by `medial fit` (summary.json, log.csv, time_points.csv, config.toml,
    /// flow/).
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
}

/// Writes `DIR/report.html`, `DIR/flow.glb` and `DIR/flow/*.vtk.series`.
pub fn run(args: &ReportArgs) -> Result<(), CliError> {
    crate::report::write(&args.dir, &args.dir)?;
    eprintln!("report in {}", args.dir.join("report.html").display());
    Ok(())
}
