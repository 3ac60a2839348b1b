//! What a fit tells its user: `log.csv` (one row per L-BFGS iteration), `summary.json`, and
//! progress on the terminal (a bar when stderr is a terminal, plain log lines otherwise).

use crate::error::CliError;
use crate::time_points::OverTime;
use medial_core::fit::objective::Evaluation;
use medial_core::model::metrics::SpokeMetrics;
use serde::Serialize;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The figures of a configuration, as in `summary.json` (`final` and each stage) and the
/// output of `medial eval`. Kinetic energy and data term are unweighted.
#[derive(Clone, Debug, Serialize)]
pub struct Figures {
    /// `E_AL`.
    pub total: f64,
    /// `KE`.
    pub kinetic: f64,
    /// `g(q^N)`.
    pub data: f64,
    /// Penalty `P`.
    pub penalty: f64,
    /// `max |C|` over time points 1…N (0 without constraints).
    pub max_abs_constraint: f64,
    /// Dice estimate, for Dice stages.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dice: Option<f64>,
    /// Dice stages, at the end of a stage: the voxel overlap `2|M ∩ A| / (|M| + |A|)` of the
    /// rasterized model `M` with the binary foreground `A` of the image, on the image's grid.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voxel_dice: Option<f64>,
    /// Mean distance to the SSD targets (mm), for SSD stages.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_distance: Option<f64>,
    /// Largest spoke–normal angle at the end of the flow, degrees (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_spoke_normal_deg: Option<f64>,
    /// Mean spoke–normal angle at the end of the flow, degrees (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_spoke_normal_deg: Option<f64>,
    /// Largest spoke-length mismatch at the end of the flow, % (medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_spoke_mismatch_pct: Option<f64>,
}

impl Figures {
    /// From an evaluation, the spoke metrics at `q^N` and the SSD mean distance.
    pub fn new(e: &Evaluation, metrics: Option<&SpokeMetrics>, mean_distance: Option<f64>) -> Self {
        Self {
            total: e.total,
            kinetic: e.kinetic,
            data: e.data,
            penalty: e.penalty,
            max_abs_constraint: e.max_abs_constraint,
            dice: e.dice,
            voxel_dice: None,
            mean_distance,
            max_spoke_normal_deg: metrics.map(|m| m.max_spoke_normal_deg),
            mean_spoke_normal_deg: metrics.map(|m| m.mean_spoke_normal_deg),
            max_spoke_mismatch_pct: metrics.map(|m| 100.0 * m.max_spoke_mismatch),
        }
    }
}

/// One stage in `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct StageSummary {
    /// The stage's name.
    pub name: String,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Value + gradient evaluations.
    pub evaluations: usize,
    /// L-BFGS iterations (all AL iterations).
    pub iterations: usize,
    /// AL iterations.
    pub al_iterations: usize,
    /// μ after the schedule.
    pub mu: f64,
    /// Why each minimisation stopped.
    pub stop: Vec<String>,
    /// The figures at the end of the stage.
    #[serde(flatten)]
    pub figures: Figures,
}

/// `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// `medial` version.
    pub version: &'static str,
    /// `k`.
    pub landmarks: usize,
    /// Boundary points.
    pub boundary_points: usize,
    /// Medial atoms.
    pub medial_atoms: usize,
    /// Medial constraints per time point (0 for a plain mesh).
    pub constraints_per_time_point: usize,
    /// `N`.
    pub time_steps: usize,
    /// Kernel width σ.
    pub sigma: f64,
    /// Worker threads.
    pub threads: usize,
    /// Wall-clock seconds of all stages.
    pub seconds: f64,
    /// Value + gradient evaluations of all stages.
    pub evaluations: usize,
    /// Figures at the end.
    #[serde(rename = "final")]
    pub final_figures: Figures,
    /// Medial templates: the worst spoke figures over time points 1 … N (`time_points.csv`
    /// holds them per time point).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub over_time: Option<OverTime>,
    /// Each stage.
    pub stages: Vec<StageSummary>,
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), CliError> {
    medial_io::atomic::write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })?;
    Ok(())
}

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
}

/// `log.csv`, written to `log.csv.part` as the fit goes and renamed when it is complete.
pub struct Log {
    out: BufWriter<std::fs::File>,
    part: PathBuf,
    path: PathBuf,
}

const LOG_HEADER: &str = "stage,al_iteration,iteration,evaluations,mu,total,kinetic,data,penalty,max_abs_constraint,max_spoke_normal_deg,max_spoke_mismatch_pct,grad_norm,seconds,dice";

impl Log {
    /// Starts `path` (as `path.part`).
    pub fn create(path: &Path) -> Result<Self, CliError> {
        let part = path.with_extension("csv.part");
        let file = std::fs::File::create(&part).map_err(|e| CliError::io(&part, e))?;
        let mut out = BufWriter::new(file);
        writeln!(out, "{LOG_HEADER}").map_err(|e| CliError::io(&part, e))?;
        Ok(Self {
            out,
            part,
            path: path.into(),
        })
    }

    /// Appends a row (flushed, so that a running fit can be watched).
    pub fn row(&mut self, r: &LogRow<'_>) -> Result<(), CliError> {
        let f = r.figures;
        let opt = |x: Option<f64>| x.map(|v| format!("{v:.9e}")).unwrap_or_default();
        writeln!(
            self.out,
            "{},{},{},{},{:e},{:.12e},{:.9e},{:.9e},{:.9e},{:.6e},{},{},{:.6e},{:.3},{}",
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
        )
        .and_then(|_| self.out.flush())
        .map_err(|e| CliError::io(&self.part, e))
    }

    /// Completes the log: renames `log.csv.part` to `log.csv`.
    pub fn finish(mut self) -> Result<(), CliError> {
        self.out.flush().map_err(|e| CliError::io(&self.part, e))?;
        self.out
            .get_ref()
            .sync_all()
            .map_err(|e| CliError::io(&self.part, e))?;
        std::fs::rename(&self.part, &self.path).map_err(|e| CliError::io(&self.path, e))
    }
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
