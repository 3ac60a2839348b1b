//! `medial batch`: fits every subject of a subject table ([`crate::cohort::subjects`]) from one
//! template into `DIR/SUBJECT/`, in this process, through the same code as `medial fit`
//! ([`crate::fitting::resolve`] and [`crate::fitting::run`]); then gathers the cohort folder
//! ([`crate::cohort::gather`]). A subject whose fit ran to its end earlier is skipped, one
//! stopped by a signal is resumed from its checkpoint, one that fails is recorded in
//! `DIR/SUBJECT/failed.json` and the others go on. `--shard` (or a Slurm array task) takes
//! a share of the subjects; `--slurm` writes the scripts of a Slurm job array instead of fitting.

use crate::cohort::gather::{self, Failure, Gathered, Standing};
use crate::cohort::shard::Shard;
use crate::cohort::slurm::{self, SlurmOptions};
use crate::cohort::subjects::{self, Subject};
use crate::cohort::FAILED_JSON;
use crate::config::Config;
use crate::error::CliError;
use crate::fitting::{self, FitOptions, Inputs};
use crate::output::{print_json, write_json};
use crate::signals::Signals;
use std::path::{Path, PathBuf};

/// The arguments of `medial batch`.
#[derive(clap::Args, Debug)]
pub struct BatchArgs {
    /// The template every subject is fitted from (a cmrep medial template, or a plain mesh;
    /// legacy VTK, mm).
    #[arg(value_name = "TEMPLATE.vtk")]
    template: PathBuf,
    /// The subjects: CSV with a header, a `subject` column (names of folders: letters, digits,
    /// '.', '_', '-') and one of `image` (segmentations, Dice), `target` (corresponding points,
    /// SSD), `surface` (meshes, varifold); optional `label` (with `image`) and `transform` (a
    /// 4×4 map for a base config's SSD transform stages). Paths relative to the CSV's folder.
    #[arg(value_name = "SUBJECTS.csv")]
    subjects: PathBuf,
    /// The cohort folder: DIR/SUBJECT/ holds each fit (as `medial fit --out` writes it),
    /// DIR/cohort.csv, DIR/thickness.npy, DIR/thickness_subjects.txt and DIR/thickness_mean.vtk
    /// the gathered figures.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// A base config: each subject is fitted by its stages with the template and the subject's
    /// target (and transform) in place of the config's, like `medial fit BASE.toml --template
    /// … --image …` [default: the automatic settings of `medial fit` without a config].
    #[arg(long, value_name = "BASE.toml")]
    config: Option<PathBuf>,
    /// Fit only shard I of N: the subjects at rows I, I + N, I + 2N, … of the table (I from 1
    /// to N) [default: all, or in a Slurm job array the task's shard from SLURM_ARRAY_TASK_ID,
    /// SLURM_ARRAY_TASK_MIN and SLURM_ARRAY_TASK_COUNT].
    #[arg(long, value_name = "I/N", conflicts_with_all = ["gather_only", "slurm"])]
    shard: Option<Shard>,
    /// Fit nothing: gather the cohort folder (the subjects whose summary.json is complete)
    /// into its tables; safe while other jobs still fit.
    #[arg(long, conflicts_with = "slurm")]
    gather_only: bool,
    /// Fit nothing: write DIR/batch.sbatch (a Slurm job array over the subjects),
    /// DIR/gather.sbatch (the gathering) and DIR/submit.sh (submits both, the gathering after
    /// the array), and print how to submit them.
    #[arg(long)]
    slurm: bool,
    #[command(flatten)]
    slurm_options: SlurmOptions,
}

/// Runs `medial batch` with `threads` worker threads in use.
pub fn run(args: &BatchArgs, threads: usize, quiet: bool) -> Result<(), CliError> {
    let checked = Checked::of(args)?;
    if args.slurm {
        return write_slurm(args, &checked.dir, checked.subjects.len());
    }
    let (gathered, outcome) = if args.gather_only {
        let names = checked.names();
        let gathered = gather::gather(&checked.dir, &checked.template, &names)?;
        let outcome = judge(&gathered, &gathered.failed, &checked.dir);
        (gathered, outcome)
    } else {
        fit_checked(args, &checked, threads, quiet)?
    };
    print_json(&gathered)?;
    outcome
}

impl BatchArgs {
    /// The arguments of `medial batch TEMPLATE SUBJECTS --out DIR [--config BASE]` (every
    /// other option at its default).
    pub fn fit(template: &Path, subjects: &Path, out: &Path, config: Option<&Path>) -> Self {
        #[derive(clap::Parser)]
        struct Line {
            #[command(flatten)]
            batch: BatchArgs,
        }
        let mut line = vec![
            "batch".as_ref(),
            template.as_os_str(),
            subjects.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
        ];
        if let Some(base) = config {
            line.extend(["--config".as_ref(), base.as_os_str()]);
        }
        <Line as clap::Parser>::parse_from(line).batch
    }
}

/// Fits the subjects (those of the shard) and gathers the cohort, as `medial batch` without
/// `--gather-only` or `--slurm` does but print; returns what it prints and its outcome (the
/// error of the subjects that failed or of a fit stopped by a signal, after the gathering).
pub fn fit_and_gather(
    args: &BatchArgs,
    threads: usize,
    quiet: bool,
) -> Result<(Gathered, Result<(), CliError>), CliError> {
    fit_checked(args, &Checked::of(args)?, threads, quiet)
}

/// The inputs of a batch, read and checked.
struct Checked {
    template: medial_core::model::Model,
    subjects: Vec<Subject>,
    /// The cohort folder, absolute.
    dir: PathBuf,
}

impl Checked {
    fn of(args: &BatchArgs) -> Result<Self, CliError> {
        let template = medial_io::model::read_model(&args.template)?;
        let subjects = subjects::read(&args.subjects, &args.template)?;
        if let Some(base) = &args.config {
            subjects::check_base(&Config::load(base)?, base, &subjects)?;
        } else if subjects[0].transform.is_some() {
            return Err(CliError::Subjects {
                path: args.subjects.clone(),
                message: "the 'transform' column needs --config BASE.toml with an SSD stage that \
                          aligns by a transform (without a config the initial map is found from \
                          the data)"
                    .into(),
            });
        }
        let dir = std::path::absolute(&args.out).map_err(|e| CliError::io(&args.out, e))?;
        Ok(Self {
            template,
            subjects,
            dir,
        })
    }

    fn names(&self) -> Vec<&str> {
        self.subjects.iter().map(|s| s.name.as_str()).collect()
    }
}

/// Fits the checked subjects of `args`' shard and gathers the cohort.
fn fit_checked(
    args: &BatchArgs,
    checked: &Checked,
    threads: usize,
    quiet: bool,
) -> Result<(Gathered, Result<(), CliError>), CliError> {
    let Checked {
        template,
        subjects,
        dir,
    } = checked;
    let shard = match args.shard {
        Some(shard) => Some(shard),
        None => Shard::from_slurm(|name| std::env::var(name).ok())?,
    };
    let mine: Vec<&Subject> = subjects
        .iter()
        .enumerate()
        .filter(|(position, _)| shard.map_or(true, |s| s.takes(*position)))
        .map(|(_, s)| s)
        .collect();
    for subject in &mine {
        result_folder_or_none(&dir.join(&subject.name), &subject.name, &args.subjects)?;
    }
    let stopped = fit_all(&mine, args.config.as_deref(), dir, threads, quiet)?;
    let gathered = gather::gather(dir, template, &checked.names())?;
    if let Some(interrupted) = stopped {
        return Ok((gathered, Err(interrupted)));
    }
    let failed: Vec<String> = gathered
        .failed
        .iter()
        .filter(|f| mine.iter().any(|s| &s.name == *f))
        .cloned()
        .collect();
    let outcome = judge(&gathered, &failed, dir);
    Ok((gathered, outcome))
}

/// Fits `subjects` into `dir` one after the other; returns the error of a fit stopped by a
/// signal (the batch stops there: the next run resumes it), after which no subject starts.
fn fit_all(
    subjects: &[&Subject],
    base: Option<&Path>,
    dir: &Path,
    threads: usize,
    quiet: bool,
) -> Result<Option<CliError>, CliError> {
    let signals = Signals::catch()?;
    for (i, subject) in subjects.iter().enumerate() {
        if let Some(signal) = signals.received() {
            return Ok(Some(CliError::Interrupted {
                signal,
                message: format!(
                    "interrupted by {} before subject '{}' ({} of {}); running the batch again \
                     continues it",
                    signal.name(),
                    subject.name,
                    i + 1,
                    subjects.len()
                ),
            }));
        }
        let out = dir.join(&subject.name);
        let standing = Standing::read(&out);
        let what = format!(
            "subject '{}' ({} of {})",
            subject.name,
            i + 1,
            subjects.len()
        );
        if standing.finished() {
            tracing::info!("{what}: fitted earlier, skipped ({})", out.display());
            continue;
        }
        tracing::info!("{what}: fitting into {}", out.display());
        match fit_one(subject, base, &out, standing.interrupted(), threads, quiet) {
            Ok(()) => {}
            Err(e @ CliError::Interrupted { .. }) => return Ok(Some(e)),
            Err(e) => {
                tracing::warn!("{what} failed (exit code {}): {e}", e.exit_code());
                let failure = Failure {
                    subject: subject.name.clone(),
                    error: e.to_string(),
                    exit_code: e.exit_code(),
                };
                write_json(&out.join(FAILED_JSON), &failure)?;
            }
        }
    }
    Ok(None)
}

/// `Ok` when the subject `name`'s folder `out` does not exist, is empty, or holds what a fit
/// leaves (its `summary.json`, `failed.json`, `checkpoint.bin`, `config.toml`, alignment, or a
/// staging folder or temporary file of the tool); refused, before any fit, when it is
/// something else (a folder of the user's beside the outputs, a file, a link), which a fit
/// must not write into.
fn result_folder_or_none(out: &Path, name: &str, table: &Path) -> Result<(), CliError> {
    const LEFT_BY_A_FIT: [&str; 5] = [
        "summary.json",
        FAILED_JSON,
        crate::checkpoint::FILE,
        "config.toml",
        "aligned_template.vtk",
    ];
    let refuse = |what: &str| CliError::Subjects {
        path: table.into(),
        message: format!(
            "subject '{name}': {} {what}: a fit must not write there; rename the subject or \
             move that away",
            out.display()
        ),
    };
    match std::fs::symlink_metadata(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(CliError::io(out, e)),
        Ok(meta) if meta.file_type().is_symlink() => Err(refuse("is a symbolic link")),
        Ok(meta) if !meta.is_dir() => Err(refuse("exists and is not a folder")),
        Ok(_) => {
            let names: Vec<String> = std::fs::read_dir(out)
                .map_err(|e| CliError::io(out, e))?
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            let of_a_fit =
                |n: &String| LEFT_BY_A_FIT.contains(&n.as_str()) || n.starts_with(".medial-");
            if names.is_empty() || names.iter().any(of_a_fit) {
                Ok(())
            } else {
                Err(refuse(
                    "is a folder that no fit wrote (it holds no summary.json, failed.json or \
                     checkpoint.bin)",
                ))
            }
        }
    }
}

/// Fits `subject` into `out` (from its checkpoint if `resume`), as `medial fit` would.
fn fit_one(
    subject: &Subject,
    base: Option<&Path>,
    out: &Path,
    resume: bool,
    threads: usize,
    quiet: bool,
) -> Result<(), CliError> {
    crate::results::create_dir(out)?;
    let failed = out.join(FAILED_JSON);
    if let Err(e) = std::fs::remove_file(&failed) {
        if e.kind() != std::io::ErrorKind::NotFound {
            return Err(CliError::io(&failed, e));
        }
    }
    let resolved = if resume {
        let none = Inputs {
            template: None,
            image: None,
            label: None,
            target: None,
            surface: None,
        };
        fitting::resolve(Some(&out.join("config.toml")), &none, out)?
    } else {
        subject.config(base, out)?
    };
    let options = FitOptions {
        out: out.into(),
        threads,
        quiet,
        checkpoint_every: None,
        resume,
    };
    fitting::run(&resolved, &options).map(|_| ())
}

/// Success, or the error naming the `failed` subjects.
fn judge(gathered: &Gathered, failed: &[String], dir: &Path) -> Result<(), CliError> {
    if failed.is_empty() {
        return Ok(());
    }
    Err(CliError::SubjectsFailed {
        failed: failed.join(", "),
        count: failed.len(),
        subjects: gathered.subjects,
        dir: dir.into(),
    })
}

/// `--slurm`: writes the scripts and prints how to submit them.
fn write_slurm(args: &BatchArgs, dir: &Path, subjects: usize) -> Result<(), CliError> {
    let absolute = |p: &Path| -> Result<String, CliError> {
        Ok(std::path::absolute(p)
            .map_err(|e| CliError::io(p, e))?
            .to_string_lossy()
            .into_owned())
    };
    let exe = std::env::current_exe().map_err(|e| CliError::io(Path::new("<medial>"), e))?;
    let mut command = vec![
        absolute(&exe)?,
        "batch".into(),
        absolute(&args.template)?,
        absolute(&args.subjects)?,
        "--out".into(),
        dir.to_string_lossy().into_owned(),
    ];
    let mut gather = command.clone();
    gather.push("--gather-only".into());
    if let Some(base) = &args.config {
        command.extend(["--config".into(), absolute(base)?]);
    }
    let jobs = slurm::Jobs {
        dir,
        fit: command,
        gather,
        subjects,
    };
    let scripts = slurm::write(&jobs, &args.slurm_options)?;
    for script in &scripts {
        println!("wrote {}", script.display());
    }
    println!(
        "submit with: sh {}  (sbatch options after it go to both jobs)",
        scripts.last().expect("three scripts").display()
    );
    Ok(())
}
