//! `medial mean`: a population template built in rounds from a cohort ([`medial_stats::mean`]):
//! each round fits the subjects by `medial batch` from the round's template, averages the usable
//! fits after Procrustes alignment, projects the average onto the medial constraints and takes
//! it as the next round's template, until the change of shape per round (the boundary's move
//! along its normals) is within the tolerance.

use crate::commands::batch::{fit_and_gather, BatchArgs};
use crate::commands::stats::cohort::{medial_template, Cohort, LeftOut};
use crate::error::CliError;
use crate::output::{print_json, write_json, write_options, write_text};
use medial_core::construction::project::ProjectOptions;
use medial_stats::{mean_template, Alignment};
use serde::Serialize;
use std::path::PathBuf;

/// Build a mean template from a cohort.
#[derive(clap::Args, Debug)]
pub struct MeanArgs {
    /// The starting template (a cmrep medial template, legacy VTK, mm).
    #[arg(value_name = "TEMPLATE.vtk")]
    pub template: PathBuf,
    /// The subjects, as `medial batch` takes them.
    #[arg(value_name = "SUBJECTS.csv")]
    pub subjects: PathBuf,
    /// Output folder: DIR/roundK/ the batch of round K (fitted from DIR/template_{K-1}.vtk, the
    /// given template for K = 1), DIR/template_K.vtk its mean, DIR/mean_template.vtk the last,
    /// DIR/rounds.csv and DIR/summary.json.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// A base config for the fits, as `medial batch --config` takes it.
    #[arg(long, value_name = "BASE.toml")]
    pub config: Option<PathBuf>,
    /// Most rounds.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub rounds: u64,
    /// Stop when a round changes the template's shape by at most this much: the root mean
    /// square of its boundary points' move along its normals, mm (the points' slide along the
    /// surface is reported, not checked: a Dice fit does not fix it). The default is a fifth of
    /// a 0.5 mm voxel: fits of segmentations do not resolve less.
    #[arg(long, value_name = "MM", default_value_t = 0.1)]
    pub tolerance: f64,
    /// The Procrustes alignment of the fits before they are averaged: similarity, rigid or
    /// none.
    #[arg(long, value_name = "HOW", default_value = "similarity")]
    pub align: Alignment,
}

/// One round in rounds.csv and summary.json.
#[derive(Serialize)]
struct Round {
    round: u64,
    subjects: usize,
    left_out: Vec<LeftOut>,
    /// RMS landmark move from the round's template, mm.
    change_mm: f64,
    /// RMS boundary move along the round's template's normals (the change of shape, which
    /// the tolerance is checked against), mm.
    shape_change_mm: f64,
    /// RMS boundary move along the surface (the points sliding on it), mm.
    slide_mm: f64,
    /// RMS landmark move of the projection onto the constraints, mm.
    projection_mm: f64,
    max_spoke_normal_deg: f64,
    max_spoke_mismatch_pct: f64,
    template: PathBuf,
}

/// What `medial mean` prints and writes as summary.json.
#[derive(Serialize)]
struct Summary {
    /// `mean`: what wrote the folder ([`crate::results::refuse_other_results`]).
    command: &'static str,
    template: PathBuf,
    alignment: &'static str,
    tolerance_mm: f64,
    converged: bool,
    mean_template: PathBuf,
    rounds: Vec<Round>,
}

/// Runs the rounds, writes the templates, DIR/rounds.csv and DIR/summary.json, prints the
/// summary.
pub fn run(args: &MeanArgs, threads: usize, quiet: bool) -> Result<(), CliError> {
    crate::results::refuse_other_results(&args.out, "mean")?;
    if !(args.tolerance >= 0.0 && args.tolerance.is_finite()) {
        return Err(CliError::Usage(format!(
            "--tolerance {}: expected a distance in mm, 0 or more",
            args.tolerance
        )));
    }
    std::fs::create_dir_all(&args.out).map_err(|e| CliError::io(&args.out, e))?;
    let mut current = args.template.clone();
    let mut rounds = Vec::new();
    let mut converged = false;
    for round in 1..=args.rounds {
        eprintln!(
            "round {round}: fitting the cohort from {}",
            current.display()
        );
        let dir = args.out.join(format!("round{round}"));
        let batch = BatchArgs::fit(&current, &args.subjects, &dir, args.config.as_deref());
        let (_, outcome) = fit_and_gather(&batch, threads, quiet)?;
        match outcome {
            Err(e @ CliError::SubjectsFailed { .. }) => eprintln!("round {round}: {e}"),
            other => other?,
        }
        let cohort = Cohort::read(&dir)?;
        let (names, left_out) = cohort.usable();
        let models = names
            .iter()
            .map(|name| cohort.fitted(name))
            .collect::<Result<Vec<_>, _>>()?;
        let reference = medial_template(&current)?;
        let mean = mean_template(&models, &reference, args.align, &ProjectOptions::default())
            .map_err(|e| CliError::Input(format!("round {round}: {e}")))?;
        let path = args.out.join(format!("template_{round}.vtk"));
        medial_io::cmrep::write_template(&path, &mean.template, write_options(true))?;
        eprintln!(
            "round {round}: {} fits averaged, the template moved by {:.4} mm (RMS): its shape \
             by {:.4} mm along its normals, its points by {:.4} mm along the surface",
            models.len(),
            mean.change,
            mean.shape_change,
            mean.slide
        );
        rounds.push(Round {
            round,
            subjects: models.len(),
            left_out,
            change_mm: mean.change,
            shape_change_mm: mean.shape_change,
            slide_mm: mean.slide,
            projection_mm: mean.projection_rms,
            max_spoke_normal_deg: mean.after.max_spoke_normal_deg,
            max_spoke_mismatch_pct: 100.0 * mean.after.max_mismatch,
            template: path.clone(),
        });
        current = path;
        if mean.shape_change <= args.tolerance {
            converged = true;
            break;
        }
    }
    let mean_path = args.out.join("mean_template.vtk");
    std::fs::copy(&current, &mean_path).map_err(|e| CliError::io(&mean_path, e))?;
    let mut table = String::from(
        "round,subjects,change_mm,shape_change_mm,slide_mm,projection_mm,max_spoke_normal_deg,\
         max_spoke_mismatch_pct\n",
    );
    for r in &rounds {
        table.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            r.round,
            r.subjects,
            r.change_mm,
            r.shape_change_mm,
            r.slide_mm,
            r.projection_mm,
            r.max_spoke_normal_deg,
            r.max_spoke_mismatch_pct
        ));
    }
    write_text(&args.out.join("rounds.csv"), &table)?;
    let summary = Summary {
        command: "mean",
        template: args.template.clone(),
        alignment: args.align.name(),
        tolerance_mm: args.tolerance,
        converged,
        mean_template: mean_path,
        rounds,
    };
    write_json(&args.out.join("summary.json"), &summary)?;
    print_json(&summary)?;
    Ok(())
}
