//! `medial fit`: runs the stages of a config (the engine's [`run_stages`]) and writes the results.

use crate::config::Config;
use crate::error::CliError;
use crate::output::{write_json, write_options};
use crate::progress::{Log, LogRow, Progress};
use crate::stage::{self, flow_of};
use crate::summary::{StageSummary, Summary};
use crate::time_points::{self, time_points};
use medial_core::fit::{run_stages, ConstraintSet, FitEvent, PlannedStage, Stage, StageOutcome};
use medial_core::flow::{Flow, Trajectory};
use medial_core::model::{MedialConstraints, Model};
use medial_io::model::{boundary_polydata, medial_polydata};
use medial_io::vtk;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `medial fit` beyond the config.
pub struct FitOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Worker threads in use.
    pub threads: usize,
    /// No progress display.
    pub quiet: bool,
}

/// Runs `config` and writes everything into `options.out`.
pub fn run(config: &Config, options: &FitOptions) -> Result<Summary, CliError> {
    let model = medial_io::model::read_model(&config.model.template)?;
    let flow = flow_of(config, model.landmarks().len())?;
    let prepared = config
        .stages
        .iter()
        .map(|s| stage::prepare(s, &model))
        .collect::<Result<Vec<_>, _>>()?;
    let planned: Vec<PlannedStage<'_>> = prepared
        .iter()
        .map(|p| PlannedStage {
            stage: Stage {
                flow: &flow,
                initial: model.landmarks(),
                attachment: p.attachment.as_ref(),
                data_weight: p.data_weight,
                constraints: p.constraints.as_ref().map(|c| c as &dyn ConstraintSet),
            },
            schedule: p.schedule,
            lbfgs: p.lbfgs,
        })
        .collect();
    create_dir(&options.out.join("flow"))?;
    let mut log = Log::create(&options.out.join("log.csv"))?;
    let mut progress = Progress::new(options.quiet);
    let start = Instant::now();
    let mut stage_start = start;
    let mut stage_seconds = Vec::with_capacity(planned.len());
    let mut log_error = None;
    let outcomes = run_stages(&planned, |event| match event {
        FitEvent::Iteration { stage, progress: p } => {
            let (name, prepared) = (&config.stages[stage].name, &prepared[stage]);
            let e = p.report.evaluation;
            let figures = prepared.figures_at(&model, e, &e.final_positions);
            let row = LogRow {
                stage: name,
                al_iteration: p.al_iteration,
                iteration: p.report.iteration,
                evaluations: p.report.evaluations,
                mu: p.mu,
                figures: &figures,
                grad_norm: p.report.gradient_norm,
                seconds: start.elapsed().as_secs_f64(),
            };
            progress.update(&row);
            if let Err(e) = log.row(&row) {
                log_error.get_or_insert(e);
            }
        }
        FitEvent::StageEnd { stage, outcome } => {
            let seconds = stage_start.elapsed().as_secs_f64();
            progress.println(&stage_line(&config.stages[stage].name, outcome, seconds));
            stage_seconds.push(seconds);
            stage_start = Instant::now();
        }
    })?;
    if let Some(e) = log_error {
        return Err(e);
    }
    progress.finish();
    let seconds = start.elapsed().as_secs_f64();
    let stages = config
        .stages
        .iter()
        .zip(&prepared)
        .zip(outcomes.iter().zip(stage_seconds))
        .map(|((cfg, p), (outcome, seconds))| {
            Ok(StageSummary {
                name: cfg.name.clone(),
                seconds,
                evaluations: outcome.evaluations,
                iterations: outcome.iterations,
                al_iterations: outcome.al_iterations,
                mu: outcome.mu,
                stop: outcome.stops.iter().map(|s| s.to_string()).collect(),
                figures: p.end_figures(&model, &outcome.evaluation)?,
            })
        })
        .collect::<Result<Vec<_>, CliError>>()?;
    let momenta = &outcomes.last().expect("a config has a stage").momenta;
    let trajectory = flow.shoot(model.landmarks(), momenta)?;
    write_results(config, options, &model, &flow, momenta, &trajectory)?;
    let points = time_points(&model, &trajectory);
    if !points.is_empty() {
        time_points::write_csv(&options.out.join("time_points.csv"), &points)?;
    }
    let summary = Summary {
        version: env!("CARGO_PKG_VERSION"),
        landmarks: model.landmarks().len(),
        boundary_points: model.boundary_count(),
        medial_atoms: model.medial_count(),
        constraints_per_time_point: model
            .medial()
            .map_or(0, |t| MedialConstraints::new(t).len()),
        time_steps: flow.time_steps(),
        sigma: flow.kernel().sigma(),
        threads: options.threads,
        seconds,
        evaluations: stages.iter().map(|s| s.evaluations).sum(),
        final_figures: stages.last().expect("a config has a stage").figures.clone(),
        over_time: time_points::over_time(&points),
        stages,
    };
    write_json(&options.out.join("summary.json"), &summary)?;
    log.finish()?;
    Ok(summary)
}

/// The line printed at the end of a stage.
fn stage_line(name: &str, outcome: &StageOutcome, seconds: f64) -> String {
    format!(
        "stage '{name}': {} iterations, {} evaluations, {seconds:.1} s, total {:.6e}, stop: {}",
        outcome.iterations,
        outcome.evaluations,
        outcome.evaluation.total,
        outcome
            .stops
            .last()
            .map(|s| s.to_string())
            .unwrap_or_default()
    )
}

/// `momenta.npy`, the model at every time point under `flow/`, and the fitted model.
fn write_results(
    config: &Config,
    options: &FitOptions,
    model: &Model,
    flow: &Flow,
    momenta: &[f64],
    trajectory: &Trajectory,
) -> Result<(), CliError> {
    let out = &options.out;
    let k = model.landmarks().len();
    medial_io::npy::write_npy(
        &out.join("momenta.npy"),
        &[flow.time_steps(), k, 3],
        momenta,
    )?;
    let vtk_options = write_options(config.output.binary_vtk);
    let last = trajectory.time_points() - 1;
    for n in 0..=last {
        if !config.output.every_time_point && n != 0 && n != last {
            continue;
        }
        let q = trajectory.positions(n);
        vtk::write_polydata(
            &out.join(format!("flow/boundary_t{n:03}.vtk")),
            &boundary_polydata(model, q),
            vtk_options,
        )?;
        if let Some(medial) = medial_polydata(model, q) {
            vtk::write_polydata(
                &out.join(format!("flow/medial_t{n:03}.vtk")),
                &medial,
                vtk_options,
            )?;
        }
    }
    let q = trajectory.final_positions();
    let fitted = out.join("fitted_template.vtk");
    match model.medial() {
        Some(t) => medial_io::cmrep::write_template(&fitted, &t.with_landmarks(q)?, vtk_options)?,
        None => vtk::write_polydata(&fitted, &boundary_polydata(model, q), vtk_options)?,
    }
    Ok(())
}

fn create_dir(path: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(path).map_err(|e| CliError::io(path, e))
}
