//! A fit run and written: the config resolved from a file or chosen by the engine
//! ([`resolve`]), its stages run by the engine ([`run_stages_resumable`]) with pauses for
//! checkpoints and signals, and its results written as one set ([`run`]). `medial fit` runs
//! one; `medial batch` one per subject.

use crate::checkpoint::{self, Fingerprint, Saved};
use crate::config::{AttachmentKind, Config, Source, StageConfig};
use crate::error::CliError;
use crate::output::model_error;
use crate::output::{write_json, write_options, write_text};
use crate::progress::{Log, LogRow, Progress};
use crate::results::ResultSet;
use crate::signals::{Signal, Signals};
use crate::stage::{self, flow_of};
use crate::summary::{Figures, StageSummary, Status, Summary};
use crate::time_points::{self, time_points};
use medial_core::fit::agreement::Miss;
use medial_core::fit::plan;
use medial_core::fit::{
    run_stages_resumable, Checkpoint, FitEvent, FitRun, PlannedStage, PreparedStage, StageOutcome,
    Target,
};
use medial_core::flow::{Flow, Trajectory, STRAIN_LIMIT};
use medial_core::model::Model;
use medial_io::model::{boundary_polydata, medial_polydata};
use medial_io::vtk;
use nalgebra::Matrix4;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The inputs of `medial fit` given as flags: without a config they choose an automatic
/// schedule ([`medial_core::fit::plan::automatic`]); with one they replace its template and
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

/// A fit ready to run: its config as `config.toml` names it, and for an automatic fit the
/// template it starts from, carried by its initial alignment, in memory.
pub struct Resolved {
    /// The config (an automatic fit's names its aligned template in the output folder).
    pub config: Config,
    /// An automatic fit's start; `None`: the config's template, read from its file.
    pub start: Option<Start>,
}

/// Where an automatic fit starts: the template carried by its initial map (written into the
/// fit's results as `aligned_template.vtk` and `alignment.txt`).
pub struct Start {
    /// The aligned template.
    pub model: Model,
    /// The initial map, template → subject.
    pub alignment: Matrix4<f64>,
    /// The template as given (written as `template.vtk`, so that `medial apply` can carry the
    /// given template's space by the alignment and the moves after it).
    pub given: Model,
    /// What the initial alignment did, one line per step (in summary.json as `alignment`).
    pub notes: Vec<String>,
    /// The trials that chose the start (in summary.json as `start_trials`).
    pub trials: Vec<medial_core::fit::trial::StartTrial>,
    /// The other starts, best first: the fit runs again from the next where it misses its
    /// target ([`run`]).
    pub others: Vec<medial_core::fit::trial::Candidate>,
    /// The stage the trials prepared against the fit's one target: its image is not read and
    /// smoothed again ([`stage::prepare_all`]).
    pub prepared: Option<PreparedStage>,
}

/// The config of a fit: `config` with the flags of `inputs` in place of its template and
/// targets, or without one the automatic schedule of `inputs`.
pub fn resolve(config: Option<&Path>, inputs: &Inputs, out: &Path) -> Result<Resolved, CliError> {
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
    Ok(Resolved {
        config,
        start: None,
    })
}

/// The automatic fit of `--template` against the one target of `inputs`: the engine's plan and
/// initial alignment ([`medial_core::fit::run::automatic`]); the config names the aligned
/// template as `out/aligned_template.vtk`, which the fit writes.
fn automatic(inputs: &Inputs, out: &Path) -> Result<Resolved, CliError> {
    let template_path = inputs
        .template
        .as_ref()
        .expect("clap requires --template without a config");
    let model = medial_io::model::read_model(template_path)?;
    let (target, source) = read_automatic_target(inputs, &model, template_path)?;
    let start =
        medial_core::fit::run::automatic(&model, &target, crate::memory::limit()).map_err(|e| {
            match e {
                medial_core::Error::NoCorrespondence { explained, minimum } => {
                    CliError::NoCorrespondence {
                        path: source_path(&source).to_path_buf(),
                        explained,
                        minimum,
                    }
                }
                e @ medial_core::Error::Memory { .. } => CliError::from(e),
                e => model_error(source_path(&source), e),
            }
        })?;
    for note in &start.notes {
        tracing::info!("{note}");
    }
    let template =
        std::path::absolute(out.join(ALIGNED_TEMPLATE)).map_err(|e| CliError::io(out, e))?;
    let sources = vec![source; start.spec.stages.len()];
    Ok(Resolved {
        config: Config::of_spec(&start.spec, template, sources),
        start: Some(Start {
            model: start.model,
            alignment: start.alignment,
            given: model,
            notes: start.notes,
            trials: start.trials,
            others: start.others,
            prepared: start.prepared,
        }),
    })
}

/// The one target of an automatic fit, read, and its file as a stage's source.
fn read_automatic_target(
    inputs: &Inputs,
    model: &Model,
    template_path: &Path,
) -> Result<(Target, Source), CliError> {
    match (&inputs.image, &inputs.target, &inputs.surface) {
        (Some(image), None, None) => {
            if model.medial().is_none() {
                return Err(CliError::Input(format!(
                    "{} is a plain mesh: a Dice fit needs a medial template (a MedialIndex point \
                     array); fit a plain mesh with --target or --surface",
                    template_path.display()
                )));
            }
            let volume = medial_io::volume::read_volume(image)?;
            Ok((
                Target::Image {
                    volume,
                    label: inputs.label,
                },
                Source::Image(image.clone(), inputs.label),
            ))
        }
        (None, Some(points), None) => Ok((
            Target::Points(medial_io::mesh::read_points(points)?),
            Source::Target(points.clone()),
        )),
        (None, None, Some(surface)) => Ok((
            Target::Surface(medial_io::mesh::read_mesh(surface)?),
            Source::Surface(surface.clone()),
        )),
        _ => Err(CliError::Input(
            "without a config, medial fit needs --template and one of --image, --target, \
             --surface"
                .into(),
        )),
    }
}

/// The file of a stage's source.
fn source_path(source: &Source) -> &Path {
    match source {
        Source::Target(p) | Source::Transform(p) | Source::Image(p, _) | Source::Surface(p) => p,
    }
}

/// The initial map of an automatic fit, in its output folder.
const ALIGNMENT: &str = "alignment.txt";
/// The template an automatic fit starts from (the given one carried by [`ALIGNMENT`]), in its
/// output folder.
const ALIGNED_TEMPLATE: &str = "aligned_template.vtk";
/// The template an automatic fit was given, as read (`medial apply` carries its space).
const GIVEN_TEMPLATE: &str = "template.vtk";

/// An automatic fit's start belongs to its set: the template it started from (`start`, the
/// bytes of [`Taken::bytes`]), the initial map and the template as given.
fn write_start(
    set: &mut ResultSet,
    start: &Taken,
    alignment: Matrix4<f64>,
    given: &Model,
) -> Result<(), CliError> {
    medial_io::affine::write_affine(&set.file(ALIGNMENT)?, &alignment)?;
    for (name, model) in [(ALIGNED_TEMPLATE, &start.model), (GIVEN_TEMPLATE, given)] {
        let data = medial_io::model::model_polydata(model);
        vtk::write_polydata(&set.file(name)?, &data, write_options(false))?;
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
///
/// An automatic fit recovers before it reports a failure: one that ends unsound runs again from
/// its start with safer settings ([`plan::safer`]); one that misses a part of its target
/// ([`medial_core::fit::agreement`]) runs again from the next start its trials ranked
/// ([`medial_core::fit::trial::Choice::others`]), and where none meets the target the run that
/// missed least is written. `summary.json`'s `retries` says what ran again and why.
pub fn run(resolved: &Resolved, options: &FitOptions) -> Result<Summary, CliError> {
    let mut start = match &resolved.start {
        Some(start) => Taken {
            model: start.model.clone(),
            alignment: Some(start.alignment),
        },
        None => Taken {
            model: medial_io::model::read_model(&resolved.config.model.template)?,
            alignment: None,
        },
    };
    let mut next_starts = resolved.start.iter().flat_map(|s| &s.others);
    let mut config = resolved.config.clone();
    let mut retries = Vec::new();
    // Runs with safer settings from the start in use.
    let mut safer_runs = 0;
    // The run of an automatic fit that missed its target least, while others are tried.
    let mut least_missed: Option<(f64, Run, Ended)> = None;
    // The result set, begun before the first run writes its log (after its inputs were read).
    let mut set = None;
    // Stages prepared before, with their sources: the trials' first stage for the first run,
    // each run's stages for the retry after it.
    let mut earlier = match &resolved.start {
        Some(start) => stage::by_source(&config, start.prepared.as_slice()),
        None => Vec::new(),
    };
    loop {
        let flow = flow_of(&config, start.model.landmarks().len())?;
        let prepared = stage::prepare_all(&config, &start.model, &earlier)?;
        earlier = stage::by_source(&config, &prepared);
        let run = Run {
            config: stage::with_choices(&config, &prepared),
            engine: medial_core::fit::run::Fit::new(start.model.clone(), flow, prepared),
            start,
        };
        // Whether an automatic fit runs again (a fit from a config runs as it was written).
        let automatic = resolved.start.is_some() && !options.resume;
        let (ended, miss) = run.with_fit(resolved, options, &retries, |fit| {
            let fingerprint = match options.resume {
                true => Some(fit.fingerprint()?),
                false => None,
            };
            let resumed = match &fingerprint {
                Some(f) => Some(Saved::read_for(&options.out.join(checkpoint::FILE), f)?),
                None => None,
            };
            if set.is_none() {
                set = Some(ResultSet::begin(&options.out)?);
            }
            let ended = fit.optimise(resumed, fingerprint)?;
            // Judged again when the set is written; here only where it decides a retry.
            let miss = match automatic {
                true => fit.miss(&ended)?,
                false => None,
            };
            Ok((ended, miss))
        })?;
        let unsound = ended.unsound_cause();
        let safer = match &unsound {
            Some(cause) if automatic => plan::safer(
                &run.config.spec(),
                run.start.model.landmarks(),
                safer_runs + 1,
            )
            .map(|safer| (cause, safer)),
            _ => None,
        };
        if let Some((cause, safer)) = safer {
            let line = format!("the fit ended unsound ({cause}); {}", safer.why);
            tracing::info!("{line}");
            retries.push(line);
            safer_runs += 1;
            config = run.config.with_spec(&safer.spec)?;
            start = run.start;
            continue;
        }
        // A run from another start that ends unsound counts as missing everything: the earlier
        // run that missed part of the target is kept over it.
        let failed = match (&miss, unsound) {
            (Some(miss), _) => (miss.share, format!("misses its target ({miss})")),
            (None, Some(cause)) if least_missed.is_some() => {
                (f64::INFINITY, format!("ended unsound ({cause})"))
            }
            _ => return run.write(ended, set, resolved, options, &retries),
        };
        let kept = match least_missed.take() {
            Some(kept) if kept.0 <= failed.0 => kept,
            _ => (failed.0, run, ended),
        };
        let Some(next) = next_starts.next() else {
            let (_, run, ended) = kept;
            return run.write(ended, set, resolved, options, &retries);
        };
        let line = format!(
            "the fit {}; runs again from the start {}, the next by its trial",
            failed.1, next.name
        );
        tracing::info!("{line}");
        retries.push(line);
        least_missed = Some(kept);
        start = Taken {
            model: next.model.clone(),
            alignment: Some(next.alignment),
        };
        config = resolved.config.clone();
        safer_runs = 0;
    }
}

/// The start a run of a fit took: its model, and an automatic fit's initial map (template →
/// subject).
struct Taken {
    model: Model,
    alignment: Option<Matrix4<f64>>,
}

impl Taken {
    /// The start's bytes as its set writes them (`aligned_template.vtk`, [`write_start`]).
    fn bytes(&self) -> Vec<u8> {
        let data = medial_io::model::model_polydata(&self.model);
        vtk::polydata_to_bytes(&data, write_options(false))
    }
}

/// One run of a fit: its config with the choices its stages made, the engine and its start.
struct Run {
    config: Config,
    engine: medial_core::fit::run::Fit,
    start: Taken,
}

impl Run {
    /// `f` of the [`Fit`] of this run.
    fn with_fit<R>(
        &self,
        resolved: &Resolved,
        options: &FitOptions,
        retries: &[String],
        f: impl FnOnce(&Fit<'_>) -> Result<R, CliError>,
    ) -> Result<R, CliError> {
        let planned = self.engine.planned();
        let start = resolved.start.as_ref();
        f(&Fit {
            config: &self.config,
            options,
            model: self.engine.model(),
            flow: self.engine.flow(),
            prepared: self.engine.stages(),
            planned: &planned,
            start: self.start.alignment.map(|_| &self.start),
            alignment: start.map_or(&[], |s| &s.notes),
            start_trials: start.map_or(&[], |s| &s.trials),
            retries,
        })
    }

    /// Writes this run's results, as it `ended`, as the fit's set, begun as `set` (an
    /// automatic fit's start with them).
    fn write(
        self,
        ended: Ended,
        set: Option<ResultSet>,
        resolved: &Resolved,
        options: &FitOptions,
        retries: &[String],
    ) -> Result<Summary, CliError> {
        let mut set = set.expect("begun before the first run");
        if let (Some(given), Some(alignment)) = (&resolved.start, self.start.alignment) {
            write_start(&mut set, &self.start, alignment, &given.given)?;
        }
        write_text(
            &set.file("config.toml")?,
            &self.config.to_toml(RESOLVED_HEADER)?,
        )?;
        self.with_fit(resolved, options, retries, |fit| fit.write_set(set, ended))
    }
}

/// What a fit runs: its config and options, the model and its flow, the prepared stages and
/// the plan the engine runs.
struct Fit<'a> {
    config: &'a Config,
    options: &'a FitOptions,
    model: &'a Model,
    flow: &'a Flow,
    prepared: &'a [PreparedStage],
    planned: &'a [PlannedStage<'a>],
    /// An automatic fit's start for this run (its set writes it at the end).
    start: Option<&'a Taken>,
    /// An automatic fit's alignment notes ([`Start::notes`]).
    alignment: &'a [String],
    /// An automatic fit's start trials ([`Start::trials`]).
    start_trials: &'a [medial_core::fit::trial::StartTrial],
    /// The runs of an automatic fit that ended unsound before this one, and why it ran again.
    retries: &'a [String],
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

impl Ended {
    /// Why the fit ended unsound, when it ran to its end and did.
    fn unsound_cause(&self) -> Option<String> {
        if self.interrupted.is_some() {
            return None;
        }
        let last = self.outcomes.last()?;
        last.unsound.as_ref().map(|u| u.cause.to_string())
    }
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
                let figures = stage::figures_at(prepared, fit.model, e, &e.final_positions);
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
                None => fingerprint.insert(self.fingerprint()?).clone(),
            };
            let saved = watch.saved(fingerprint, checkpoint);
            if let Some(signal) = signals.received() {
                return Ok(watch.ended(saved.fit.outcomes(), Some((signal, saved))));
            }
            saved.write(&out.join(checkpoint::FILE))?;
            from = Some(saved.fit);
        }
    }

    /// The fingerprint of this fit's checkpoints: its config's, where an automatic fit's start
    /// is the template in memory (its file is written with the set, at the end).
    fn fingerprint(&self) -> Result<Fingerprint, CliError> {
        Fingerprint::of(self.config, self.start.map(Taken::bytes).as_deref())
    }

    /// The part of its target the fit missed (at the end of its last stage), where it ran to its
    /// end, sound, and missed one ([`stage::end_figures`]).
    fn miss(&self, ended: &Ended) -> Result<Option<Miss>, CliError> {
        let last = match (&ended.interrupted, ended.outcomes.last()) {
            (None, Some(last)) if last.unsound.is_none() => last,
            _ => return Ok(None),
        };
        let stage = &self.prepared[ended.outcomes.len() - 1];
        let sigma = self.flow.kernel().sigma();
        Ok(stage::end_figures(stage, self.model, &last.evaluation, sigma)?.1)
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
                    failure(
                        status,
                        &stages[last],
                        cfg,
                        &self.options.out,
                        self.retries.len(),
                        time_points::over_time(&points),
                    ),
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
        set.commit("summary.json", |path, listing| {
            summary.files = listing.files;
            summary.sha256 = listing.sha256;
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
        let sigma = self.flow.kernel().sigma();
        self.config
            .stages
            .iter()
            .zip(self.prepared)
            .zip(outcomes.iter().zip(seconds))
            .map(|((cfg, p), (outcome, seconds))| {
                let (figures, miss) =
                    stage::end_figures(p, self.model, &outcome.evaluation, sigma)?;
                Ok(StageSummary {
                    misses: miss.map(|m| m.to_string()),
                    ..stage_summary(cfg, p.constraints.is_some(), outcome, seconds, figures)
                })
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
                .map_or(0, |t| medial_core::model::MedialConstraints::new(t).len()),
            time_steps: self.flow.time_steps(),
            sigma: self.flow.kernel().sigma(),
            threads: self.options.threads,
            seconds,
            evaluations: stages.iter().map(|s| s.evaluations).sum(),
            final_figures: stages.last().expect("a config has a stage").figures.clone(),
            over_time: time_points::over_time(points),
            step_strains,
            stages,
            alignment: self.alignment.to_vec(),
            start_trials: self.start_trials.to_vec(),
            retries: self.retries.to_vec(),
            files: Vec::new(),
            sha256: Default::default(),
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
    } else if last.misses.is_some() {
        Status::MissesTarget
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
        misses: None,
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
    if last.unsound.is_none() && last.figures.voxel_dice.is_some_and(|d| d <= 0.0) {
        // No overlap at all is no fit, whatever the optimiser's progress rule said (issue 33).
        last.unsound = Some(
            "the fitted model overlaps no foreground voxel of the image (voxel Dice 0): check \
             the template's scale and position against the image"
                .into(),
        );
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
/// `retried`: the runs of an automatic fit before this one that ended unsound; `over_time`:
/// the worst figures over the fitted flow's time points, which the constraints are judged on.
fn failure(
    status: Status,
    last: &StageSummary,
    cfg: &StageConfig,
    out: &Path,
    retried: usize,
    over_time: Option<time_points::OverTime>,
) -> Option<CliError> {
    let written = format!("results written to {} (status \"", out.display());
    match status {
        Status::Unsound => Some(CliError::Unsound(format!(
            "stage '{}', {}; {written}unsound\", the last sound iterate){}",
            last.name,
            last.unsound.as_deref().unwrap_or_default(),
            match retried {
                0 => "; to try: twice the time steps without coarse steps, a 1.5× wider sigma, \
                      a nearer start (docs/troubleshooting.md)"
                    .to_string(),
                n => format!(
                    ", after {n} more runs with safer settings (summary.json: retries); to try: \
                     a nearer start (docs/troubleshooting.md)"
                ),
            }
        ))),
        Status::ConstraintsNotMet => {
            // The worst over the flow's time points and its end: the figures judged.
            let worst = |end: Option<f64>, flow: Option<f64>| {
                [end, flow].into_iter().flatten().fold(f64::NAN, f64::max)
            };
            Some(CliError::ConstraintsNotMet(format!(
                "stage '{}': the medial constraints are not met (max spoke–normal {:.3}°, max \
                 mismatch {:.3} % over the fitted flow; tolerance {}°, {} %): raise mu, \
                 mu_factor or al_iterations; {written}constraints_not_met\")",
                last.name,
                worst(
                    last.figures.max_spoke_normal_deg,
                    over_time.as_ref().map(|o| o.max_spoke_normal_deg)
                ),
                worst(
                    last.figures.max_spoke_mismatch_pct,
                    over_time.as_ref().map(|o| o.max_spoke_mismatch_pct)
                ),
                cfg.tolerance_deg,
                cfg.tolerance_pct,
            )))
        }
        Status::MissesTarget => Some(CliError::MissesTarget(format!(
            "stage '{}': the model misses its target: {}: check where the fit started \
             (aligned_template.vtk of a fit without a config, else the template) and that the \
             template is of this structure; {written}misses_target\")",
            last.name,
            last.misses.as_deref().unwrap_or_default(),
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
