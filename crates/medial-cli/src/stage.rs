//! Turns a config into what the engine runs: the flow, and for each `[[stage]]` the attachment,
//! whether the medial constraints apply, the μ schedule and the L-BFGS options; and the figures
//! reported for a configuration of the model's landmarks.

use crate::config::{
    AttachmentKind, Config, ConstraintUnitsConfig, MuUpdateConfig, StageConfig,
    TransformConventionConfig, VarifoldKindConfig,
};
use crate::error::CliError;
use crate::memory::Estimate;
use crate::summary::Figures;
use medial_core::attachment::dice::{DiceAttachment, DiceParams};
use medial_core::attachment::ssd::Ssd;
use medial_core::attachment::varifold::{Kind, Varifold, VarifoldParams, DEFAULT_NORMAL_WIDTH};
use medial_core::attachment::Attachment;
use medial_core::fit::augmented_lagrangian::{AlSchedule, CoarseTime, MuUpdate, Settle};
use medial_core::fit::objective::Evaluation;
use medial_core::fit::optimize::{LbfgsOptions, ProgressRule};
use medial_core::flow::{Flow, FlowParams};
use medial_core::image::rasterize::voxel_dice;
use medial_core::image::volume::Volume;
use medial_core::mesh::distance::SurfaceDistance;
use medial_core::mesh::Bounds;
use medial_core::model::constraints::{ConstraintUnits, MedialConstraints};
use medial_core::model::Model;
use medial_core::{TriMesh, Vec3};
use medial_io::affine::Convention;

/// The flow of a config for `landmarks` points; refuses a flow whose fit would pass the memory
/// limit ([`Estimate::flow`]).
pub fn flow_of(config: &Config, landmarks: usize) -> Result<Flow, CliError> {
    let f = &config.flow;
    Estimate::flow(config, landmarks).check(|| {
        format!(
            "a fit of {} time steps × {landmarks} landmarks",
            f.time_steps
        )
    })?;
    let params = FlowParams {
        sigma: f.sigma,
        time_steps: f.time_steps,
        kinetic_weight: f.kinetic_weight,
    };
    Ok(Flow::new(params, landmarks)?.with_kernel_tolerance(f.kernel_tolerance)?)
}

/// A stage ready to run.
pub struct Prepared {
    /// The data term.
    pub attachment: Box<dyn Attachment>,
    /// Its weight `w_data`.
    pub data_weight: f64,
    /// SSD targets, to report the mean distance.
    pub ssd: Option<Ssd>,
    /// Dice stages: the binary foreground of the image (before smoothing), to report the voxel
    /// overlap of the rasterized model.
    pub mask: Option<Volume>,
    /// Varifold stages: the target surface, to report the distance of the model's boundary to it.
    pub surface: Option<SurfaceDistance>,
    /// Varifold stages: the kernel width in use, mm (given, or chosen from the target surface).
    pub varifold_width: Option<f64>,
    /// The medial constraints, when they apply.
    pub constraints: Option<MedialConstraints>,
    /// The μ schedule.
    pub schedule: AlSchedule,
    /// L-BFGS options.
    pub lbfgs: LbfgsOptions,
}

impl Prepared {
    /// Dice stages: the voxel overlap of the model's boundary at landmarks `q` (rasterized on
    /// the image's grid) with the image's foreground.
    pub fn voxel_dice(&self, model: &Model, q: &[Vec3]) -> Result<Option<f64>, CliError> {
        let (Some(mask), Some(template)) = (&self.mask, model.medial()) else {
            return Ok(None);
        };
        let boundary = TriMesh::new(
            q[..template.boundary_count()].to_vec(),
            template.boundary_triangles().to_vec(),
        )?;
        Ok(Some(voxel_dice(&boundary, mask)?))
    }

    /// The reported figures of an evaluation whose flow ends at `q`.
    pub fn figures_at(&self, model: &Model, e: &Evaluation, q: &[Vec3]) -> Figures {
        let metrics = model.metrics(q);
        Figures::new(
            e,
            metrics.as_ref(),
            self.ssd.as_ref().map(|s| s.mean_distance(q)),
        )
    }

    /// The figures at the end of a stage: [`Prepared::figures_at`] the end of the flow, with
    /// the voxel overlap of Dice stages and the surface distance of varifold stages.
    pub fn end_figures(&self, model: &Model, e: &Evaluation) -> Result<Figures, CliError> {
        let q = &e.final_positions;
        Ok(Figures {
            voxel_dice: self.voxel_dice(model, q)?,
            surface_distance: self.surface.as_ref().map(|s| {
                let boundary = &q[..model.boundary_count()];
                s.mean_distance(boundary)
            }),
            ..self.figures_at(model, e, q)
        })
    }
}

/// Prepares `stage` for `model`.
pub fn prepare(stage: &StageConfig, model: &Model) -> Result<Prepared, CliError> {
    let constrained = stage.constraints.unwrap_or(model.medial().is_some());
    if constrained && model.medial().is_none() {
        return Err(CliError::Input(format!(
            "stage '{}': constraints = true needs a medial template (a VTK file with a MedialIndex array)",
            stage.name
        )));
    }
    let weight = stage.data_weight();
    let (mut ssd, mut mask, mut surface, mut varifold_width) = (None, None, None, None);
    let (attachment, data_weight): (Box<dyn Attachment>, _) = match stage.attachment {
        AttachmentKind::Ssd => {
            let points = Ssd::new(ssd_targets(stage, model)?)?;
            (Box::new(ssd.insert(points).clone()), weight)
        }
        AttachmentKind::Dice => {
            let (dice, foreground) = dice(stage, model)?;
            mask = Some(foreground);
            (Box::new(dice), weight)
        }
        AttachmentKind::Varifold => {
            let (varifold, target) = varifold(stage, model)?;
            surface = Some(SurfaceDistance::new(&target)?);
            varifold_width = Some(varifold.width());
            let weight = weight / varifold.target_norm2();
            (Box::new(varifold), weight)
        }
    };
    Ok(Prepared {
        data_weight,
        attachment,
        ssd,
        mask,
        surface,
        varifold_width,
        constraints: constraints(stage, model, constrained)?,
        schedule: AlSchedule {
            mu: stage.mu,
            mu_factor: stage.mu_factor,
            mu_max: stage.mu_max,
            iterations: stage.al_iterations,
            mu_update: match stage.mu_update {
                MuUpdateConfig::Always => MuUpdate::Always,
                MuUpdateConfig::IfNotHalved => MuUpdate::IfNotHalved,
            },
            first_iterations: stage.first_iterations,
            settle: stage.settle_constraint.map(|max_abs_constraint| Settle {
                max_abs_constraint,
                data_change: stage.settle_data_change,
            }),
            coarse: stage
                .coarse_time_steps
                .zip(stage.coarse_al_iterations())
                .map(|(time_steps, al_iterations)| CoarseTime {
                    time_steps,
                    al_iterations,
                }),
        },
        lbfgs: LbfgsOptions {
            max_iterations: stage.max_iterations,
            memory: stage.lbfgs_memory,
            gradient_tolerance: stage.gradient_tolerance,
            relative_decrease: stage.relative_decrease,
            progress: (stage.progress_window > 0).then_some(ProgressRule {
                window: stage.progress_window,
                decrease: stage.progress_decrease,
            }),
        },
    })
}

/// The medial constraints of a constrained stage, in the stage's units.
fn constraints(
    stage: &StageConfig,
    model: &Model,
    constrained: bool,
) -> Result<Option<MedialConstraints>, CliError> {
    let Some(template) = model.medial().filter(|_| constrained) else {
        return Ok(None);
    };
    let units = match stage.constraint_units {
        ConstraintUnitsConfig::Absolute => ConstraintUnits::Absolute,
        ConstraintUnitsConfig::Relative => ConstraintUnits::Relative,
    };
    let constraints = MedialConstraints::with_units(template, units)
        .map_err(|e| CliError::Input(format!("stage '{}': {e}", stage.name)))?;
    Ok(Some(constraints))
}

/// The SSD targets: the points of `target` (same count and order as the template boundary),
/// or the template boundary moved by the affine `transform`.
fn ssd_targets(stage: &StageConfig, model: &Model) -> Result<Vec<Vec3>, CliError> {
    let nb = model.boundary_count();
    if let Some(path) = &stage.transform {
        let convention = match stage.transform_convention {
            Some(TransformConventionConfig::Lps) => Convention::Lps,
            Some(TransformConventionConfig::Ras) | None => Convention::Ras,
        };
        let read = medial_io::affine::read_affine_as(path, convention)?;
        let determinant = read.matrix().fixed_view::<3, 3>(0, 0).determinant();
        if !(determinant.is_finite() && determinant > 0.0) {
            return Err(CliError::Transform {
                stage: stage.name.clone(),
                path: path.clone(),
                determinant,
            });
        }
        let m = match stage.transform_invert {
            Some(true) => read.inverse(),
            _ => read,
        };
        return Ok(model.landmarks()[..nb]
            .iter()
            .map(|p| m.transform_point(&(*p).into()).coords)
            .collect());
    }
    let path = stage
        .target
        .as_deref()
        .expect("checked by the config: ssd has target or transform");
    let points = medial_io::mesh::read_points(path)?;
    if points.len() != nb {
        return Err(CliError::Input(format!(
            "stage '{}': target {} has {} points but the template boundary has {nb}; an SSD target needs the same points in the same order",
            stage.name,
            path.display(),
            points.len()
        )));
    }
    Ok(points)
}

/// The varifold attachment of a stage (the model's boundary against the stage's surface) and
/// the surface.
fn varifold(stage: &StageConfig, model: &Model) -> Result<(Varifold, TriMesh), CliError> {
    let path = stage
        .surface
        .as_deref()
        .expect("checked by the config: varifold has surface");
    let target = medial_io::mesh::read_mesh(path)?;
    let kind = match stage.varifold_kind {
        VarifoldKindConfig::Varifold => Kind::Varifold,
        VarifoldKindConfig::Oriented => Kind::OrientedVarifold {
            normal_width: DEFAULT_NORMAL_WIDTH,
        },
        VarifoldKindConfig::Current => Kind::Current,
    };
    let params = VarifoldParams {
        kind,
        width: stage.varifold_width,
    };
    let varifold = Varifold::new(
        model.boundary_triangles(),
        model.landmarks().len(),
        &target,
        params,
    )
    .map_err(|e| CliError::Input(format!("stage '{}': {e}", stage.name)))?;
    Ok((varifold, target))
}

/// `config` with the settings chosen from the data written out (each varifold stage's kernel
/// width), so that the config a fit writes runs again to the same bits with every value named.
pub fn with_choices(config: &Config, prepared: &[Prepared]) -> Config {
    let mut resolved = config.clone();
    for (stage, p) in resolved.stages.iter_mut().zip(prepared) {
        stage.varifold_width = stage.varifold_width.or(p.varifold_width);
    }
    resolved
}

/// Voxels kept around the foreground when an image is refined: the reach of the smoothing
/// (4 σ) and two voxels more.
fn refine_margin(stage: &StageConfig, volume: &Volume) -> usize {
    (4.0 * stage.image_sigma / volume.spacing().min()).ceil() as usize + 2
}

/// The Dice attachment of a stage (the image's foreground, smoothed, against the model) and the
/// foreground itself. Refuses a stage past the memory limit ([`Estimate::dice`]) and an image
/// whose foreground no sample of the template's interior sees.
fn dice(stage: &StageConfig, model: &Model) -> Result<(DiceAttachment, Volume), CliError> {
    let template = model.medial().ok_or_else(|| {
        CliError::Input(format!(
            "stage '{}': the dice attachment needs a medial template (its interior is sampled between boundary and medial sheet)",
            stage.name
        ))
    })?;
    let path = stage
        .image
        .as_deref()
        .expect("checked by the config: dice has image");
    let volume = medial_io::volume::read_volume(path)?;
    let margin = refine_margin(stage, &volume);
    let refined_voxels: usize = match stage.image_refine {
        1 => 0,
        f => volume.refined_dims(f, margin).iter().product(),
    };
    Estimate::dice(
        stage,
        template.boundary_triangles().len(),
        template.landmark_count(),
        volume.data().len() + refined_voxels,
    )
    .check(|| format!("stage '{}'", stage.name))?;
    let mask = volume.foreground(stage.label);
    let fine = match stage.image_refine {
        1 => None,
        f => Some(volume.refined(f, margin)?.foreground(stage.label)),
    };
    drop(volume); // Not needed past its masks: freed before the smoothing copies.
    let image = fine
        .as_ref()
        .unwrap_or(&mask)
        .smoothed(stage.image_sigma)
        .map_err(|e| CliError::Input(format!("stage '{}': image_sigma: {e}", stage.name)))?;
    drop(fine);
    let medial_of: Vec<usize> = template
        .medial_index()
        .iter()
        .map(|&m| template.atom_landmark(m))
        .collect();
    let params = DiceParams {
        subdivision: stage.subdivision,
        layers: stage.layers,
    };
    let attachment = DiceAttachment::new(
        template.boundary_triangles(),
        &medial_of,
        template.landmark_count(),
        image,
        params,
    )
    .map_err(|e| CliError::Input(format!("stage '{}': {}: {e}", stage.name, path.display())))?;
    if attachment.dice(template.landmarks(), None)?.overlap <= 0.0 {
        // The attachment has refused an empty foreground, the template has boundary points.
        return Err(CliError::NoOverlap {
            stage: stage.name.clone(),
            image: path.into(),
            foreground: Box::new(mask.support_bounds().expect("a foreground voxel")),
            template: Box::new(Bounds::of(template.boundary_points()).expect("a boundary point")),
        });
    }
    Ok((attachment, mask))
}
