//! `medial`: diffeomorphic medial modeling from the command line. The binary's `main` calls
//! [`main`]; the library exists so that the fuzz targets (`fuzz/`) reach the config parser.
//!
//! Data flows one way: [`config`] reads a TOML schedule, [`stage`] assembles what the engine runs,
//! the [`commands`] run it, and [`summary`], [`progress`], [`time_points`], [`atoms`] and
//! [`output`] write what a user reads, as one set of files ([`results`]). A fit stopped by a
//! signal ([`signals`]) leaves a [`checkpoint`] to resume from. A [`cohort`] is many fits of one
//! template, run by `medial batch` (on a Slurm cluster too) and gathered into tables.

mod atoms;
mod checkpoint;
mod cohort;
mod commands;
pub mod config;
mod error;
mod fitting;
mod memory;
mod output;
mod progress;
mod report;
mod results;
mod signals;
mod stage;
mod summary;
mod time_points;

use clap::Parser;
pub use error::CliError;
use std::process::ExitCode;

/// Fit medial templates of sheet-like structures (heart wall, placenta, valve leaflets,
/// cartilage) to subjects with a diffeomorphic flow that keeps the medial axis medial.
#[derive(Parser)]
#[command(name = "medial", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
    /// Worker threads (default: all cores). Results are bit-identical for any count.
    #[arg(long, global = true, value_name = "N")]
    threads: Option<usize>,
    /// No progress display (log lines and warnings still go to stderr).
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Refuse a run whose memory estimate passes this many GiB, before allocating it
    /// [default: the machine's total memory, 16 where unknown].
    #[arg(long, global = true, value_name = "GIB", value_parser = memory::parse_gib)]
    max_memory: Option<f64>,
}

/// Parses the command line, runs the command, prints an error as one line; the exit code.
pub fn main() -> ExitCode {
    main_with(std::env::args_os())
}

/// [`main`] with the command line `args` (the program's name first), for a test that runs a
/// command in its own process ([`before_each_commit_step`]).
#[doc(hidden)]
pub fn main_with<T: Into<std::ffi::OsString> + Clone>(
    args: impl IntoIterator<Item = T>,
) -> ExitCode {
    let cli = Cli::parse_from(args);
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("MEDIAL_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .init();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}

/// Calls `hook` with 1, 2, … before each file operation (a link, a rename, a removal) of the
/// commit of a result set in this process: the kill-anywhere test of the crash-safe commit
/// (`tests/cli/reliability.rs`, decision 0300) kills its process at the n-th. The binary never
/// sets one, and there is no option or variable to set one.
#[doc(hidden)]
pub fn before_each_commit_step(hook: fn(usize)) {
    results::before_each_step(hook);
}

/// Stack of each worker thread: the main thread's usual 8 MiB, as the whole command runs on
/// the pool.
const STACK_BYTES: usize = 8 << 20;

/// The command, run on a thread of the pool (the main thread waits): the fit's sequential
/// work (L-BFGS, the checks) then shares its parallel parts with the other threads as rayon
/// tasks, instead of handing each one to the pool from outside and sleeping until it is done
/// (see the README's Performance section).
fn run(cli: Cli) -> Result<(), CliError> {
    signals::survive_file_size_limit()?;
    memory::set_limit(cli.max_memory);
    let threads = configure_threads(cli.threads)?;
    rayon::scope(|_| commands::run(cli.command, threads, cli.quiet))
}

/// Starts rayon's global pool (`threads`, or one per core) with threads of [`STACK_BYTES`];
/// returns the number of threads in use.
fn configure_threads(threads: Option<usize>) -> Result<usize, CliError> {
    if threads == Some(0) {
        return Err(CliError::Input("--threads must be at least 1".into()));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .stack_size(STACK_BYTES)
        .build_global()
        .map_err(|e| CliError::Input(format!("cannot start the worker threads: {e}")))?;
    Ok(rayon::current_num_threads())
}
