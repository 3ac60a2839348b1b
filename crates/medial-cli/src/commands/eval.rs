//! `medial eval`: the objective of a stage at given momenta, without optimising.

use crate::config::Config;
use crate::error::CliError;
use crate::stage::{self, flow_of};
use crate::summary::Figures;
use medial_core::fit::objective::{ConstraintSet, Objective, Penalty};
use std::path::{Path, PathBuf};

/// Arguments of `medial eval` beyond the config.
pub struct EvalOptions {
    /// Momenta, `[N, k, 3]`.
    pub momenta: PathBuf,
    /// Stage whose objective is evaluated (default: the first).
    pub stage: Option<String>,
    /// μ, positive (checked by the command line; default: the stage's).
    pub mu: Option<f64>,
    /// Multipliers `[N, L]` (default: zeros).
    pub lambda: Option<PathBuf>,
    /// Where to write `∂E/∂u`, `[N, k, 3]`.
    pub gradient: Option<PathBuf>,
}

/// Evaluates and returns the figures (and writes the gradient if asked).
pub fn run(config: &Config, options: &EvalOptions) -> Result<Figures, CliError> {
    let stage_cfg = match &options.stage {
        Some(name) => config.stage(name).ok_or_else(|| {
            let names: Vec<&str> = config.stages.iter().map(|s| s.name.as_str()).collect();
            CliError::Input(format!("no stage named '{name}'; the config has {names:?}"))
        })?,
        None => &config.stages[0],
    };
    let model = medial_io::model::read_model(&config.model.template)?;
    let k = model.landmarks().len();
    let flow = flow_of(config, k)?;
    let prepared = stage::prepare(stage_cfg, &model, stage::read_target(stage_cfg, &model)?)?;
    let steps = flow.time_steps();
    let momenta = read_array(&options.momenta, &[steps, k, 3], "momenta")?;
    let constraints = prepared.constraints.as_ref();
    let lambda = match (&options.lambda, constraints) {
        (Some(path), Some(c)) => read_array(path, &[steps, c.len()], "lambda")?,
        (Some(_), None) => {
            return Err(CliError::Input(
                "--lambda given but the stage has no constraints".into(),
            ))
        }
        (None, c) => vec![0.0; steps * c.map_or(0, |c| c.len())],
    };
    let mut objective = Objective::new(
        &flow,
        model.landmarks(),
        prepared.attachment.as_ref(),
        prepared.data_weight,
    );
    if let Some(c) = constraints {
        let mu = options.mu.unwrap_or(stage_cfg.mu);
        objective = objective.with_penalty(Penalty {
            constraints: c as &dyn ConstraintSet,
            mu,
            lambda: &lambda,
        })?;
    }
    let mut gradient = options.gradient.as_ref().map(|_| vec![0.0; momenta.len()]);
    let evaluation = objective.evaluate(&momenta, gradient.as_deref_mut())?;
    if let (Some(path), Some(g)) = (&options.gradient, &gradient) {
        medial_io::npy::write_npy(path, &[steps, k, 3], g)?;
    }
    Ok(stage::end_figures(&prepared, &model, &evaluation, flow.kernel().sigma())?.0)
}

/// Reads a `.npy` array and checks its shape.
fn read_array(path: &Path, shape: &[usize], what: &str) -> Result<Vec<f64>, CliError> {
    let array = medial_io::npy::read_npy(path)?;
    if array.shape != shape {
        return Err(CliError::Input(format!(
            "{}: {what} must have shape {shape:?}, found {:?}",
            path.display(),
            array.shape
        )));
    }
    if let Some(i) = array.data.iter().position(|x| !x.is_finite()) {
        return Err(CliError::Input(format!(
            "{}: {what} holds a non-finite number at flat index {i}",
            path.display()
        )));
    }
    Ok(array.data)
}
