//! `medial`: diffeomorphic medial modeling from the command line.

mod config;
mod error;
mod eval;
mod fit;
mod inflate_cmd;
mod model;
mod project_cmd;
mod rasterize_cmd;
mod report;
mod stage;
mod synth_cmd;
mod time_points;
mod warp_cmd;

use clap::{Parser, Subcommand};
use error::CliError;
use std::path::PathBuf;
use std::process::ExitCode;

/// Fit medial templates of sheet-like structures (heart wall, placenta, valve leaflets,
/// cartilage) to subjects with a diffeomorphic flow that keeps the medial axis medial.
#[derive(Parser)]
#[command(name = "medial", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Worker threads (default: all cores). Results are bit-identical for any count.
    #[arg(long, global = true, value_name = "N")]
    threads: Option<usize>,
    /// No progress display (log lines and warnings still go to stderr).
    #[arg(long, short, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run the stages of a TOML config and write summary.json, log.csv, momenta.npy, the flow
    /// of the model (flow/boundary_tNNN.vtk, flow/medial_tNNN.vtk), time_points.csv (medial
    /// templates) and fitted_template.vtk.
    Fit {
        /// The config file (TOML); relative paths in it are relative to its folder.
        config: PathBuf,
        /// Output folder (created if needed) [default: "out" beside the config].
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Evaluate a stage's objective at given controls without optimising; prints one JSON object.
    Eval {
        /// The config file (TOML).
        config: PathBuf,
        /// Controls u, a float64 .npy array of shape [N, k, 3] (coordinate unit per unit time).
        #[arg(long, value_name = "U.npy")]
        momenta: PathBuf,
        /// Stage whose objective is evaluated [default: the first].
        #[arg(long, value_name = "NAME")]
        stage: Option<String>,
        /// Penalty weight μ [default: the stage's mu].
        #[arg(long, value_name = "X")]
        mu: Option<f64>,
        /// Lagrange multipliers, .npy of shape [N, L] [default: zeros].
        #[arg(long, value_name = "LAM.npy")]
        lambda: Option<PathBuf>,
        /// Also write the gradient ∂E/∂u as .npy of shape [N, k, 3].
        #[arg(long, value_name = "G.npy")]
        gradient: Option<PathBuf>,
    },
    /// Inflate a medial sheet (a triangle mesh with a Radius per vertex, optionally
    /// Loop-subdivided) into a cmrep boundary template; prints a JSON summary.
    Inflate(inflate_cmd::InflateArgs),
    /// Move a template's points as little as possible so that its medial constraints hold
    /// (spokes normal to the boundary, equal spokes per atom); prints the figures as JSON.
    Project(project_cmd::ProjectArgs),
    /// Write a synthetic case (template, target segmentation from a known deformation,
    /// affine initialisation, fit.toml) into a folder.
    Synth(synth_cmd::SynthArgs),
    /// Turn any cmrep template into a synthetic case: a known twist + bend (about its long
    /// principal axis) + affine warp; writes the template, the warped boundary points, the
    /// rasterized target, the affine part, fit_boundary.toml and fit.toml into a folder.
    Warp(warp_cmd::WarpArgs),
    /// Rasterize a closed triangle mesh into a binary NIfTI mask.
    Rasterize(rasterize_cmd::RasterizeArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("MEDIAL_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .init();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), CliError> {
    let threads = configure_threads(cli.threads)?;
    match cli.command {
        Command::Fit { config, out } => {
            let cfg = config::Config::load(&config)?;
            let out = out.unwrap_or_else(|| {
                config
                    .parent()
                    .unwrap_or(std::path::Path::new("."))
                    .join("out")
            });
            let summary = fit::run(
                &cfg,
                &fit::FitOptions {
                    out: out.clone(),
                    threads,
                    quiet: cli.quiet,
                },
            )?;
            inflate_cmd::print_json(&summary.final_figures)?;
            eprintln!("results in {}", out.display());
        }
        Command::Eval {
            config,
            momenta,
            stage,
            mu,
            lambda,
            gradient,
        } => {
            let cfg = config::Config::load(&config)?;
            let figures = eval::run(
                &cfg,
                &eval::EvalOptions {
                    momenta,
                    stage,
                    mu,
                    lambda,
                    gradient,
                },
            )?;
            inflate_cmd::print_json(&figures)?;
        }
        Command::Inflate(args) => inflate_cmd::run(&args)?,
        Command::Project(args) => project_cmd::run(&args)?,
        Command::Synth(args) => synth_cmd::run(&args)?,
        Command::Warp(args) => warp_cmd::run(&args)?,
        Command::Rasterize(args) => rasterize_cmd::run(&args)?,
    }
    Ok(())
}

/// Sets the size of rayon's global pool; returns the number of threads in use.
fn configure_threads(threads: Option<usize>) -> Result<usize, CliError> {
    if let Some(n) = threads {
        if n == 0 {
            return Err(CliError::Input("--threads must be at least 1".into()));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| CliError::Input(format!("cannot start {n} threads: {e}")))?;
    }
    Ok(rayon::current_num_threads())
}
