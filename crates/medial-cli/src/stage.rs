//! The stages of a config read into the engine: the flow within the memory limit, each stage's
//! data read from its file into a [`Target`] and prepared ([`PreparedStage::new`]), the settings
//! the engine chose from the data written back into the config, and the figures a fit reports.

use crate::config::{Config, Source, StageConfig};
use crate::error::CliError;
use crate::memory;
use crate::summary::Figures;
use medial_core::fit::objective::Evaluation;
use medial_core::fit::{Disagreement, Miss};
use medial_core::fit::{PreparedStage, Target};
use medial_core::flow::Flow;
use medial_core::model::Model;
use medial_core::Vec3;
use medial_io::affine::Convention;

/// The flow of a config for `landmarks` points; refuses a flow whose fit would pass the memory
/// limit ([`medial_core::fit::FitSpec::flow_estimate`]).
pub fn flow_of(config: &Config, landmarks: usize) -> Result<Flow, CliError> {
    let spec = config.spec();
    memory::limit().check(&spec.flow_estimate(landmarks), || {
        format!(
            "a fit of {} time steps × {landmarks} landmarks",
            config.flow.time_steps
        )
    })?;
    Ok(spec.flow.flow(landmarks)?)
}

/// Reads the data of `stage` for `model`: the points of its target mesh, the template's
/// boundary carried by its transform, its image or its surface.
pub fn read_target(stage: &StageConfig, model: &Model) -> Result<Target, CliError> {
    let source = stage.source().map_err(CliError::Input)?;
    Ok(match source {
        Source::Target(path) => Target::Points(medial_io::mesh::read_points(&path)?),
        Source::Transform(path) => {
            let convention = stage.transform_convention.unwrap_or(Convention::Ras);
            let read = medial_io::affine::read_affine_as(&path, convention)?;
            let determinant = read.matrix().fixed_view::<3, 3>(0, 0).determinant();
            if !(determinant.is_finite() && determinant > 0.0) {
                return Err(CliError::Transform {
                    stage: stage.name.clone(),
                    path,
                    determinant,
                });
            }
            let m = match stage.transform_invert {
                Some(true) => read.inverse(),
                _ => read,
            };
            let boundary = &model.landmarks()[..model.boundary_count()];
            Target::Points(medial_core::mesh::carry_points(boundary, m.matrix()))
        }
        Source::Image(path, label) => Target::Image {
            volume: medial_io::volume::read_volume(&path)?,
            label,
        },
        Source::Surface(path) => Target::Surface(medial_io::mesh::read_mesh(&path)?),
    })
}

/// Prepares `stage` for `model` against `target` (read from the stage's file), within the
/// memory limit; errors name the stage and its file.
pub fn prepare(
    stage: &StageConfig,
    model: &Model,
    target: Target,
) -> Result<PreparedStage, CliError> {
    let file = stage.source().ok().map(|source| match source {
        Source::Target(p) | Source::Transform(p) | Source::Image(p, _) | Source::Surface(p) => p,
    });
    PreparedStage::new(&stage.spec(), model, target, memory::limit()).map_err(|e| match e {
        medial_core::Error::NoOverlap {
            foreground,
            template,
        } => CliError::NoOverlap {
            stage: stage.name.clone(),
            image: file.clone().unwrap_or_default(),
            foreground,
            template,
        },
        medial_core::Error::Memory {
            estimate, limit, ..
        } => CliError::Memory {
            what: format!("stage '{}'", stage.name),
            estimate,
            limit,
        },
        // About the stage's settings or the template, not its file.
        e @ (medial_core::Error::Setting { .. }
        | medial_core::Error::NeedsMedial(_)
        | medial_core::Error::WrongTarget { .. }) => {
            CliError::Input(format!("stage '{}': {e}", stage.name))
        }
        e => {
            let file = file.as_deref().map(|p| format!("{}: ", p.display()));
            CliError::Input(format!(
                "stage '{}': {}{e}",
                stage.name,
                file.unwrap_or_default()
            ))
        }
    })
}

/// Reads the data of every stage of `config` and prepares it for `model`; a stage whose data
/// a stage of `earlier` prepared against the same source serves ([`PreparedStage::shared`])
/// neither reads nor prepares it again.
pub fn prepare_all(
    config: &Config,
    model: &Model,
    earlier: &[(Source, PreparedStage)],
) -> Result<Vec<PreparedStage>, CliError> {
    config
        .stages
        .iter()
        .map(|s| {
            let source = s.source().ok();
            let same = earlier
                .iter()
                .filter(|(from, _)| Some(from) == source.as_ref())
                .map(|(_, p)| p);
            match PreparedStage::shared(same, &s.spec(), model)? {
                Some(shared) => Ok(shared),
                None => prepare(s, model, read_target(s, model)?),
            }
        })
        .collect()
}

/// Each stage of `config` prepared in `prepared`, with its source: the `earlier` of a
/// [`prepare_all`] that follows.
pub fn by_source(config: &Config, prepared: &[PreparedStage]) -> Vec<(Source, PreparedStage)> {
    (config.stages.iter().zip(prepared))
        .filter_map(|(s, p)| Some((s.source().ok()?, p.clone())))
        .collect()
}

/// `config` with the settings chosen from the data written out (each varifold stage's kernel
/// width), so that the config a fit writes runs again to the same bits with every value named.
pub fn with_choices(config: &Config, prepared: &[PreparedStage]) -> Config {
    let mut resolved = config.clone();
    for (stage, p) in resolved.stages.iter_mut().zip(prepared) {
        stage.varifold_width = stage.varifold_width.or(p.varifold_width);
    }
    resolved
}

/// The reported figures of an evaluation of `stage` whose flow ends at `q`.
pub fn figures_at(stage: &PreparedStage, model: &Model, e: &Evaluation, q: &[Vec3]) -> Figures {
    let metrics = model.metrics(q);
    Figures::new(e, metrics.as_ref(), stage.ssd_distance(q))
}

/// The figures at the end of a stage: [`figures_at`] the end of the flow, with the voxel
/// overlap of Dice stages, the surface distance of varifold stages and the parts missed and
/// added of both; and, for those, the part of the target the model missed if it is too large
/// ([`Disagreement::miss`] for the flow's kernel width `sigma`, mm).
pub fn end_figures(
    stage: &PreparedStage,
    model: &Model,
    e: &Evaluation,
    sigma: f64,
) -> Result<(Figures, Option<Miss>), CliError> {
    let q = &e.final_positions;
    let disagreement = stage.disagreement(model, q)?;
    let pct = |share: f64| 100.0 * share;
    let d = disagreement.as_ref();
    let figures = Figures {
        voxel_dice: d.and_then(Disagreement::voxel_dice),
        missed_pct: d.map(|d| pct(d.missed_beyond(d.reach(sigma)))),
        added_pct: d.map(|d| pct(d.added_beyond(d.reach(sigma)))),
        surface_distance: stage.surface_distance(model, q),
        ..figures_at(stage, model, e, q)
    };
    Ok((figures, d.and_then(|d| d.miss(sigma))))
}
