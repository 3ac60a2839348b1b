//! The commands of `medial`, one module each (`medial fit` wires [`crate::fitting`]): [`eval`]
//! evaluates a TOML schedule;
//! [`inflate`], [`project`] and [`synth`] build templates and synthetic cases; [`rasterize`]
//! turns a closed mesh into a mask; [`report`] writes the views of a fit folder again;
//! [`check`] measures whether the medial points stay the centres of inscribed balls; [`apply`]
//! carries other data by the map of a fit; [`batch`] fits a cohort of subjects and gathers it;
//! [`template`] builds a template from a shape (a segmentation or a closed mesh); [`stats`]
//! tests a design's contrasts at every element of a mesh or at every atom of a cohort; [`pca`]
//! finds the shape modes of a cohort; [`mean`] builds a population template from one.

mod apply;
mod batch;
mod check;
mod eval;
mod inflate;
mod mean;
mod pca;
mod project;
mod rasterize;
mod report;
mod stats;
mod synth;
mod template;

use crate::config::Config;
use crate::error::CliError;
use crate::output::print_json;
use clap::Subcommand;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The commands of `medial`.
#[derive(Subcommand)]
pub enum Command {
    /// Run the stages of a TOML config, or without one an automatic schedule for --template
    /// and one of --image, --target, --surface; write config.toml (the resolved config),
    /// summary.json, log.csv, momenta.npy, lambda.npy, the flow of the model
    /// (flow/boundary_tNNN.vtk, flow/medial_tNNN.vtk), time_points.csv, the per-atom table
    /// (atoms.csv, atoms.npy) and fitted_template.vtk as one set (summary.json, moved in last, lists the others), then the views of the set:
    /// the ParaView series flow/boundary.vtk.series and flow/medial.vtk.series, flow.glb (the
    /// flow animated over t, coloured by thickness) and report.html. SIGINT or SIGTERM stops
    /// the fit after the current iteration with a checkpoint and the results so far (exit code
    /// 130 / 143); --resume continues it to the same bits. A fit that ends unsound exits 3, one
    /// whose constraints are above their tolerance 4, one whose model misses a part of its
    /// image or surface 6, each with its results written and its status in summary.json.
    Fit {
        /// The config file (TOML); relative paths in it are relative to its folder. With it,
        /// --template and the targets override the config's.
        #[arg(
            value_name = "CONFIG.toml",
            required_unless_present_any = ["template", "resume"]
        )]
        config: Option<PathBuf>,
        /// Output folder (created if needed) [default with a config: "out" beside it].
        #[arg(
            long,
            value_name = "DIR",
            required_unless_present_any = ["config", "resume"],
            conflicts_with = "resume"
        )]
        out: Option<PathBuf>,
        /// Continue the fit stopped in DIR (by SIGINT, SIGTERM or a kill after a periodic
        /// checkpoint) from DIR/checkpoint.bin, writing into DIR; it ends with the same bits as
        /// a fit never stopped. Without CONFIG.toml, DIR/config.toml is the config; a fit
        /// started without one resumes with the flags it was started with (--template and its
        /// target: a kill before its first results leaves no config.toml). Refused when the
        /// config or an input file differs from the stopped fit's.
        #[arg(long, value_name = "DIR")]
        resume: Option<PathBuf>,
        /// Also write DIR/checkpoint.bin every SECONDS of wall-clock time (after the iteration
        /// in progress) without stopping, so that a fit killed at a batch system's wall-time
        /// limit can be resumed with --resume.
        #[arg(long, value_name = "SECONDS", value_parser = positive_seconds)]
        checkpoint_every: Option<Duration>,
        #[command(flatten)]
        inputs: crate::fitting::Inputs,
    },
    /// Evaluate a stage's objective at given momenta without optimising; prints one JSON object.
    Eval {
        /// The config file (TOML).
        config: PathBuf,
        /// Momenta u, a float64 .npy array of shape [N, k, 3] (coordinate unit per unit time).
        #[arg(long, value_name = "U.npy")]
        momenta: PathBuf,
        /// Stage whose objective is evaluated [default: the first].
        #[arg(long, value_name = "NAME")]
        stage: Option<String>,
        /// Penalty weight μ, positive [default: the stage's mu].
        #[arg(long, value_name = "X", value_parser = positive_mu)]
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
    Inflate(inflate::InflateArgs),
    /// Move a template's points as little as possible so that its medial constraints hold
    /// (spokes normal to the boundary, equal spokes per atom); prints the figures as JSON.
    Project(project::ProjectArgs),
    /// Write a synthetic case into a folder: a built-in shape (cup, toy) or, with --from, any
    /// cmrep template, a target segmentation and the target boundary points from a known
    /// twist + bend + affine deformation, the affine part, and ready configs.
    Synth(synth::SynthArgs),
    /// Build a medial template from a shape (a segmentation or a closed mesh): its medial sheet
    /// (exact distance transform, ridge, a triangular lattice with a radius per vertex), one Loop
    /// subdivision, inflation, projection, a short Dice fit to the shape itself (two AL iterations) and
    /// projection again; writes TEMPLATE.vtk and its figures as JSON (printed too).
    Template(template::TemplateArgs),
    /// Rasterize a closed triangle mesh into a binary NIfTI mask.
    Rasterize(rasterize::RasterizeArgs),
    /// Write report.html, flow.glb and the ParaView series (flow/*.vtk.series) of a fit folder
    /// again from its files.
    Report(report::ReportArgs),
    /// Fit every subject of SUBJECTS.csv from one template into DIR/SUBJECT/ (as `medial fit`
    /// does; subjects fitted earlier are skipped, interrupted ones resumed, failed ones
    /// recorded in DIR/SUBJECT/failed.json while the others go on), then gather DIR/cohort.csv,
    /// DIR/thickness.npy [subjects × atoms] and DIR/thickness_mean.vtk; exit code 1 if a subject
    /// failed. --shard I/N or a Slurm array task fits a share; --slurm writes Slurm job scripts.
    Batch(batch::BatchArgs),
    /// Measure whether the medial points of a template, or of a fit at every time point, stay
    /// the centres of balls inscribed in the boundary (residual |d − r| / r, balls poking out);
    /// prints JSON, exits with code 5 past --max-residual.
    Check(check::CheckArgs),
    /// Carry points, meshes (.vtk, .obj, .gltf, .glb; VTK arrays kept) or NIfTI images (labels
    /// nearest, intensities linear) from the template's space to the subject's by the map of a
    /// fit (its flow after its initial alignment), or back with --inverse; optionally write the
    /// displacement field as a NIfTI warp for ITK, ANTs and greedy. Prints a JSON summary.
    Apply(apply::ApplyArgs),
    /// A general linear model at every point (or cell, --cell) of a mesh whose array holds one
    /// component per subject, as meshglm takes it, or at every atom of a `medial batch` cohort
    /// (a measure of each subject's fitted model, --array): t or F and parametric p, with --permutations
    /// the FWER-corrected p of the maximum statistic, of clusters (--threshold) and of TFCE
    /// (--tfce). Writes DIR/stats.vtk (arrays beta, t, p, p_fwer, cluster, p_cluster, tfce,
    /// p_tfce), DIR/clusters.csv, the clusters' outlines DIR/clusters_edges.vtk and
    /// DIR/summary.json (printed too).
    Stats(stats::StatsArgs),
    /// Shape modes of a `medial batch` cohort: generalised Procrustes alignment of the fitted
    /// models' medial atoms (positions and radii) or boundaries, principal components. Writes
    /// DIR/modes.csv (variance and explained fraction of each mode), DIR/scores.csv (subject,
    /// pc1, …: a design for `medial stats`), the mean shape, each mode's shapes from −2 to +2
    /// SD as ParaView series (DIR/modeK_boundary.vtk.series, modeK_medial.vtk.series) and
    /// DIR/summary.json (printed too).
    Pca(pca::PcaArgs),
    /// A population template: fits the subjects by `medial batch` from the template, averages
    /// the fits after generalised Procrustes alignment, projects the average onto the medial
    /// constraints and fits again from it, until a round moves it by at most --tolerance mm
    /// (RMS) or --rounds are done. Writes DIR/roundK/ (each round's batch),
    /// DIR/template_K.vtk, DIR/mean_template.vtk, DIR/rounds.csv (the change per round) and
    /// DIR/summary.json (printed too).
    Mean(mean::MeanArgs),
}

/// Parses `--mu`: a positive, finite penalty weight.
fn positive_mu(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(mu) if mu.is_finite() && mu > 0.0 => Ok(mu),
        _ => Err(format!(
            "the penalty weight μ must be a positive number, got '{text}'"
        )),
    }
}

/// Parses `--checkpoint-every`: a positive, finite number of seconds.
fn positive_seconds(text: &str) -> Result<Duration, String> {
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 => Ok(Duration::from_secs_f64(s)),
        _ => Err(format!(
            "the checkpoint period must be a positive number of seconds, got '{text}'"
        )),
    }
}

/// Runs `command` with `threads` worker threads in use.
pub fn run(command: Command, threads: usize, quiet: bool) -> Result<(), CliError> {
    match command {
        Command::Fit {
            config,
            out,
            resume,
            checkpoint_every,
            inputs,
        } => {
            let out = resume
                .clone()
                .or(out)
                .or_else(|| {
                    config
                        .as_ref()
                        .map(|c| c.parent().unwrap_or(Path::new(".")).join("out"))
                })
                .expect("clap requires --out without a config or --resume");
            // A fit without a config resumes as it started: automatic, from the flags.
            let config = config.or_else(|| {
                (resume.as_ref())
                    .filter(|_| inputs.template.is_none())
                    .map(|dir| dir.join("config.toml"))
            });
            let resolved = crate::fitting::resolve(config.as_deref(), &inputs, &out)?;
            let summary = crate::fitting::run(
                &resolved,
                &crate::fitting::FitOptions {
                    out: out.clone(),
                    threads,
                    quiet,
                    checkpoint_every,
                    resume: resume.is_some(),
                },
            )?;
            print_json(&summary.final_figures)?;
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
            let cfg = Config::load(&config)?;
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
            print_json(&figures)?;
        }
        Command::Inflate(args) => inflate::run(&args)?,
        Command::Project(args) => project::run(&args)?,
        Command::Synth(args) => synth::run(&args)?,
        Command::Template(args) => template::run(&args)?,
        Command::Rasterize(args) => rasterize::run(&args)?,
        Command::Report(args) => report::run(&args)?,
        Command::Check(args) => check::run(&args)?,
        Command::Batch(args) => batch::run(&args, threads, quiet)?,
        Command::Apply(args) => apply::run(&args)?,
        Command::Stats(args) => stats::run(&args)?,
        Command::Pca(args) => pca::run(&args)?,
        Command::Mean(args) => mean::run(&args, threads, quiet)?,
    }
    Ok(())
}
