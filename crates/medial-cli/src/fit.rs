//! `medial fit`: runs the stages of a config and writes the results.

use crate::config::Config;
use crate::error::CliError;
use crate::inflate_cmd::write_options;
use crate::model::Model;
use crate::report::{write_json, Figures, Log, LogRow, Progress, StageSummary, Summary};
use crate::stage::{self, Prepared};
use crate::time_points::{self, time_points};
use medial_core::fit::augmented_lagrangian::{run_stage, Stage};
use medial_core::fit::objective::ConstraintSet;
use medial_core::flow::{Flow, FlowParams, Trajectory};
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

/// Builds the flow of a config for `landmarks` points.
pub fn flow_of(config: &Config, landmarks: usize) -> Result<Flow, CliError> {
    let f = &config.flow;
    let params = FlowParams {
        sigma: f.sigma,
        time_steps: f.time_steps,
        kinetic_weight: f.kinetic_weight,
    };
    Ok(Flow::new(params, landmarks)?)
}

/// Runs `config` and writes everything into `options.out`.
pub fn run(config: &Config, options: &FitOptions) -> Result<Summary, CliError> {
    let model = Model::load(&config.model.template)?;
    let flow = flow_of(config, model.landmarks().len())?;
    let stages = config
        .stages
        .iter()
        .map(|s| stage::prepare(s, &model))
        .collect::<Result<Vec<_>, _>>()?;
    create_dir(&options.out.join("flow"))?;
    let mut log = Log::create(&options.out.join("log.csv"))?;
    let mut progress = Progress::new(options.quiet);
    let start = Instant::now();
    let mut controls = vec![0.0; flow.control_len()];
    let mut summaries = Vec::with_capacity(stages.len());
    for (cfg, prepared) in config.stages.iter().zip(&stages) {
        let stage_start = Instant::now();
        let engine_stage = Stage {
            flow: &flow,
            template: model.landmarks(),
            attachment: prepared.attachment.as_ref(),
            data_weight: cfg.data_weight(),
            constraints: prepared
                .constraints
                .as_ref()
                .map(|c| c as &dyn ConstraintSet),
        };
        let mut log_error = None;
        let outcome = run_stage(
            &engine_stage,
            &prepared.schedule,
            &prepared.lbfgs,
            controls,
            |p| {
                let q = &p.report.evaluation.final_positions;
                let figures = figures_at(&model, prepared, p.report.evaluation, q);
                let row = LogRow {
                    stage: &cfg.name,
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
            },
        )?;
        if let Some(e) = log_error {
            return Err(e);
        }
        let figures = end_figures(&model, prepared, &outcome.evaluation)?;
        progress.println(&format!(
            "stage '{}': {} iterations, {} evaluations, {:.1} s, total {:.6e}, stop: {}",
            cfg.name,
            outcome.iterations,
            outcome.evaluations,
            stage_start.elapsed().as_secs_f64(),
            figures.total,
            outcome
                .stops
                .last()
                .map(|s| s.to_string())
                .unwrap_or_default()
        ));
        summaries.push(StageSummary {
            name: cfg.name.clone(),
            seconds: stage_start.elapsed().as_secs_f64(),
            evaluations: outcome.evaluations,
            iterations: outcome.iterations,
            al_iterations: outcome.al_iterations,
            mu: outcome.mu,
            stop: outcome.stops.iter().map(|s| s.to_string()).collect(),
            figures,
        });
        controls = outcome.controls;
    }
    progress.finish();
    let seconds = start.elapsed().as_secs_f64();
    let trajectory = flow.shoot(model.landmarks(), &controls)?;
    write_results(config, options, &model, &flow, &controls, &trajectory)?;
    let points = time_points(&model, &trajectory);
    if !points.is_empty() {
        time_points::write_csv(&options.out.join("time_points.csv"), &points)?;
    }
    let summary = Summary {
        version: env!("CARGO_PKG_VERSION"),
        landmarks: model.landmarks().len(),
        boundary_points: model.boundary_count(),
        medial_atoms: model.medial_count(),
        constraints_per_time_point: model.constraints().map_or(0, |c| c.len()),
        time_steps: flow.time_steps(),
        sigma: flow.kernel().sigma(),
        threads: options.threads,
        seconds,
        evaluations: summaries.iter().map(|s| s.evaluations).sum(),
        final_figures: summaries
            .last()
            .map(|s| s.figures.clone())
            .expect("a config has at least one stage"),
        over_time: time_points::over_time(&points),
        stages: summaries,
    };
    write_json(&options.out.join("summary.json"), &summary)?;
    log.finish()?;
    Ok(summary)
}

/// The reported figures of an evaluation whose flow ends at `q`.
pub fn figures_at(
    model: &Model,
    prepared: &Prepared,
    e: &medial_core::fit::objective::Evaluation,
    q: &[medial_core::Vec3],
) -> Figures {
    let metrics = model.metrics(q);
    Figures::new(
        e,
        metrics.as_ref(),
        prepared.ssd.as_ref().map(|s| s.mean_distance(q)),
    )
}

/// The figures at the end of a stage: [`figures_at`] the end of the flow, with the voxel
/// overlap of Dice stages.
pub fn end_figures(
    model: &Model,
    prepared: &Prepared,
    e: &medial_core::fit::objective::Evaluation,
) -> Result<Figures, CliError> {
    let q = &e.final_positions;
    Ok(Figures {
        voxel_dice: prepared.voxel_dice(model, q)?,
        ..figures_at(model, prepared, e, q)
    })
}

/// `momenta.npy`, the model at every time point under `flow/`, and the fitted model.
fn write_results(
    config: &Config,
    options: &FitOptions,
    model: &Model,
    flow: &Flow,
    controls: &[f64],
    trajectory: &Trajectory,
) -> Result<(), CliError> {
    let out = &options.out;
    let k = model.landmarks().len();
    medial_io::npy::write_npy(
        &out.join("momenta.npy"),
        &[flow.time_steps(), k, 3],
        controls,
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
            &model.boundary_polydata(q),
            vtk_options,
        )?;
        if let Some(medial) = model.medial_polydata(q) {
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
        None => vtk::write_polydata(&fitted, &model.boundary_polydata(q), vtk_options)?,
    }
    Ok(())
}

fn create_dir(path: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(path).map_err(|e| CliError::io(path, e))
}
