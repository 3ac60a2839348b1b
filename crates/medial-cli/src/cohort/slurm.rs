//! A cohort as Slurm jobs: `batch.sbatch`, a job array whose every task runs `medial batch`
//! on its shard of the subjects (from `SLURM_ARRAY_TASK_ID`, [`super::shard`]); `gather.sbatch`,
//! which gathers the cohort folder; and `submit.sh`, which submits the array and then the
//! gather job with `--dependency=afterany:<array>` (it runs when every task has ended, failed
//! or not). Options given to `submit.sh` go to both `sbatch` calls and override the scripts'
//! `#SBATCH` lines. The logs go to `DIR/slurm/`. The scripts name the `medial` binary that wrote
//! them (the environment variable `MEDIAL` replaces it) and every path absolute.

use crate::error::CliError;
use crate::output::write_text;
use crate::results::create_dir;
use std::path::{Path, PathBuf};

/// The job array.
pub const BATCH_SCRIPT: &str = "batch.sbatch";
/// The gather job.
pub const GATHER_SCRIPT: &str = "gather.sbatch";
/// Submits both.
pub const SUBMIT_SCRIPT: &str = "submit.sh";
/// The folder of the jobs' logs.
pub const LOG_FOLDER: &str = "slurm";

/// The resources of the array's tasks, as `sbatch` options.
#[derive(clap::Args, Debug)]
pub struct SlurmOptions {
    /// With --slurm: array tasks, each fitting every N-th subject [default: one per subject].
    #[arg(long, value_name = "N", requires = "slurm", value_parser = clap::value_parser!(u64).range(1..))]
    pub slurm_tasks: Option<u64>,
    /// With --slurm: CPUs of each task (sbatch --cpus-per-task); its fits use them all.
    #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    pub slurm_cpus: u64,
    /// With --slurm: wall-clock limit of each task (sbatch --time: MM, HH:MM:SS, D-HH:MM:SS).
    #[arg(long, value_name = "TIME", default_value = "01:00:00", value_parser = sbatch_value)]
    pub slurm_time: String,
    /// With --slurm: memory of each task and of the gather job (sbatch --mem: e.g. 4G, 500M).
    #[arg(long, value_name = "SIZE", default_value = "4G", value_parser = sbatch_value)]
    pub slurm_mem: String,
    /// With --slurm: the partition of both jobs (sbatch --partition) [default: the cluster's].
    #[arg(long, value_name = "NAME", requires = "slurm", value_parser = sbatch_value)]
    pub slurm_partition: Option<String>,
}

/// A value for an `#SBATCH` line: letters, digits and `:-_.,+` only.
fn sbatch_value(text: &str) -> Result<String, String> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || ":-_.,+".contains(c);
    if !text.is_empty() && text.chars().all(allowed) {
        Ok(text.into())
    } else {
        Err(format!(
            "'{text}' cannot go on an #SBATCH line: use letters, digits and :-_.,+"
        ))
    }
}

/// The jobs of a cohort: the `medial batch` command line that fits it (binary first, without
/// a shard) and the one that gathers it.
pub struct Jobs<'a> {
    /// The cohort folder (absolute).
    pub dir: &'a Path,
    /// `medial batch TEMPLATE SUBJECTS --out DIR [--config BASE]`, the binary first.
    pub fit: Vec<String>,
    /// The same with `--gather-only`.
    pub gather: Vec<String>,
    /// Subjects in the table.
    pub subjects: usize,
}

/// Writes the three scripts into `jobs.dir` and creates its log folder; returns the scripts'
/// paths (`submit.sh` last).
pub fn write(jobs: &Jobs<'_>, options: &SlurmOptions) -> Result<Vec<PathBuf>, CliError> {
    let dir = jobs.dir;
    let dir_text = dir.to_string_lossy();
    if dir_text
        .chars()
        .any(|c| c.is_whitespace() || c == '%' || c == '"')
    {
        return Err(CliError::Input(format!(
            "{dir_text}: --slurm needs an output folder whose path has no spaces, '%' or '\"' \
             (Slurm reads the log paths from #SBATCH lines)"
        )));
    }
    let logs = dir.join(LOG_FOLDER);
    create_dir(&logs)?;
    let tasks = options
        .slurm_tasks
        .map_or(jobs.subjects, |t| usize::try_from(t).unwrap_or(usize::MAX))
        .min(jobs.subjects);
    let partition = options
        .slurm_partition
        .as_ref()
        .map(|p| format!("#SBATCH --partition={p}\n"))
        .unwrap_or_default();
    let per_task = if tasks == jobs.subjects {
        "one subject per task".to_string()
    } else {
        format!("each task every {tasks}-th subject")
    };
    let batch = format!(
        "#!/bin/bash\n\
         # Written by `medial batch --slurm`: fits the {} subjects into {dir_text}, a job array \
         of {tasks} tasks ({per_task}; a task takes its shard from SLURM_ARRAY_TASK_ID). Finished \
         subjects are skipped, so the array can be submitted again. sbatch options on the \
         command line override these lines.\n\
         #SBATCH --job-name=medial-batch\n\
         #SBATCH --array=1-{tasks}\n\
         #SBATCH --cpus-per-task={}\n\
         #SBATCH --time={}\n\
         #SBATCH --mem={}\n\
         {partition}\
         #SBATCH --output={}/batch-%A_%a.out\n\
         {}",
        jobs.subjects,
        options.slurm_cpus,
        options.slurm_time,
        options.slurm_mem,
        logs.display(),
        run_line(&jobs.fit, "--threads \"${SLURM_CPUS_PER_TASK:-1}\"")?,
    );
    let gather = format!(
        "#!/bin/bash\n\
         # Written by `medial batch --slurm`: gathers {dir_text} (cohort.csv, thickness.npy, \
         thickness_mean.vtk) once the array has ended.\n\
         #SBATCH --job-name=medial-gather\n\
         #SBATCH --cpus-per-task=1\n\
         #SBATCH --time=00:30:00\n\
         #SBATCH --mem={}\n\
         {partition}\
         #SBATCH --output={}/gather-%j.out\n\
         {}",
        options.slurm_mem,
        logs.display(),
        run_line(&jobs.gather, "")?,
    );
    let (batch_path, gather_path) = (dir.join(BATCH_SCRIPT), dir.join(GATHER_SCRIPT));
    let submit = format!(
        "#!/bin/sh\n\
         # Written by `medial batch --slurm`: submits the job array, then the gather job that \
         runs once every task has ended (afterany: also after failed tasks). Arguments go to \
         both sbatch calls (e.g. --account=lab --partition=short).\n\
         set -eu\n\
         results={}\n\
         array=$(sbatch --parsable \"$@\" {})\n\
         array=${{array%%;*}}\n\
         gather=$(sbatch --parsable \"$@\" --dependency=afterany:\"$array\" {})\n\
         gather=${{gather%%;*}}\n\
         echo \"submitted the array job $array ({tasks} tasks) and the gather job $gather; \
         follow them with: squeue -j $array,$gather; results: $results\"\n",
        quote(&dir.join(super::gather::COHORT_CSV))?,
        quote(&batch_path)?,
        quote(&gather_path)?,
    );
    let submit_path = dir.join(SUBMIT_SCRIPT);
    for (path, text) in [
        (&batch_path, batch),
        (&gather_path, gather),
        (&submit_path, submit),
    ] {
        write_text(path, &text)?;
        executable(path)?;
    }
    Ok(vec![batch_path, gather_path, submit_path])
}

/// The script lines that run `command` (binary first) with `extra` appended unquoted:
/// `medial=${MEDIAL:-binary}` and `exec "$medial" args… extra`.
fn run_line(command: &[String], extra: &str) -> Result<String, CliError> {
    let (binary, args) = command.split_first().expect("a command has a binary");
    let args = shlex::try_join(args.iter().map(String::as_str))
        .map_err(|e| CliError::Input(format!("a path cannot go into a shell script: {e}")))?;
    Ok(format!(
        "set -eu\nmedial=${{MEDIAL:-{}}}\nexec \"$medial\" {args} {extra}\n",
        shlex::try_quote(binary).map_err(|e| CliError::Input(format!("{binary}: {e}")))?
    ))
}

/// `path` quoted for a shell.
fn quote(path: &Path) -> Result<String, CliError> {
    let text = path.to_string_lossy();
    shlex::try_quote(&text)
        .map(|q| q.into_owned())
        .map_err(|e| CliError::Input(format!("{text}: {e}")))
}

/// Makes the script `path` executable (`rwxr-xr-x` as the umask allows).
fn executable(path: &Path) -> Result<(), CliError> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path)
            .map_err(|e| CliError::io(path, e))?
            .permissions()
            .mode();
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode | 0o111))
            .map_err(|e| CliError::io(path, e))?;
    }
    Ok(())
}
