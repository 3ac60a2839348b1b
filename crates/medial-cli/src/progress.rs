//! A fit as it runs: `log.csv` (one row per L-BFGS iteration) and progress on the terminal (a
//! spinner when stderr is a terminal, plain log lines every few seconds otherwise).

use crate::error::CliError;
use crate::results::ResultSet;
use crate::summary::Figures;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// One row of `log.csv`.
pub struct LogRow<'a> {
    /// Stage name.
    pub stage: &'a str,
    /// AL iteration.
    pub al_iteration: usize,
    /// L-BFGS iteration.
    pub iteration: usize,
    /// Evaluations in this minimisation so far.
    pub evaluations: usize,
    /// μ.
    pub mu: f64,
    /// Figures at the iterate.
    pub figures: &'a Figures,
    /// `‖∇E‖`.
    pub grad_norm: f64,
    /// Seconds since the fit started.
    pub seconds: f64,
    /// Time steps of the flow of this minimisation (coarse or the config's).
    pub time_steps: usize,
}

/// `log.csv`, written to `.medial-<pid>-log.csv.part` in the result folder as the fit goes
/// (flushed row by row, for `tail -f`) and moved into the set of results when the fit ends
/// ([`Log::finish`]); removed if the fit fails before. The name is a temporary name of the tool
/// ([`medial_io::atomic::temp_owner`]): a later run removes it when this one was killed, and
/// never a user's `*.part` file. It keeps its text for checkpoints.
pub struct Log {
    out: BufWriter<std::fs::File>,
    part: PathBuf,
    text: String,
    finished: bool,
}

const LOG_HEADER: &str = "stage,al_iteration,iteration,evaluations,mu,total,kinetic,data,penalty,max_abs_constraint,max_spoke_normal_deg,max_spoke_mismatch_pct,grad_norm,seconds,dice,time_steps";

impl Log {
    /// Starts `path` (as [`part_name`] beside it, numbered) with `earlier`, the log of a
    /// checkpoint up to it, or with the header when `earlier` is empty.
    pub fn create(path: &Path, earlier: &str) -> Result<Self, CliError> {
        // Numbered: a fit run again from another start keeps an earlier run's log open (the
        // run it may write) beside the new one's.
        static LOGS: AtomicUsize = AtomicUsize::new(0);
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        let number = LOGS.fetch_add(1, Ordering::Relaxed);
        let part =
            path.with_file_name(part_name(&format!("{number}-{}", name.unwrap_or_default())));
        let file = std::fs::File::options()
            .write(true)
            .create_new(true)
            .open(&part)
            .map_err(|e| CliError::io(&part, e))?;
        let mut log = Self {
            out: BufWriter::new(file),
            part,
            text: String::new(),
            finished: false,
        };
        match earlier {
            "" => log.append(&format!("{LOG_HEADER}\n"))?,
            text => log.append(text)?,
        }
        Ok(log)
    }

    /// Appends a row (flushed, so that a running fit can be watched).
    pub fn row(&mut self, r: &LogRow<'_>) -> Result<(), CliError> {
        let f = r.figures;
        let opt = |x: Option<f64>| x.map(|v| format!("{v:.9e}")).unwrap_or_default();
        let line = format!(
            "{},{},{},{},{:e},{:.12e},{:.9e},{:.9e},{:.9e},{:.6e},{},{},{:.6e},{:.3},{},{}\n",
            csv_field(r.stage),
            r.al_iteration,
            r.iteration,
            r.evaluations,
            r.mu,
            f.total,
            f.kinetic,
            f.data,
            f.penalty,
            f.max_abs_constraint,
            opt(f.max_spoke_normal_deg),
            opt(f.max_spoke_mismatch_pct),
            r.grad_norm,
            r.seconds,
            opt(f.dice),
            r.time_steps,
        );
        self.append(&line)
    }

    fn append(&mut self, text: &str) -> Result<(), CliError> {
        self.text.push_str(text);
        self.out
            .write_all(text.as_bytes())
            .and_then(|_| self.out.flush())
            .map_err(|e| CliError::io(&self.part, e))
    }

    /// Everything written so far, header included.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Completes the log: syncs `log.csv.part` and moves it into `set` as `log.csv`.
    pub fn finish(mut self, set: &mut ResultSet) -> Result<(), CliError> {
        self.out.flush().map_err(|e| CliError::io(&self.part, e))?;
        self.out
            .get_ref()
            .sync_all()
            .map_err(|e| CliError::io(&self.part, e))?;
        set.adopt(&self.part, "log.csv")?;
        self.finished = true;
        Ok(())
    }
}

impl Drop for Log {
    /// A log that was not finished goes with its fit (best effort).
    fn drop(&mut self) {
        if !self.finished {
            let _ = std::fs::remove_file(&self.part);
        }
    }
}

/// The name of the unfinished file `name` of this process: `.medial-<pid>-<name>.part`.
pub fn part_name(name: &str) -> String {
    format!("{}{name}.part", medial_io::atomic::temp_prefix())
}

/// Quotes a CSV field when it needs it.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Progress of a fit: an indicatif spinner on a terminal, a log line every few seconds
/// otherwise (batch jobs).
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    last_line: Instant,
}

impl Progress {
    /// Chooses the display from whether stderr is a terminal; `quiet` shows nothing.
    pub fn new(quiet: bool) -> Self {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
            );
            bar.enable_steady_tick(Duration::from_millis(200));
            bar
        });
        Self {
            bar,
            last_line: Instant::now() - Duration::from_secs(60),
        }
    }

    /// Shows the state after an iteration.
    pub fn update(&mut self, r: &LogRow<'_>) {
        let f = r.figures;
        let mut msg = format!(
            "{} al {} it {:>4} E {:.6e} data {:.4e} KE {:.3e}",
            r.stage, r.al_iteration, r.iteration, f.total, f.data, f.kinetic
        );
        if let Some(d) = f.dice {
            msg += &format!(" dice {d:.4}");
        }
        if let (Some(a), Some(m)) = (f.max_spoke_normal_deg, f.max_spoke_mismatch_pct) {
            msg += &format!(" spoke∠ {a:.3}° mismatch {m:.2}%");
        }
        match &self.bar {
            Some(bar) => bar.set_message(msg),
            None if self.last_line.elapsed() >= Duration::from_secs(5) || r.iteration == 0 => {
                tracing::info!("{msg}");
                self.last_line = Instant::now();
            }
            None => {}
        }
    }

    /// Prints a line above the bar (or as a log line).
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(bar) => bar.println(line),
            None => tracing::info!("{line}"),
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
