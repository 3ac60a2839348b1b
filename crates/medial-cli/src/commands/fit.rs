//! `medial fit`: runs the stages of a config (the engine's [`run_stages_resumable`]), pausing
//! for checkpoints and signals, and writes the results as one set.

use crate::checkpoint::{self, Fingerprint, Saved};
use crate::config::StageConfig;
use crate::config::{AttachmentKind, Config};
use crate::error::CliError;
use crate::output::model_error;
use crate::output::{write_json, write_options, write_text};
use crate::plan::{plain_sigma, varifold_widths, Geometry, Target};
use crate::progress::{Log, LogRow, Progress};
use crate::results::{create_dir, ResultSet};
use crate::signals::{Signal, Signals};
use crate::stage::{self, flow_of, Prepared};
use crate::summary::{Figures, StageSummary, Status, Summary};
use crate::time_points::{self, time_points};
use medial_core::build::project::{project, ConstraintFigures, ProjectOptions};
use medial_core::fit::{
    affine_between, align_affine, align_similarity, anisotropy, explained_spread,
    run_stages_resumable, similarity_between, Checkpoint, ConstraintSet, FitEvent, FitRun, Guard,
    PlannedStage, Stage, StageOutcome,
};
use medial_core::flow::{Flow, Trajectory, STRAIN_LIMIT};
use medial_core::image::rasterize::{grid_around, rasterize};
use medial_core::image::Volume;
use medial_core::mesh::topology::{check_closed_oriented_manifold, check_outward};
use medial_core::mesh::TriMesh;
use medial_core::model::MedialTemplate;
use medial_core::model::{MedialConstraints, Model};
use medial_core::synth::{boundary_mesh, PrincipalAxes};
use medial_core::Vec3;
use medial_io::model::{boundary_polydata, medial_polydata};
use medial_io::vtk;
use nalgebra::Matrix4;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The inputs of `medial fit` given as flags: without a config they choose an automatic
/// schedule ([`crate::plan::FitPlan::automatic`]); with one they replace its template and
/// targets. Relative paths are relative to the working directory.
#[derive(clap::Args, Debug)]
pub struct Inputs {
    /// The template: a cmrep medial template (legacy VTK with a MedialIndex point array; mm).
    #[arg(long, value_name = "TEMPLATE.vtk")]
    pub template: Option<PathBuf>,
    /// A segmentation to fit by Dice (.nii, .nii.gz, .exr; world coordinates in mm).
    #[arg(long, value_name = "SEG.nii.gz", conflicts_with_all = ["target", "surface"])]
    pub image: Option<PathBuf>,
    /// With --image: the foreground label [default: every voxel > 0].
    #[arg(long, value_name = "L", requires = "image")]
    pub label: Option<f64>,
    /// Points in correspondence with the template's boundary points, fitted by SSD (.vtk,
    /// .obj, .gltf, .glb; same count and order).
    #[arg(long, value_name = "POINTS.vtk", conflicts_with = "surface")]
    pub target: Option<PathBuf>,
    /// A surface without correspondence (any vertex count and order), fitted by a varifold
    /// distance (.vtk, .obj, .gltf, .glb).
    #[arg(long, value_name = "MESH.vtk")]
    pub surface: Option<PathBuf>,
}

impl Inputs {
    /// The same inputs with absolute paths, so that the resolved config names them wherever it
    /// is read from.
    fn absolute(&self) -> Result<Self, CliError> {
        let abs = |p: &Option<PathBuf>| {
            p.as_deref()
                .map(|p| std::path::absolute(p).map_err(|e| CliError::io(p, e)))
                .transpose()
        };
        Ok(Self {
            template: abs(&self.template)?,
            image: abs(&self.image)?,
            label: self.label,
            target: abs(&self.target)?,
            surface: abs(&self.surface)?,
        })
    }
}

/// The config of a fit: `config` with the flags of `inputs` in place of its template and
/// targets, or without one the automatic schedule of `inputs`.
pub fn resolve(config: Option<&Path>, inputs: &Inputs, out: &Path) -> Result<Config, CliError> {
    if inputs.label.is_some() && inputs.image.is_none() {
        return Err(CliError::Usage("--label needs --image".into()));
    }
    let inputs = &inputs.absolute()?;
    let Some(path) = config else {
        return automatic(inputs, out);
    };
    let mut config = Config::load(path)?;
    if let Some(template) = &inputs.template {
        config.model.template.clone_from(template);
    }
    for stage in &mut config.stages {
        match stage.attachment {
            AttachmentKind::Dice => {
                if let Some(image) = &inputs.image {
                    stage.image = Some(image.clone());
                    stage.label = inputs.label.or(stage.label);
                }
            }
            AttachmentKind::Ssd if stage.target.is_some() => {
                if let Some(target) = &inputs.target {
                    stage.target = Some(target.clone());
                }
            }
            AttachmentKind::Varifold => {
                if let Some(surface) = &inputs.surface {
                    stage.surface = Some(surface.clone());
                }
            }
            AttachmentKind::Ssd => {}
        }
    }
    Ok(config)
}

/// The automatic schedule of `--template` against the one target of `inputs`. The template is
/// first carried by an initial alignment: a similarity (which keeps it medial) by moments and
/// overlap onto an image (or a closed surface, rasterized) or by least squares onto
/// corresponding points, then an affine map the same way; none for an open surface. An affine map that is not a similarity
/// is applied and the template projected back onto its constraints. `out/aligned_template.vtk`
/// is the template the fit starts from, `out/alignment.txt` the map.
fn automatic(inputs: &Inputs, out: &Path) -> Result<Config, CliError> {
    let template_path = inputs
        .template
        .as_ref()
        .expect("clap requires --template without a config");
    match medial_io::model::read_model(template_path)? {
        Model::Medial(template) => automatic_medial(&template, template_path, inputs, out),
        Model::Plain(mesh) => automatic_plain(&mesh, template_path, inputs, out),
    }
}

/// The one target of an automatic fit, and its initial map of the template's boundary
/// `boundary` (see [`automatic`]); `spacing` rasterizes a closed surface.
fn target_and_alignment(
    boundary: &TriMesh,
    inputs: &Inputs,
    spacing: f64,
) -> Result<(Matrix4<f64>, Target), CliError> {
    match (&inputs.image, &inputs.target, &inputs.surface) {
        (Some(image), None, None) => {
            let volume = medial_io::volume::read_volume(image)?;
            let mask = volume.foreground(inputs.label);
            let target = Target::Image {
                path: image.clone(),
                label: inputs.label,
                voxel_mm: mask.spacing().min(),
                graded_signed: volume.is_graded_signed(),
            };
            drop(volume);
            Ok((align_to_image(boundary, &mask, image)?, target))
        }
        (None, Some(points), None) => {
            let q = medial_io::mesh::read_points(points)?;
            Ok((
                align_to_points(boundary, &q, points)?,
                Target::Points(points.clone()),
            ))
        }
        (None, None, Some(surface)) => {
            let mesh = medial_io::mesh::read_mesh(surface)?;
            let (width, fine_width) =
                varifold_widths(boundary, &mesh).map_err(|e| model_error(surface, e))?;
            let target = Target::Surface {
                path: surface.clone(),
                width,
                fine_width,
            };
            Ok((align_to_surface(boundary, &mesh, surface, spacing)?, target))
        }
        _ => Err(CliError::Input(
            "without a config, medial fit needs --template and one of --image, --target, \
             --surface"
                .into(),
        )),
    }
}

/// [`automatic`] for a medial template.
fn automatic_medial(
    template: &MedialTemplate,
    template_path: &Path,
    inputs: &Inputs,
    out: &Path,
) -> Result<Config, CliError> {
    let boundary = boundary_mesh(template).map_err(|e| model_error(template_path, e))?;
    let axes = PrincipalAxes::of(boundary.points()).map_err(|e| model_error(template_path, e))?;
    let geometry = Geometry::of(template, &boundary, &axes);
    // Voxels of half the mean spoke, so that the wall is a few voxels thick.
    let spacing = (geometry.mean_spoke_mm / 2.0).max(geometry.long_extent_mm / 256.0);
    let (alignment, target) = target_and_alignment(&boundary, inputs, spacing)?;
    let aligned = write_aligned(template, &alignment, out)?;
    Ok(geometry
        .plan()
        .automatic(aligned, &target, template.landmarks()))
}

/// [`automatic`] for a plain mesh: the whole initial map is applied (there are no constraints
/// to keep), then one unconstrained stage ([`crate::plan::automatic_plain`]).
fn automatic_plain(
    mesh: &TriMesh,
    template_path: &Path,
    inputs: &Inputs,
    out: &Path,
) -> Result<Config, CliError> {
    let dice_refused = || {
        CliError::Input(format!(
            "{} is a plain mesh: a Dice fit needs a medial template (a MedialIndex point \
             array); fit a plain mesh with --target or --surface",
            template_path.display()
        ))
    };
    if inputs.image.is_some() {
        return Err(dice_refused());
    }
    let axes = PrincipalAxes::of(mesh.points()).map_err(|e| model_error(template_path, e))?;
    let sigma = plain_sigma(mesh, &axes);
    let (alignment, target) = target_and_alignment(mesh, inputs, axes.extent.z / 128.0)?;
    create_dir(out)?;
    medial_io::affine::write_affine(&out.join(ALIGNMENT), &alignment)?;
    let aligned = aligned_template_path(out)?;
    vtk::write_trimesh(
        &aligned,
        &carry_mesh(mesh, &alignment)?,
        write_options(false),
    )?;
    crate::plan::automatic_plain(aligned, &target, sigma, mesh.points()).ok_or_else(dice_refused)
}

/// An initial map that is at most this far from a similarity ([`anisotropy`]) is taken as its
/// similarity alone: applying and projecting would move the template by less than the
/// projection's own tolerance can tell.
const AFFINE_ANISOTROPY: f64 = 0.01;

/// The similarity by moments and overlap, then the affine map by moments when it raises the
/// overlap and is more than [`AFFINE_ANISOTROPY`] from a similarity.
fn align_to_image(
    boundary: &TriMesh,
    mask: &Volume,
    image: &Path,
) -> Result<Matrix4<f64>, CliError> {
    let s = align_similarity(boundary, mask).map_err(|e| model_error(image, e))?;
    tracing::info!(
        "initial similarity: scale {:.4}, voxel Dice {:.3} → {:.3}",
        s.scale,
        s.voxel_dice_before,
        s.voxel_dice
    );
    let carried = carry_mesh(boundary, &s.matrix)?;
    let a = align_affine(&carried, mask).map_err(|e| model_error(image, e))?;
    if anisotropy(&a.matrix) <= AFFINE_ANISOTROPY {
        return Ok(s.matrix);
    }
    tracing::info!(
        "initial affine: anisotropy {:.1} %, voxel Dice {:.3} → {:.3}",
        100.0 * anisotropy(&(a.matrix * s.matrix)),
        a.voxel_dice_before,
        a.voxel_dice
    );
    Ok(a.matrix * s.matrix)
}

/// The least fraction of the target points' spread ([`explained_spread`]) that the
/// least-squares similarity must account for: below it the points are taken not to correspond
/// to the template boundary's, one for one.
const MIN_EXPLAINED_SPREAD: f64 = 0.5;

/// The least-squares similarity to the corresponding points, or the least-squares affine map
/// when it is more than [`AFFINE_ANISOTROPY`] from a similarity (and preserves orientation:
/// points that correspond poorly can call for a reflection). Points that the similarity
/// explains less than [`MIN_EXPLAINED_SPREAD`] of are refused: they do not correspond.
fn align_to_points(
    boundary: &TriMesh,
    q: &[Vec3],
    points: &Path,
) -> Result<Matrix4<f64>, CliError> {
    let bad = |e: medial_core::Error| CliError::Input(format!("{}: {e}", points.display()));
    let similarity = similarity_between(boundary.points(), q).map_err(bad)?;
    let by_similarity = carry_points(boundary.points(), &similarity);
    let explained = explained_spread(&by_similarity, q);
    if explained.is_nan() || explained < MIN_EXPLAINED_SPREAD {
        return Err(CliError::NoCorrespondence {
            path: points.to_path_buf(),
            explained,
            minimum: MIN_EXPLAINED_SPREAD,
        });
    }
    let rms = |moved: &[Vec3]| {
        let sum: f64 = moved
            .iter()
            .zip(q)
            .map(|(a, b)| (a - b).norm_squared())
            .sum();
        (sum / q.len() as f64).sqrt()
    };
    let rms_similarity = rms(&by_similarity);
    let affine = match affine_between(boundary.points(), q) {
        Ok(affine) => Some(affine).filter(|a| anisotropy(a) > AFFINE_ANISOTROPY),
        Err(e) => {
            tracing::warn!("no initial affine map, the similarity alone: {e}");
            None
        }
    };
    let Some(affine) = affine else {
        tracing::info!(
            "initial similarity: rms distance {rms_similarity:.3} mm, {:.1} % of the points' \
             spread explained",
            100.0 * explained
        );
        return Ok(similarity);
    };
    tracing::info!(
        "initial affine: anisotropy {:.1} %, rms distance {rms_similarity:.3} mm (similarity, \
         {:.1} % of the points' spread explained) → {:.3} mm",
        100.0 * anisotropy(&affine),
        100.0 * explained,
        rms(&carry_points(boundary.points(), &affine))
    );
    Ok(affine)
}

/// A closed surface is rasterized with voxels of `spacing` mm and aligned to as an image; an
/// open one gets no initial alignment.
fn align_to_surface(
    boundary: &TriMesh,
    mesh: &TriMesh,
    surface: &Path,
    spacing: f64,
) -> Result<Matrix4<f64>, CliError> {
    if let Err(defect) = check_closed_oriented_manifold(mesh).and_then(|_| check_outward(mesh)) {
        tracing::info!("no initial alignment: the surface is not a closed outward mesh ({defect})");
        return Ok(Matrix4::identity());
    }
    let (dims, grid) =
        grid_around(mesh, spacing, 2.0 * spacing).map_err(|e| model_error(surface, e))?;
    let mask = rasterize(mesh, dims, grid).map_err(|e| model_error(surface, e))?;
    align_to_image(boundary, &mask, surface)
}

/// `points` carried by the affine map `m`.
fn carry_points(points: &[Vec3], m: &Matrix4<f64>) -> Vec<Vec3> {
    points
        .iter()
        .map(|p| m.transform_point(&(*p).into()).coords)
        .collect()
}

/// `mesh` carried by the affine map `m`.
fn carry_mesh(mesh: &TriMesh, m: &Matrix4<f64>) -> Result<TriMesh, CliError> {
    Ok(TriMesh::new(
        carry_points(mesh.points(), m),
        mesh.triangles().to_vec(),
    )?)
}

/// Carries `template` by `alignment` and writes it as `out/aligned_template.vtk`, the map as
/// `out/alignment.txt`; returns the template's absolute path. A map that is not a similarity
/// breaks the medial constraints: the carried template is projected back onto them
/// ([`project`]); a projection that fails is an error naming the map. A template that is not
/// medial as given (an inflated sheet before its projection) is projected too, with a warning
/// when that fails.
fn write_aligned(
    template: &MedialTemplate,
    alignment: &Matrix4<f64>,
    out: &Path,
) -> Result<PathBuf, CliError> {
    create_dir(out)?;
    medial_io::affine::write_affine(&out.join(ALIGNMENT), alignment)?;
    let mut carried = template.with_landmarks(&carry_points(template.landmarks(), alignment))?;
    let options = ProjectOptions::default();
    let affine = anisotropy(alignment) > AFFINE_ANISOTROPY;
    let medial = ConstraintFigures::of(
        &carried,
        &MedialConstraints::new(&carried),
        carried.landmarks(),
    )
    .meets(&options);
    if affine || !medial {
        let why = if affine {
            "after the affine map"
        } else {
            "as given"
        };
        match project(&carried, &options) {
            Ok(projection) => {
                tracing::info!(
                    "template projected onto its constraints {why}: {:.3}° / {:.3} % → {:.3}° / \
                     {:.3} %, landmarks moved ≤ {:.3} mm (rms {:.3} mm)",
                    projection.before.max_spoke_normal_deg,
                    100.0 * projection.before.max_mismatch,
                    projection.after.max_spoke_normal_deg,
                    100.0 * projection.after.max_mismatch,
                    projection.max_displacement,
                    projection.rms_displacement
                );
                carried = projection.template;
            }
            Err(e) if affine => {
                return Err(CliError::Input(format!(
                    "the initial affine map (anisotropy {:.1} %) cannot be followed by a \
                     projection onto the medial constraints: {e}; give a config with an SSD \
                     stage instead",
                    100.0 * anisotropy(alignment)
                )))
            }
            Err(e) => tracing::warn!("the template is not medial and its projection failed: {e}"),
        }
    }
    let aligned = aligned_template_path(out)?;
    medial_io::cmrep::write_template(&aligned, &carried, write_options(false))?;
    Ok(aligned)
}

/// The initial map of an automatic fit, in its output folder.
const ALIGNMENT: &str = "alignment.txt";
/// The template an automatic fit starts from (the given one carried by [`ALIGNMENT`]), in its
/// output folder.
const ALIGNED_TEMPLATE: &str = "aligned_template.vtk";

/// The absolute path of [`ALIGNED_TEMPLATE`] in `out` (the resolved config names it so).
fn aligned_template_path(out: &Path) -> Result<PathBuf, CliError> {
    std::path::absolute(out.join(ALIGNED_TEMPLATE)).map_err(|e| CliError::io(out, e))
}

/// The files of an automatic fit's initial alignment, written into the output folder before
/// the fit because its config starts from them, belong to its set: copied into it, they are
/// listed in `summary.json` (and removed by a later set of another kind).
fn keep_alignment(set: &mut ResultSet, config: &Config, out: &Path) -> Result<(), CliError> {
    if config.model.template != aligned_template_path(out)? {
        return Ok(());
    }
    for name in [ALIGNMENT, ALIGNED_TEMPLATE] {
        let from = out.join(name);
        if from.exists() {
            std::fs::copy(&from, set.file(name)?).map_err(|e| CliError::io(&from, e))?;
        }
    }
    Ok(())
}

/// Options of `medial fit` beyond the config.
pub struct FitOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Worker threads in use.
    pub threads: usize,
    /// No progress display.
    pub quiet: bool,
    /// Write a checkpoint this often (wall-clock time) without stopping.
    pub checkpoint_every: Option<Duration>,
    /// Continue from the checkpoint in `out` instead of starting afresh.
    pub resume: bool,
}

/// The comment lines of the resolved `config.toml` a fit writes.
const RESOLVED_HEADER: &str = "# The config of this fit as it ran, every setting written out \
(paths absolute or as given).\n# `medial fit config.toml --out DIR` runs it again to the same \
bits.\n";

/// Runs `config` (or, with [`FitOptions::resume`], continues it from the checkpoint in
/// `options.out`) and writes its results into `options.out` as one set ([`ResultSet`]). A fit
/// that ends at an unsound iterate, or with its constraints above their tolerance, writes its
/// results (marked in `summary.json`'s `status`) and then returns the error that says so; so
/// does a fit stopped by SIGINT or SIGTERM, which also writes its checkpoint.
pub fn run(config: &Config, options: &FitOptions) -> Result<Summary, CliError> {
    let model = medial_io::model::read_model(&config.model.template)?;
    // Constrained and Dice stages rely on the medial points staying inside (Dice samples the
    // prisms); the others only on the boundary surface.
    let (prisms, surface) = (Guard::new(&model), Guard::of_surface(&model));
    let flow = flow_of(config, model.landmarks().len())?;
    let prepared = config
        .stages
        .iter()
        .map(|s| stage::prepare(s, &model))
        .collect::<Result<Vec<_>, _>>()?;
    let resolved = stage::with_choices(config, &prepared);
    let config = &resolved;
    let planned: Vec<PlannedStage<'_>> = prepared
        .iter()
        .map(|p| PlannedStage {
            stage: Stage {
                flow: &flow,
                initial: model.landmarks(),
                attachment: p.attachment.as_ref(),
                data_weight: p.data_weight,
                constraints: p.constraints.as_ref().map(|c| c as &dyn ConstraintSet),
                guard: Some(if p.constraints.is_some() || p.mask.is_some() {
                    &prisms
                } else {
                    &surface
                }),
            },
            schedule: p.schedule,
            lbfgs: p.lbfgs,
        })
        .collect();
    let fit = Fit {
        config,
        options,
        model: &model,
        flow: &flow,
        prepared: &prepared,
        planned: &planned,
    };
    let (resumed, fingerprint) = if options.resume {
        let fingerprint = Fingerprint::of(config)?;
        let path = options.out.join(checkpoint::FILE);
        (
            Some(Saved::read_for(&path, &fingerprint)?),
            Some(fingerprint),
        )
    } else {
        (None, None)
    };
    let mut set = ResultSet::begin(&options.out)?;
    keep_alignment(&mut set, config, &options.out)?;
    write_text(&set.file("config.toml")?, &config.to_toml(RESOLVED_HEADER)?)?;
    let ended = fit.optimise(resumed, fingerprint)?;
    fit.write_set(set, ended)
}

/// What a fit runs: its config and options, the model and its flow, the prepared stages and
/// the plan the engine runs.
struct Fit<'a> {
    config: &'a Config,
    options: &'a FitOptions,
    model: &'a Model,
    flow: &'a Flow,
    prepared: &'a [Prepared],
    planned: &'a [PlannedStage<'a>],
}

/// How the optimisation of a fit ended.
struct Ended {
    /// The outcome of every stage run (of an interrupted fit: the one in progress as it stood).
    outcomes: Vec<StageOutcome>,
    /// Wall-clock seconds of each of them.
    stage_seconds: Vec<f64>,
    /// Wall-clock seconds of the fit.
    seconds: f64,
    log: Log,
    /// The signal that stopped the fit, and its checkpoint.
    interrupted: Option<(Signal, Saved)>,
}

/// Wall-clock seconds since a start, after `before` seconds of earlier runs.
struct Clock {
    start: Instant,
    before: f64,
}

impl Clock {
    fn new(before: f64) -> Self {
        Self {
            start: Instant::now(),
            before,
        }
    }

    fn seconds(&self) -> f64 {
        self.before + self.start.elapsed().as_secs_f64()
    }
}

/// A fit as it runs: its log, its progress display and its clocks.
struct Watch {
    log: Log,
    progress: Progress,
    /// The fit.
    clock: Clock,
    /// The stage in progress.
    stage_clock: Clock,
    /// Seconds of each stage that ended.
    stage_seconds: Vec<f64>,
    /// The first failure to write the log.
    error: Option<CliError>,
}

impl Watch {
    /// Logs and shows an iteration; shows the end of a stage.
    fn event(&mut self, fit: &Fit<'_>, event: FitEvent<'_>) {
        match event {
            FitEvent::Iteration { stage, progress: p } => {
                let (name, prepared) = (&fit.config.stages[stage].name, &fit.prepared[stage]);
                let e = p.report.evaluation;
                let figures = prepared.figures_at(fit.model, e, &e.final_positions);
                let row = LogRow {
                    stage: name,
                    al_iteration: p.al_iteration,
                    iteration: p.report.iteration,
                    evaluations: p.report.evaluations,
                    mu: p.mu,
                    figures: &figures,
                    grad_norm: p.report.gradient_norm,
                    seconds: self.clock.seconds(),
                    time_steps: p.time_steps,
                };
                self.progress.update(&row);
                if let Err(e) = self.log.row(&row) {
                    self.error.get_or_insert(e);
                }
            }
            FitEvent::StageEnd { stage, outcome } => {
                let seconds = self.stage_clock.seconds();
                let line = stage_line(&fit.config.stages[stage].name, outcome, seconds);
                self.progress.println(&line);
                self.stage_seconds.push(seconds);
                self.stage_clock = Clock::new(0.0);
            }
        }
    }

    /// The checkpoint file of the engine's `checkpoint`.
    fn saved(&self, fingerprint: Fingerprint, checkpoint: Checkpoint) -> Saved {
        let mut stage_seconds = self.stage_seconds.clone();
        stage_seconds.push(self.stage_clock.seconds());
        let log = self.log.text().to_owned();
        Saved::new(
            fingerprint,
            log,
            self.clock.seconds(),
            stage_seconds,
            checkpoint,
        )
    }

    /// The end of the optimisation with `outcomes`.
    fn ended(self, outcomes: Vec<StageOutcome>, interrupted: Option<(Signal, Saved)>) -> Ended {
        self.progress.finish();
        let stage_seconds = match &interrupted {
            Some((_, saved)) => saved.stage_seconds.clone(),
            None => self.stage_seconds,
        };
        Ended {
            outcomes,
            stage_seconds,
            seconds: self.clock.seconds(),
            log: self.log,
            interrupted,
        }
    }
}

impl Fit<'_> {
    /// Runs the plan, from the start or from `resumed`, until it ends or a signal stops it;
    /// writes a checkpoint every [`FitOptions::checkpoint_every`] on the way. `fingerprint`
    /// is the config's, when already known.
    fn optimise(
        &self,
        resumed: Option<Saved>,
        mut fingerprint: Option<Fingerprint>,
    ) -> Result<Ended, CliError> {
        let out = &self.options.out;
        let (log, seconds, mut stage_seconds, mut from) = match resumed {
            Some(s) => (s.log, s.seconds, s.stage_seconds, Some(s.fit)),
            None => (String::new(), 0.0, Vec::new(), None),
        };
        let progress = Progress::new(self.options.quiet);
        if let Some(c) = &from {
            progress.println(&format!(
                "resuming stage '{}', AL iteration {}, iteration {} from {}",
                self.config.stages[c.stage()].name,
                c.al_iteration(),
                c.iteration(),
                out.join(checkpoint::FILE).display()
            ));
        }
        let stage_so_far = stage_seconds.pop().unwrap_or(0.0);
        let mut watch = Watch {
            log: Log::create(&out.join("log.csv"), &log)?,
            progress,
            clock: Clock::new(seconds),
            stage_clock: Clock::new(stage_so_far),
            stage_seconds,
            error: None,
        };
        let signals = Signals::catch()?;
        loop {
            let since = Instant::now();
            let pause = || {
                signals.received().is_some()
                    || (self.options.checkpoint_every).is_some_and(|every| since.elapsed() >= every)
            };
            let run = run_stages_resumable(self.planned, from.take(), &pause, |event| {
                watch.event(self, event)
            })?;
            if let Some(e) = watch.error.take() {
                return Err(e);
            }
            let checkpoint = match run {
                FitRun::Complete(outcomes) => return Ok(watch.ended(outcomes, None)),
                FitRun::Paused(checkpoint) => *checkpoint,
            };
            let fingerprint = match &fingerprint {
                Some(f) => f.clone(),
                None => fingerprint.insert(Fingerprint::of(self.config)?).clone(),
            };
            let saved = watch.saved(fingerprint, checkpoint);
            if let Some(signal) = signals.received() {
                return Ok(watch.ended(saved.fit.outcomes(), Some((signal, saved))));
            }
            saved.write(&out.join(checkpoint::FILE))?;
            from = Some(saved.fit);
        }
    }

    /// Writes the results of `ended` as one set and moves it into the result folder; returns
    /// the summary, or the error of a fit that did not end sound and within its tolerances.
    fn write_set(&self, mut set: ResultSet, ended: Ended) -> Result<Summary, CliError> {
        let Ended {
            outcomes,
            stage_seconds,
            seconds,
            log,
            interrupted,
        } = ended;
        let mut stages = self.stage_summaries(&outcomes, stage_seconds)?;
        let momenta = &outcomes.last().expect("a config has a stage").momenta;
        let trajectory = self.flow.shoot(self.model.landmarks(), momenta)?;
        let points = time_points(self.model, &trajectory);
        let strains = self.flow.step_strains(&trajectory, momenta)?;
        warn_of_strain(&strains);
        write_results(
            self.config,
            &mut set,
            self.model,
            self.flow,
            momenta,
            &trajectory,
            &points,
        )?;
        if let Some(lambda) = outcomes.iter().rev().find(|o| !o.lambda.is_empty()) {
            let per_time_point = lambda.lambda.len() / self.flow.time_steps();
            medial_io::npy::write_npy(
                &set.file("lambda.npy")?,
                &[self.flow.time_steps(), per_time_point],
                &lambda.lambda,
            )?;
        }
        if !points.is_empty() {
            time_points::write_csv(&set.file("time_points.csv")?, &points)?;
        }
        let last = stages.len() - 1;
        let (status, failure) = match &interrupted {
            Some((signal, saved)) => {
                saved.write(&set.file(checkpoint::FILE)?)?;
                let error =
                    interrupted_error(*signal, &saved.fit, &stages[last].name, &self.options.out);
                (Status::Interrupted, Some(error))
            }
            None => {
                set.retire(checkpoint::FILE);
                let (planned, cfg) = (&self.planned[last], &self.config.stages[last]);
                judge_flow(&mut stages[last], planned, cfg, &trajectory, &points);
                let status = status_of(&stages[last]);
                (
                    status,
                    failure(status, &stages[last], cfg, &self.options.out),
                )
            }
        };
        let mut summary = self.summary(status, seconds, stages, &points, strains);
        log.finish(&mut set)?;
        // The views are made from the set's own files (as `medial report` makes them from a
        // fit folder's), in the staging folder with a draft of the summary, and belong to the set.
        write_json(&set.staging().join("summary.json"), &summary)?;
        for view in crate::report::write(set.staging(), &self.options.out)? {
            set.include(&view);
        }
        set.commit("summary.json", |path, files| {
            summary.files = files;
            write_json(path, &summary)
        })?;
        match failure {
            Some(e) => Err(e),
            None => Ok(summary),
        }
    }

    /// The summary of every stage run, from its outcome and seconds.
    fn stage_summaries(
        &self,
        outcomes: &[StageOutcome],
        seconds: Vec<f64>,
    ) -> Result<Vec<StageSummary>, CliError> {
        self.config
            .stages
            .iter()
            .zip(self.prepared)
            .zip(outcomes.iter().zip(seconds))
            .map(|((cfg, p), (outcome, seconds))| {
                let figures = p.end_figures(self.model, &outcome.evaluation)?;
                Ok(stage_summary(
                    cfg,
                    p.constraints.is_some(),
                    outcome,
                    seconds,
                    figures,
                ))
            })
            .collect()
    }

    /// `summary.json` of a fit that ended `status` (its `files` are the set's, filled in when
    /// it is committed).
    fn summary(
        &self,
        status: Status,
        seconds: f64,
        stages: Vec<StageSummary>,
        points: &[time_points::TimePoint],
        step_strains: Vec<f64>,
    ) -> Summary {
        let model = self.model;
        Summary {
            version: env!("CARGO_PKG_VERSION"),
            status,
            landmarks: model.landmarks().len(),
            boundary_points: model.boundary_count(),
            medial_atoms: model.medial_count(),
            constraints_per_time_point: model
                .medial()
                .map_or(0, |t| MedialConstraints::new(t).len()),
            time_steps: self.flow.time_steps(),
            sigma: self.flow.kernel().sigma(),
            threads: self.options.threads,
            seconds,
            evaluations: stages.iter().map(|s| s.evaluations).sum(),
            final_figures: stages.last().expect("a config has a stage").figures.clone(),
            over_time: time_points::over_time(points),
            step_strains,
            stages,
            files: Vec::new(),
        }
    }
}

/// A warning when a step of the fitted flow strains space past [`STRAIN_LIMIT`].
fn warn_of_strain(strains: &[f64]) {
    let Some((n, &worst)) = (strains.iter().enumerate())
        .max_by(|a, b| a.1.total_cmp(b.1))
        .filter(|(_, s)| s.is_nan() || **s > STRAIN_LIMIT)
    else {
        return;
    };
    tracing::warn!(
        "step {n} of the fitted flow strains space by dt·|∇v| = {worst:.2} (above \
         {STRAIN_LIMIT}; 1 or more can fold space between the landmarks): raise [flow] \
         time_steps"
    );
}

/// How a fit whose last stage run is `last` ended (not interrupted).
fn status_of(last: &StageSummary) -> Status {
    if last.unsound.is_some() {
        Status::Unsound
    } else if last.constraints_met == Some(false) {
        Status::ConstraintsNotMet
    } else if last.converged {
        Status::Converged
    } else {
        Status::Budget
    }
}

/// The error of a fit that `signal` stopped at `checkpoint`, in the stage `stage`, its results
/// and checkpoint written to `out`.
fn interrupted_error(signal: Signal, checkpoint: &Checkpoint, stage: &str, out: &Path) -> CliError {
    CliError::Interrupted {
        signal,
        message: format!(
            "interrupted by {} in stage '{stage}', AL iteration {}, iteration {}: the checkpoint \
             and the results of that iterate are in {} (status \"interrupted\"); `medial fit \
             --resume {}` continues the fit",
            signal.name(),
            checkpoint.al_iteration(),
            checkpoint.iteration(),
            out.display(),
            out.display()
        ),
    }
}

/// The summary of a stage that ran.
fn stage_summary(
    cfg: &StageConfig,
    constrained: bool,
    outcome: &StageOutcome,
    seconds: f64,
    figures: Figures,
) -> StageSummary {
    let constraints_met = constrained.then(|| {
        figures
            .max_spoke_normal_deg
            .zip(figures.max_spoke_mismatch_pct)
            .is_some_and(|(deg, pct)| deg <= cfg.tolerance_deg && pct <= cfg.tolerance_pct)
    });
    StageSummary {
        name: cfg.name.clone(),
        seconds,
        evaluations: outcome.evaluations,
        iterations: outcome.iterations,
        al_iterations: outcome.al_iterations,
        mu: outcome.mu,
        stop: outcome.stops.iter().map(|s| s.to_string()).collect(),
        converged: outcome.converged(),
        settled: outcome.settled,
        restarts: outcome.restarts,
        coarse_al_iterations: outcome.coarse_al_iterations,
        strained_iterations: outcome.strained_iterations,
        constraints_met,
        unsound: outcome.unsound.as_ref().map(|u| {
            format!(
                "AL iteration {}, iteration {}: {}",
                u.al_iteration, u.iteration, u.cause
            )
        }),
        figures,
    }
}

/// Judges the whole fitted flow, not only its end, for the last stage `last`: a fold at any
/// time point makes it unsound, and a constrained stage meets its tolerances only if the worst
/// spoke figures over time points 1 … N do.
fn judge_flow(
    last: &mut StageSummary,
    planned: &PlannedStage<'_>,
    cfg: &StageConfig,
    trajectory: &Trajectory,
    points: &[time_points::TimePoint],
) {
    if last.unsound.is_none() {
        let guard = planned
            .stage
            .guard
            .expect("the fit gives every stage a guard");
        last.unsound = (1..trajectory.time_points()).find_map(|n| {
            let cause = guard.check_fold(trajectory.positions(n)).err()?;
            Some(format!("time point {n} of the fitted flow: {cause}"))
        });
    }
    if let (Some(true), Some(worst)) = (last.constraints_met, time_points::over_time(points)) {
        last.constraints_met = Some(
            worst.max_spoke_normal_deg <= cfg.tolerance_deg
                && worst.max_spoke_mismatch_pct <= cfg.tolerance_pct,
        );
    }
}

/// The error a fit that ended `status` returns once its results are written (none for a
/// sound fit within its tolerances).
fn failure(status: Status, last: &StageSummary, cfg: &StageConfig, out: &Path) -> Option<CliError> {
    let written = format!("results written to {} (status \"", out.display());
    match status {
        Status::Unsound => Some(CliError::Unsound(format!(
            "stage '{}', {}; {written}unsound\", the last sound iterate)",
            last.name,
            last.unsound.as_deref().unwrap_or_default()
        ))),
        Status::ConstraintsNotMet => Some(CliError::ConstraintsNotMet(format!(
            "stage '{}': the medial constraints are not met (max spoke–normal {:.3}°, max \
             mismatch {:.3} %; tolerance {}°, {} %): raise mu, mu_factor or al_iterations; \
             {written}constraints_not_met\")",
            last.name,
            last.figures.max_spoke_normal_deg.unwrap_or(f64::NAN),
            last.figures.max_spoke_mismatch_pct.unwrap_or(f64::NAN),
            cfg.tolerance_deg,
            cfg.tolerance_pct,
        ))),
        Status::Converged | Status::Budget | Status::Interrupted => None,
    }
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

/// `momenta.npy`, the model at every time point under `flow/` (the medial sheet with the
/// fidelity of `points`, the figures at every time point of a medial template), the per-atom
/// table of a medial template ([`crate::atoms`]) and the fitted model, into `set`.
fn write_results(
    config: &Config,
    set: &mut ResultSet,
    model: &Model,
    flow: &Flow,
    momenta: &[f64],
    trajectory: &Trajectory,
    points: &[time_points::TimePoint],
) -> Result<(), CliError> {
    let k = model.landmarks().len();
    medial_io::npy::write_npy(
        &set.file("momenta.npy")?,
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
            &set.file(&format!("flow/boundary_t{n:03}.vtk"))?,
            &boundary_polydata(model, q),
            vtk_options,
        )?;
        let medial = points
            .get(n)
            .and_then(|p| medial_polydata(model, q, &p.fidelity));
        if let Some(medial) = medial {
            vtk::write_polydata(
                &set.file(&format!("flow/medial_t{n:03}.vtk"))?,
                &medial,
                vtk_options,
            )?;
        }
    }
    let q = trajectory.final_positions();
    if let (Some(t), Some(end)) = (model.medial(), points.last()) {
        crate::atoms::write(set, t, trajectory.positions(0), q, &end.fidelity)?;
    }
    let fitted = set.file("fitted_template.vtk")?;
    match model.medial() {
        Some(t) => medial_io::cmrep::write_template(&fitted, &t.with_landmarks(q)?, vtk_options)?,
        None => vtk::write_polydata(&fitted, &boundary_polydata(model, q), vtk_options)?,
    }
    Ok(())
}
