//! A whole fit: stages run one after the other, each warm-started from the momenta at which the
//! one before ended (the paper's SSD initialisation towards an affine map, then Dice stages with
//! μ rising). All stages share one flow, so that their momenta are of one size.

use crate::fit::augmented_lagrangian::{
    run_stage, AlSchedule, Progress, Stage, StageCheckpoint, StageOutcome, StageRun, StageStart,
};
use crate::fit::optimize::LbfgsOptions;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

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

/// A fit paused after an accepted L-BFGS iterate: the outcomes of the stages before, and the
/// stage in progress ([`StageCheckpoint`]). Serialisable (serde) in full, every number as it
/// is: written in a format that keeps every `f64` bit (±∞ included), [`run_stages_resumable`]
/// from it ends with the very bits of a fit that never paused.
#[derive(Clone, Serialize, Deserialize)]
pub struct Checkpoint {
    completed: Vec<StageOutcome>,
    current: StageCheckpoint,
}

impl Checkpoint {
    /// Index of the stage in progress.
    pub fn stage(&self) -> usize {
        self.completed.len()
    }

    /// AL iteration in progress of that stage (0-based).
    pub fn al_iteration(&self) -> usize {
        self.current.al_iteration()
    }

    /// Accepted iterations of the minimisation in progress.
    pub fn iteration(&self) -> usize {
        self.current.iteration()
    }

    /// The outcome of every stage so far: those that ended, then the one in progress as it
    /// stands ([`StageCheckpoint::partial`]); the last holds the fit's momenta so far.
    pub fn outcomes(&self) -> Vec<StageOutcome> {
        let mut outcomes = self.completed.clone();
        outcomes.push(self.current.partial());
        outcomes
    }
}

impl std::fmt::Debug for Checkpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checkpoint")
            .field("stage", &self.stage())
            .field("al_iteration", &self.al_iteration())
            .field("iteration", &self.iteration())
            .finish_non_exhaustive()
    }
}

/// How [`run_stages_resumable`] ended.
pub enum FitRun {
    /// Every stage ran (or one ended unsound): the outcome of each stage run.
    Complete(Vec<StageOutcome>),
    /// `pause` asked for a stop: the checkpoint to resume from.
    Paused(Box<Checkpoint>),
}

/// Runs `stages` in order, the first from zero momenta, each later one from the momenta of the
/// one before; returns the outcome of every stage run (the last one holds the fit's momenta).
/// A stage that ends unsound ([`StageOutcome::unsound`]) is the last one run. `report` sees
/// every L-BFGS iteration and the end of every stage.
pub fn run_stages(
    stages: &[PlannedStage<'_>],
    report: impl FnMut(FitEvent<'_>),
) -> Result<Vec<StageOutcome>> {
    match run_stages_resumable(stages, None, &|| false, report)? {
        FitRun::Complete(outcomes) => Ok(outcomes),
        FitRun::Paused(_) => Err(Error::Optimisation(
            "a fit that is never asked to pause paused".into(),
        )),
    }
}

/// [`run_stages`] that can pause and resume: from the start (`from = None`) or from a
/// checkpoint of the same plan. After every accepted L-BFGS iterate at which no stopping rule
/// holds, `pause` is asked whether to stop there; if so, the fit returns [`FitRun::Paused`].
/// Resumed from that checkpoint, it reports the iterations and stage ends that follow (none
/// twice) and ends with the very bits, figures and counts of a fit that never paused.
///
/// Errors: those of [`run_stage`]; [`Error::InvalidParameter`] or [`Error::ShapeMismatch`]
/// for a checkpoint that does not fit `stages`.
pub fn run_stages_resumable(
    stages: &[PlannedStage<'_>],
    from: Option<Checkpoint>,
    pause: &dyn Fn() -> bool,
    mut report: impl FnMut(FitEvent<'_>),
) -> Result<FitRun> {
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
    let (mut outcomes, mut start) = match from {
        None => (
            Vec::with_capacity(stages.len()),
            StageStart::Momenta(vec![0.0; len]),
        ),
        Some(c) => {
            check_fits(&c, stages.len(), len)?;
            (c.completed, StageStart::Resume(Box::new(c.current)))
        }
    };
    for (index, planned) in stages.iter().enumerate().skip(outcomes.len()) {
        let run = run_stage(
            &planned.stage,
            &planned.schedule,
            &planned.lbfgs,
            start,
            pause,
            |progress| {
                report(FitEvent::Iteration {
                    stage: index,
                    progress,
                })
            },
        )?;
        let outcome = match run {
            StageRun::Done(outcome) => *outcome,
            StageRun::Paused(current) => {
                return Ok(FitRun::Paused(Box::new(Checkpoint {
                    completed: outcomes,
                    current: *current,
                })))
            }
        };
        report(FitEvent::StageEnd {
            stage: index,
            outcome: &outcome,
        });
        start = StageStart::Momenta(outcome.momenta.clone());
        let unsound = outcome.unsound.is_some();
        outcomes.push(outcome);
        if unsound {
            break;
        }
    }
    Ok(FitRun::Complete(outcomes))
}

/// A checkpoint of a plan of `stages` stages whose momenta have `len` numbers.
fn check_fits(c: &Checkpoint, stages: usize, len: usize) -> Result<()> {
    if c.stage() >= stages {
        return Err(Error::InvalidParameter(format!(
            "the checkpoint is in stage {} of a fit of {stages} stages",
            c.stage() + 1
        )));
    }
    if c.current.momenta_len() != len {
        return Err(Error::ShapeMismatch {
            what: "momenta of the checkpoint".into(),
            expected: len,
            found: c.current.momenta_len(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attachment::ssd::Ssd;
    use crate::fit::augmented_lagrangian::{CoarseTime, Constraints, Extend, Settle};
    use crate::fit::guard::Guard;
    use crate::fit::{MedialTolerance, ProgressRule, StopReason};
    use crate::flow::{Flow, FlowParams};
    use crate::model::{MedialConstraints, MedialTemplate};
    use crate::testing::meshes::bipyramid;
    use crate::Vec3;
    use std::cell::Cell;

    /// What a report says about an iteration, bit for bit (stage, AL iteration, iteration,
    /// evaluations, μ, E, time steps).
    type Row = (usize, usize, usize, usize, u64, u64, usize);

    /// Two stages on the hexagonal bipyramid: SSD without constraints towards its boundary
    /// rotated, stretched and shifted, then constrained SSD over three AL iterations.
    struct Case {
        flow: Flow,
        initial: Vec<Vec3>,
        ssd: Ssd,
        template: MedialTemplate,
        constraints: MedialConstraints,
        guard: Guard,
        /// What the constrained stage's schedule judges its violation against.
        tolerance: MedialTolerance,
    }

    impl Case {
        fn new() -> Self {
            Self::with(1.1, 4)
        }

        /// The case with the target boundary scaled by `scale` and `time_steps` steps (1.1 and
        /// 4 in [`Case::new`]).
        fn with(scale: f64, time_steps: usize) -> Self {
            let t = bipyramid(0.4);
            let r = nalgebra::Rotation3::from_euler_angles(0.2, -0.1, 0.3);
            let targets = t
                .boundary_points()
                .iter()
                .map(|p| r * p * scale + Vec3::new(0.1, 0.0, -0.05));
            let params = FlowParams {
                sigma: 0.8,
                time_steps,
                kinetic_weight: 0.01,
            };
            Self {
                flow: Flow::new(params, t.landmark_count()).unwrap(),
                initial: t.landmarks().to_vec(),
                ssd: Ssd::new(targets.collect()).unwrap(),
                constraints: MedialConstraints::new(&t),
                guard: Guard::of_template(&t),
                template: t,
                tolerance: MedialTolerance::default(),
            }
        }

        /// [`Case::plan`] with the constrained stage coarse to fine in time, in half the steps
        /// in its first two AL iterations (of three).
        fn coarse_plan(&self) -> Vec<PlannedStage<'_>> {
            let mut plan = self.plan();
            plan[1].schedule.coarse = Some(CoarseTime {
                time_steps: self.flow.time_steps() / 2,
                al_iterations: 2,
            });
            plan
        }

        /// [`Case::plan`] with the constrained stage scheduled for two AL iterations and
        /// extended by up to two while on course: whether the last goes on depends on the
        /// violation the AL iteration before it ended at.
        fn extended_plan(&self) -> Vec<PlannedStage<'_>> {
            let mut plan = self.plan();
            plan[1].schedule.iterations = 2;
            plan[1].schedule.extend = Some(Extend {
                above: 0.0,
                at_most: 2,
            });
            plan
        }

        /// The constrained stage's constraints, judged against the case's tolerance.
        fn constraints(&self) -> Constraints<'_> {
            Constraints {
                set: &self.constraints,
                template: &self.template,
                tolerance: self.tolerance,
            }
        }

        fn plan(&self) -> Vec<PlannedStage<'_>> {
            let stage = |constraints| Stage {
                flow: &self.flow,
                initial: &self.initial,
                attachment: &self.ssd,
                data_weight: 1.0,
                constraints,
                guard: Some(&self.guard),
            };
            let lbfgs = LbfgsOptions {
                max_iterations: 12,
                memory: 4,
                ..LbfgsOptions::default()
            };
            vec![
                PlannedStage {
                    stage: stage(None),
                    schedule: AlSchedule::default(),
                    lbfgs,
                },
                PlannedStage {
                    stage: stage(Some(self.constraints())),
                    schedule: AlSchedule {
                        mu: 1.0,
                        mu_factor: 10.0,
                        iterations: 3,
                        first_iterations: Some(16),
                        ..AlSchedule::default()
                    },
                    // The progress rule's history survives a pause too.
                    lbfgs: LbfgsOptions {
                        progress: Some(ProgressRule {
                            window: 4,
                            decrease: 1e-3,
                        }),
                        ..lbfgs
                    },
                },
            ]
        }
    }

    /// Runs the plan from `from`, pausing when `pause(rows so far)` says so; appends a row per
    /// reported iteration.
    fn run(
        plan: &[PlannedStage<'_>],
        from: Option<Checkpoint>,
        pause: impl Fn(usize) -> bool,
        rows: &mut Vec<Row>,
    ) -> FitRun {
        let count = Cell::new(rows.len());
        let paused = || pause(count.get());
        let result = run_stages_resumable(plan, from, &paused, |event| {
            if let FitEvent::Iteration { stage, progress } = event {
                let r = progress.report;
                rows.push((
                    stage,
                    progress.al_iteration,
                    r.iteration,
                    r.evaluations,
                    progress.mu.to_bits(),
                    r.evaluation.total.to_bits(),
                    progress.time_steps,
                ));
                count.set(count.get() + 1);
            }
        });
        result.unwrap()
    }

    /// Through postcard and back, as the command line stores it; the bytes survive a second
    /// round trip unchanged (every number kept, ±∞ included).
    fn round_trip(c: &Checkpoint) -> Checkpoint {
        let bytes = postcard::to_stdvec(c).unwrap();
        let back: Checkpoint = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(postcard::to_stdvec(&back).unwrap(), bytes);
        back
    }

    /// Everything of each outcome, every number to the bit.
    fn bits(outcomes: &[StageOutcome]) -> Vec<String> {
        let to_bits = |x: &[f64]| x.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        outcomes
            .iter()
            .map(|o| {
                format!(
                    "{:?} {:?} {} {} {:?} {:?}",
                    to_bits(&o.momenta),
                    to_bits(&o.lambda),
                    o.iterations,
                    o.evaluations,
                    o.stops,
                    o.evaluation
                )
            })
            .collect()
    }

    fn complete(run: FitRun) -> Vec<StageOutcome> {
        match run {
            FitRun::Complete(outcomes) => outcomes,
            FitRun::Paused(c) => panic!("paused at {c:?}"),
        }
    }

    /// An unsound iterate makes L-BFGS back off and restart with fresh memory, up to
    /// `max_restarts` times; with 0 the first one ends the minimisation (a start's trial).
    /// Here every iterate that lowers the objective by more than a tenth is refused.
    #[test]
    fn a_minimisation_restarts_after_an_unsound_iterate_up_to_its_limit() {
        use crate::fit::objective::{Evaluation, Objective};
        use crate::fit::optimize::{minimize, Minimization, Start};
        let case = Case::new();
        let objective = Objective::new(&case.flow, &case.initial, &case.ssd, 1.0);
        let start = objective
            .evaluate(&vec![0.0; case.flow.momenta_len()], None)
            .unwrap();
        let check = |e: &Evaluation| match e.total < 0.9 * start.total {
            true => Err(crate::fit::Unsound::NonFinite("a test's refusal".into())),
            false => Ok(()),
        };
        let run = |max_restarts| {
            let options = LbfgsOptions {
                max_iterations: 50,
                max_restarts,
                ..LbfgsOptions::default()
            };
            let zero = Start::Momenta(vec![0.0; case.flow.momenta_len()]);
            match minimize(&objective, zero, &options, check, &|| false, |_| {}).unwrap() {
                Minimization::Done(m) => m,
                Minimization::Paused(_) => unreachable!("never asked to pause"),
            }
        };
        let (once, default) = (run(0), run(LbfgsOptions::default().max_restarts));
        assert!(
            matches!(once.stop, StopReason::Unsound(_)),
            "{:?}",
            once.stop
        );
        assert_eq!(once.restarts, 0);
        assert!(
            matches!(default.stop, StopReason::Unsound(_)),
            "{:?}",
            default.stop
        );
        assert!(default.restarts > 0, "{default:?}");
        assert!(once.evaluations < default.evaluations);
        for m in [&once, &default] {
            assert!(m.evaluation.total >= 0.9 * start.total);
        }
    }

    #[test]
    fn a_fit_paused_anywhere_and_resumed_ends_with_the_same_bits() {
        let case = Case::new();
        paused_anywhere_and_resumed(&case.plan());
        paused_anywhere_and_resumed(&case.coarse_plan());
    }

    fn paused_anywhere_and_resumed(plan: &[PlannedStage<'_>]) {
        let mut baseline_rows = Vec::new();
        let baseline = complete(run(plan, None, |_| false, &mut baseline_rows));
        assert_eq!(baseline.len(), 2);
        assert_eq!(baseline[1].al_iterations, 3);
        let first_of = |stage: usize, al: usize| {
            baseline_rows
                .iter()
                .position(|r| r.0 == stage && r.1 == al)
                .unwrap()
        };
        // Early in the first stage, the second AL iteration of the second stage, and late in it.
        for at in [2, first_of(1, 1) + 3, baseline_rows.len() - 3] {
            let mut rows = Vec::new();
            let FitRun::Paused(checkpoint) = run(plan, None, |n| n >= at, &mut rows) else {
                panic!("no pause at row {at}");
            };
            assert_eq!(rows.len(), at, "paused right after the asked row");
            let partial = checkpoint.outcomes();
            let len = plan[0].stage.flow.momenta_len();
            assert!(
                partial.iter().all(|o| o.momenta.len() == len),
                "in the stage's steps"
            );
            assert_eq!(
                partial.last().unwrap().stops.last(),
                Some(&StopReason::Paused)
            );
            let resumed = complete(run(
                plan,
                Some(round_trip(&checkpoint)),
                |_| false,
                &mut rows,
            ));
            assert_eq!(rows, baseline_rows, "paused at row {at}");
            assert_eq!(bits(&resumed), bits(&baseline), "paused at row {at}");
        }
    }

    #[test]
    fn a_fit_paused_after_every_iterate_ends_with_the_same_bits() {
        let case = Case::new();
        paused_after_every_iterate(&case.plan());
        paused_after_every_iterate(&case.coarse_plan());
        // Coarse AL iterations that go on in coarse steps (the case above leaves them).
        paused_after_every_iterate(&Case::with(1.1, 8).coarse_plan());
        // The extension's comparison with the AL iteration before survives a pause.
        paused_after_every_iterate(&case.extended_plan());
    }

    fn paused_after_every_iterate(plan: &[PlannedStage<'_>]) {
        let mut baseline_rows = Vec::new();
        let baseline = complete(run(plan, None, |_| false, &mut baseline_rows));
        let (mut rows, mut from, mut pauses) = (Vec::new(), None, 0);
        let outcomes = loop {
            match run(plan, from.take(), |_| true, &mut rows) {
                FitRun::Complete(outcomes) => break outcomes,
                FitRun::Paused(c) => {
                    pauses += 1;
                    from = Some(round_trip(&c));
                }
            }
        };
        assert!(pauses > 10, "{pauses} pauses");
        assert_eq!(rows, baseline_rows);
        assert_eq!(bits(&outcomes), bits(&baseline));
    }

    #[test]
    fn a_checkpoint_of_another_plan_is_refused() {
        let case = Case::new();
        let plan = case.plan();
        let mut rows = Vec::new();
        let at = 30;
        let FitRun::Paused(checkpoint) = run(&plan, None, |n| n >= at, &mut rows) else {
            panic!("no pause");
        };
        assert_eq!(checkpoint.stage(), 1, "row {at} is in the second stage");
        let one_stage = &plan[..1];
        let result = run_stages_resumable(one_stage, Some(*checkpoint.clone()), &|| false, |_| {});
        assert!(matches!(result, Err(Error::InvalidParameter(_))));
        // The same plan with a longer flow: the momenta do not fit.
        let other = Flow::new(
            FlowParams {
                sigma: 0.8,
                time_steps: 5,
                kinetic_weight: 0.01,
            },
            case.initial.len(),
        )
        .unwrap();
        let mut longer = plan.clone();
        longer.iter_mut().for_each(|p| p.stage.flow = &other);
        let result = run_stages_resumable(&longer, Some(*checkpoint), &|| false, |_| {});
        assert!(matches!(result, Err(Error::ShapeMismatch { .. })));
    }

    /// The constrained stage of the plan with its L-BFGS options and AL schedule changed, run
    /// from the template, and the totals it reported per AL iteration.
    fn constrained_run(
        case: &Case,
        change: impl Fn(&mut LbfgsOptions, &mut AlSchedule),
    ) -> (StageOutcome, Vec<Vec<f64>>) {
        let mut plan = case.plan();
        let mut stage = plan.remove(1);
        change(&mut stage.lbfgs, &mut stage.schedule);
        let mut totals: Vec<Vec<f64>> = Vec::new();
        let outcomes = run_stages(&[stage], |event| {
            if let FitEvent::Iteration { progress, .. } = event {
                if progress.report.iteration == 0 {
                    totals.push(Vec::new());
                }
                totals
                    .last_mut()
                    .unwrap()
                    .push(progress.report.evaluation.total);
            }
        })
        .unwrap();
        (outcomes.into_iter().next().unwrap(), totals)
    }

    #[test]
    fn the_progress_rule_stops_when_a_window_decreased_too_little() {
        let rule = ProgressRule {
            window: 3,
            decrease: 0.02,
        };
        let (outcome, totals) = constrained_run(&Case::new(), |lbfgs, schedule| {
            lbfgs.max_iterations = 500;
            lbfgs.progress = Some(rule);
            schedule.first_iterations = None;
        });
        assert!(
            outcome.stops.contains(&StopReason::Progress),
            "{:?}",
            outcome.stops
        );
        for (stop, e) in outcome.stops.iter().zip(&totals) {
            let k = e.len() - 1;
            let held =
                |k: usize| k >= 3 && e[k - 3] - e[k] <= 0.02 * e[k - 3].abs().max(e[k].abs());
            assert!(k < 500, "the rule ends the minimisation before its budget");
            assert!((3..k).all(|j| !held(j)), "it did not hold earlier");
            assert_eq!(*stop == StopReason::Progress, held(k), "{stop:?} at {k}");
        }
    }

    #[test]
    fn the_first_al_iteration_has_its_own_budget() {
        let (outcome, totals) = constrained_run(&Case::new(), |lbfgs, schedule| {
            lbfgs.relative_decrease = 0.0;
            lbfgs.gradient_tolerance = 0.0;
            lbfgs.progress = None;
            schedule.first_iterations = Some(5);
        });
        let iterations: Vec<usize> = totals.iter().map(|e| e.len() - 1).collect();
        assert_eq!(iterations, [5, 12, 12]);
        assert_eq!(outcome.iterations, 29);
    }

    /// Where each AL iteration of a run of `case`'s constrained stage ended (the last report of
    /// each minimisation is its optimum).
    #[derive(Clone, Copy, Debug)]
    struct AlEnd {
        max_abs_constraint: f64,
        /// [`Constraints::violation`] against the case's tolerance.
        violation: f64,
    }

    fn al_ends(case: &Case, change: impl Fn(&mut LbfgsOptions, &mut AlSchedule)) -> Vec<AlEnd> {
        let mut plan = case.plan();
        let mut stage = plan.remove(1);
        change(&mut stage.lbfgs, &mut stage.schedule);
        let constraints = case.constraints();
        let mut ends: Vec<AlEnd> = Vec::new();
        run_stages(&[stage], |event| {
            if let FitEvent::Iteration { progress, .. } = event {
                let e = progress.report.evaluation;
                let end = AlEnd {
                    max_abs_constraint: e.max_abs_constraint,
                    violation: constraints.violation(&e.final_positions),
                };
                match progress.report.iteration {
                    0 => ends.push(end),
                    _ => *ends.last_mut().unwrap() = end,
                }
            }
        })
        .unwrap();
        ends
    }

    #[test]
    fn a_schedule_that_settles_ends_at_the_first_al_iteration_where_it_does() {
        let budget = |lbfgs: &mut LbfgsOptions, schedule: &mut AlSchedule| {
            lbfgs.max_iterations = 12;
            schedule.first_iterations = None;
        };
        let all = al_ends(&Case::new(), budget);
        assert_eq!(all.len(), 3);
        let (c1, c2) = (all[1].max_abs_constraint, all[2].max_abs_constraint);
        assert!(c2 < c1, "the constraints tighten: {all:?}");
        // (rule, AL iterations run, settled): the last AL iteration may settle too.
        for (max_abs_constraint, data_change, ends_after, settled) in [
            (c1, 1.0, 2, true),
            (0.5 * (c1 + c2), 1.0, 3, true),
            (f64::INFINITY, 0.0, 3, false),
        ] {
            let settle = Settle {
                max_abs_constraint,
                data_change,
            };
            let (outcome, totals) = constrained_run(&Case::new(), |lbfgs, schedule| {
                budget(lbfgs, schedule);
                schedule.settle = Some(settle);
            });
            assert_eq!(totals.len(), ends_after, "{settle:?} on {all:?}");
            assert_eq!(outcome.al_iterations, ends_after);
            assert_eq!(outcome.settled, settled);
            assert!(!settled || outcome.converged());
        }
    }

    /// The rate rule on figures worked by hand: hippocampus t002's last AL iterations shrank
    /// its angle by 0.78 each, ending the schedule at 2.04°; four more at that rate meet 1°
    /// (0.755°), two do not (1.24°).
    #[test]
    fn a_schedule_is_on_course_when_its_last_rate_meets_the_tolerance_in_the_iterations_left() {
        let before = 2.04 / 0.78;
        assert!(Extend::on_course(before, 2.04, 4));
        assert!(Extend::on_course(before, 2.04, 3)); // 0.968
        assert!(!Extend::on_course(before, 2.04, 2)); // 1.24
                                                      // Stalled or worse: never on course, however many are left; the first is a decrease.
        assert!(!Extend::on_course(2.0, 2.0, 1000));
        assert!(!Extend::on_course(1.5, 2.0, 1000));
        assert!(Extend::on_course(f64::INFINITY, 50.0, 1));
        // Within the tolerance and still falling: on course.
        assert!(Extend::on_course(0.9, 0.8, 1));
        // A violation that cannot be judged (NaN) never extends.
        assert!(!Extend::on_course(1.0, f64::NAN, 4));
        assert!(!Extend::on_course(f64::NAN, 2.0, 4));
    }

    /// Past its AL iterations a schedule goes on while the violation (the spoke figures as a
    /// fit reports them, against the tolerance) is above the level and on course, at most
    /// `at_most` more. Which of the extensions run is decided by the tolerance the same
    /// violations are judged against: the same run extended or not.
    #[test]
    fn a_schedule_goes_on_while_its_violation_is_above_the_level_and_on_course() {
        let budget = |lbfgs: &mut LbfgsOptions, schedule: &mut AlSchedule| {
            lbfgs.max_iterations = 12;
            schedule.first_iterations = None;
            schedule.iterations = 4;
        };
        let v: Vec<f64> = al_ends(&Case::new(), budget)
            .iter()
            .map(|e| e.violation)
            .collect();
        assert!(v[1] < v[0] && v[2] < v[1], "the case converges: {v:?}");
        // Scheduled for 2, at most 2 more: after AL iteration 2 the rate v1/v0 over the 2 left
        // projects v1·(v1/v0)²; after AL iteration 3, v2·(v2/v1) over the one left. A
        // tolerance k times the default divides every violation by k.
        let first = v[1] * (v[1] / v[0]).powi(2);
        let second = v[2] * (v[2] / v[1]);
        // (tolerance factor, level, AL iterations run)
        for (k, above, runs) in [
            (0.9 * first, 0.0, 2),
            (1.1 * first, 0.0, if second <= 1.1 * first { 4 } else { 3 }),
            (1.1 * first.max(second), 0.0, 4),
            (1.1 * first, f64::INFINITY, 2),
            // Above the level after AL iteration 2, below it after 3.
            (
                1.1 * first.max(second),
                0.5 * (v[1] + v[2]) / (1.1 * first.max(second)),
                3,
            ),
        ] {
            let mut case = Case::new();
            case.tolerance.angle_deg *= k;
            case.tolerance.mismatch_pct *= k;
            let (outcome, totals) = constrained_run(&case, |lbfgs, schedule| {
                budget(lbfgs, schedule);
                schedule.iterations = 2;
                schedule.extend = Some(Extend { above, at_most: 2 });
            });
            assert_eq!(totals.len(), runs, "×{k} above {above} on {v:?}");
            assert_eq!(outcome.al_iterations, runs);
        }
    }

    /// The time steps of each AL iteration's minimisation as the reports give them.
    fn steps_per_al_iteration(rows: &[Row]) -> Vec<usize> {
        let mut steps: Vec<usize> = Vec::new();
        for r in rows.iter().filter(|r| r.0 == 1) {
            match r.2 {
                0 => steps.push(r.6),
                _ => assert_eq!(Some(&r.6), steps.last(), "one flow per minimisation"),
            }
        }
        steps
    }

    #[test]
    fn coarse_al_iterations_run_in_coarse_steps_and_the_last_in_the_stages() {
        // In 4 steps the coarse flow strains space by less than 0.5 (in 2 it does not).
        let case = Case::with(1.1, 8);
        let (mut fine_rows, mut coarse_rows) = (Vec::new(), Vec::new());
        let fine = complete(run(&case.plan(), None, |_| false, &mut fine_rows));
        let coarse = complete(run(&case.coarse_plan(), None, |_| false, &mut coarse_rows));
        assert_eq!(steps_per_al_iteration(&fine_rows), [8, 8, 8]);
        assert_eq!(steps_per_al_iteration(&coarse_rows), [4, 4, 8]);
        let (f, c) = (&fine[1], &coarse[1]);
        assert_eq!((c.coarse_al_iterations, c.strained_iterations), (2, 0));
        assert_eq!(c.momenta.len(), f.momenta.len());
        assert_eq!(c.lambda.len(), f.lambda.len());
        // The same stage (after the same first stage), ended in the same steps, no worse for
        // its cheaper AL iterations (of 12 iterations each: not converged either way).
        assert_eq!(bits(&fine[..1]), bits(&coarse[..1]));
        let e = (&f.evaluation, &c.evaluation);
        assert!(e.1.data <= 1.2 * e.0.data, "{e:?}");
        assert!(
            e.1.max_abs_constraint <= 2.0 * e.0.max_abs_constraint.max(1e-3),
            "{e:?}"
        );
        // Its figures are those of its momenta in the stage's flow.
        let objective = crate::fit::Objective::new(&case.flow, &case.initial, &case.ssd, 1.0);
        let again = objective.evaluate(&c.momenta, None).unwrap();
        assert_eq!(again.data.to_bits(), c.evaluation.data.to_bits());
    }

    #[test]
    fn a_coarse_flow_that_strains_space_runs_again_in_the_stages_steps() {
        // Scaled threefold, the coarse flow's 2 steps strain space by more than 0.5 within 10
        // iterations: the AL iteration starts again in 4 steps, where the stage without coarse
        // steps starts, and ends with its very bits (only the counters differ).
        let case = Case::with(3.0, 4);
        let (mut fine_rows, mut coarse_rows) = (Vec::new(), Vec::new());
        let fine = complete(run(&case.plan(), None, |_| false, &mut fine_rows));
        let coarse = complete(run(&case.coarse_plan(), None, |_| false, &mut coarse_rows));
        assert_eq!(steps_per_al_iteration(&coarse_rows), [2, 4, 4, 4]);
        let dropped = coarse_rows.iter().filter(|r| r.6 == 2).count();
        assert_eq!(dropped, 11, "iterations 0 … 10 of the coarse minimisation");
        let (f, c) = (&fine[1], &coarse[1]);
        let to_bits = |x: &[f64]| x.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(to_bits(&c.momenta), to_bits(&f.momenta));
        assert_eq!(to_bits(&c.lambda), to_bits(&f.lambda));
        assert_eq!(c.evaluation, f.evaluation);
        assert_eq!(c.iterations, f.iterations + 10);
        assert_eq!((c.coarse_al_iterations, c.strained_iterations), (0, 10));
        assert!(c.evaluations > f.evaluations);
        assert_eq!(c.al_iterations, f.al_iterations);
    }
}
