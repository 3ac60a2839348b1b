//! A whole fit: stages run one after the other, each warm-started from the momenta at which the
//! one before ended (the paper's SSD initialisation towards an affine map, then Dice stages with
//! μ rising). All stages share one flow, so that their momenta are of one size.

use crate::fit::augmented_lagrangian::{run_stage, AlSchedule, Progress, Stage, StageOutcome};
use crate::fit::optimize::LbfgsOptions;
use crate::{Error, Result};

/// A stage with its schedule: what [`run_stage`] needs besides the starting momenta.
#[derive(Clone, Copy)]
pub struct PlannedStage<'a> {
    /// Flow, initial landmarks, attachment, constraints.
    pub stage: Stage<'a>,
    /// The μ schedule (used when the stage has constraints).
    pub schedule: AlSchedule,
    /// Options of each L-BFGS minimisation.
    pub lbfgs: LbfgsOptions,
}

/// What [`run_stages`] reports while it runs.
#[derive(Clone, Copy)]
pub enum FitEvent<'e> {
    /// An L-BFGS iteration of the stage with index `stage`.
    Iteration {
        /// Index of the stage in the plan.
        stage: usize,
        /// Where the iteration sits in the stage's schedule.
        progress: &'e Progress<'e>,
    },
    /// The stage with index `stage` ended.
    StageEnd {
        /// Index of the stage in the plan.
        stage: usize,
        /// Its outcome.
        outcome: &'e StageOutcome,
    },
}

/// Runs `stages` in order, the first from zero momenta, each later one from the momenta of the
/// one before; returns the outcome of every stage run (the last one holds the fit's momenta).
/// A stage that ends unsound ([`StageOutcome::unsound`]) is the last one run. `report` sees
/// every L-BFGS iteration and the end of every stage.
pub fn run_stages(
    stages: &[PlannedStage<'_>],
    mut report: impl FnMut(FitEvent<'_>),
) -> Result<Vec<StageOutcome>> {
    let Some(first) = stages.first() else {
        return Err(Error::InvalidParameter(
            "a fit needs at least one stage".into(),
        ));
    };
    let len = first.stage.flow.momenta_len();
    if let Some(other) = stages.iter().find(|s| s.stage.flow.momenta_len() != len) {
        return Err(Error::ShapeMismatch {
            what: "momenta of the stages of one fit (one flow for all)".into(),
            expected: len,
            found: other.stage.flow.momenta_len(),
        });
    }
    let mut momenta = vec![0.0; len];
    let mut outcomes = Vec::with_capacity(stages.len());
    for (index, planned) in stages.iter().enumerate() {
        let outcome = run_stage(
            &planned.stage,
            &planned.schedule,
            &planned.lbfgs,
            momenta,
            |progress| {
                report(FitEvent::Iteration {
                    stage: index,
                    progress,
                })
            },
        )?;
        report(FitEvent::StageEnd {
            stage: index,
            outcome: &outcome,
        });
        momenta = outcome.momenta.clone();
        let unsound = outcome.unsound.is_some();
        outcomes.push(outcome);
        if unsound {
            break;
        }
    }
    Ok(outcomes)
}
