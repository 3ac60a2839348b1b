//! Candidate starts of an automatic fit judged by a short trial of the flow (decision 0037).
//!
//! The initial alignment offers more than one place to start where the moments of filled shapes
//! cannot tell them apart: the template carried by the alignment, the same with its wall
//! thickened to the foreground's ([`crate::fit::initial::thickened`]), and the template where it
//! was given (no move: moments can mislead on a thin or partial shape). Their starting overlaps
//! say where each begins, not where the flow takes it: a thicker start overlaps more but may
//! fold; a start that overlaps less may be a shorter way. Each is judged by what the fit itself
//! reaches from it in its first progress window ([`trial_spec`]): the same stage, the same flow,
//! the same first penalty weight, for [`ProgressRule::window`] L-BFGS iterations. The start
//! whose trial ends at the lowest objective `E_AL` is taken; a start whose trial ends unsound
//! (a fold, a flow past its strain limit) is not. The winner's fit then starts afresh from it
//! (the trial is a judge, not a stage: a fit runs the same from the same start however it was
//! chosen); only the data its first stage prepared (an image read and smoothed) serves the fit
//! again ([`Choice::prepared`]).
//!
//! ```no_run
//! use medial_core::fit::trial::{choose, Candidate};
//! use medial_core::fit::{plan, Target};
//! use medial_core::memory::MemoryLimit;
//! use medial_core::model::Model;
//! # fn read() -> (Model, Model, medial_core::image::Volume) { unimplemented!() }
//! let (aligned, given, segmentation) = read();
//! let target = Target::Image { volume: segmentation, label: None };
//! let spec = plan::automatic(&aligned, &target).unwrap();
//! let candidates = vec![
//!     Candidate::new("aligned", aligned, nalgebra::Matrix4::identity()),
//!     Candidate::new("as given", given, nalgebra::Matrix4::identity()),
//! ];
//! let choice = choose(candidates, &spec, &target, None, MemoryLimit::none()).unwrap();
//! println!("{} ({} trials)", choice.taken.name, choice.trials.len());
//! ```

use crate::fit::optimize::ProgressRule;
use crate::fit::prepare::{PreparedStage, Target};
use crate::fit::run::Fit;
use crate::fit::spec::FitSpec;
use crate::image::rasterize::voxel_dice;
use crate::image::Volume;
use crate::memory::MemoryLimit;
use crate::model::Model;
use crate::{Error, Result};
use nalgebra::Matrix4;
use serde::Serialize;

/// L-BFGS iterations of a trial where the fit's first stage has no progress rule (its window
/// otherwise): the window over which a first AL iteration judges its own progress.
pub const TRIAL_ITERATIONS: usize = 40;

/// A start an automatic fit may take.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// What it is, in words ("aligned", "thickened 1.51×", "as given").
    pub name: String,
    /// The model the fit would start from.
    pub model: Model,
    /// The map that carries the given template's space to this start's (template → subject).
    pub alignment: Matrix4<f64>,
    /// Its voxel Dice against the target's foreground, where the caller has it already (none:
    /// the trial measures it).
    pub overlap: Option<f64>,
}

impl Candidate {
    /// The start `model`, carried from the given template by `alignment`, called `name`.
    pub fn new(name: impl Into<String>, model: Model, alignment: Matrix4<f64>) -> Self {
        Self {
            name: name.into(),
            model,
            alignment,
            overlap: None,
        }
    }
}

/// What a short trial of the flow from one candidate start reached.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StartTrial {
    /// The candidate's name ([`Candidate::name`]).
    pub start: String,
    /// Against an image: the voxel Dice of the start's boundary.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voxel_dice_start: Option<f64>,
    /// Against an image: the voxel Dice at the end of the trial's flow.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voxel_dice: Option<f64>,
    /// `E_AL` at the end of the trial (the fit's first objective); none when it ended unsound.
    pub objective: Option<f64>,
    /// L-BFGS iterations run.
    pub iterations: usize,
    /// Value + gradient evaluations run.
    pub evaluations: usize,
    /// Wall-clock time of the trial, its preparation and overlaps included, s.
    pub seconds: f64,
    /// Why the trial ended unsound, or could not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unsound: Option<String>,
    /// Whether the fit starts from this candidate.
    pub taken: bool,
}

/// The fit of `spec` cut to its first progress window: its first stage's first AL iteration
/// for the stage's [`ProgressRule::window`] L-BFGS iterations (else [`TRIAL_ITERATIONS`]), in
/// the coarse time steps where that AL iteration would run coarse, with no extension or
/// settling, ending at its first unsound iterate (a start whose trial folds is not taken, so
/// nothing is gained by backing off and trying again). What the trials of two starts reach is then what the fit would have reached from
/// each at that point.
pub fn trial_spec(spec: &FitSpec) -> Result<FitSpec> {
    let first = spec
        .stages
        .first()
        .ok_or_else(|| Error::InvalidParameter("a fit without stages has nothing to try".into()))?;
    let mut stage = first.clone();
    let window = stage
        .lbfgs
        .progress
        .map_or(TRIAL_ITERATIONS, |p: ProgressRule| p.window);
    stage.lbfgs.max_iterations = window;
    stage.lbfgs.progress = None;
    stage.lbfgs.max_restarts = 0;
    stage.schedule.first_iterations = Some(window);
    stage.schedule.iterations = 1;
    stage.schedule.extend = None;
    stage.schedule.settle = None;
    let mut flow = spec.flow;
    if let Some(coarse) = stage.schedule.coarse.take() {
        flow.time_steps = coarse.time_steps;
    }
    Ok(FitSpec {
        flow,
        stages: vec![stage],
    })
}

/// The trial of `candidate` ([`trial_spec`] of `spec`) against `target`, whose foreground is
/// `mask` for an image; the stages prepared for an earlier candidate of the same topology in
/// `shared` serve it too (the image smoothed once), and a candidate that prepares afresh leaves
/// its own there. A trial that ends unsound or fails to run is reported so; only a memory limit
/// (which every candidate would meet alike) is an error. Its `seconds` are the caller's.
fn run_trial(
    candidate: &Candidate,
    spec: &FitSpec,
    target: &Target,
    mask: Option<&Volume>,
    shared: &mut Option<Fit>,
    memory: MemoryLimit,
) -> Result<StartTrial> {
    // The voxel Dice of the candidate's boundary with its landmarks at `q`.
    let dice_of = |q: &[crate::Vec3]| -> Option<f64> {
        let mask = mask?;
        let boundary = match &candidate.model {
            Model::Medial(t) => t.with_landmarks(q).ok()?.boundary_mesh().ok()?,
            Model::Plain(m) => crate::TriMesh::new(q.to_vec(), m.triangles().to_vec()).ok()?,
        };
        voxel_dice(&boundary, mask).ok()
    };
    let mut trial = StartTrial {
        start: candidate.name.clone(),
        voxel_dice_start: (candidate.overlap).or_else(|| dice_of(candidate.model.landmarks())),
        voxel_dice: None,
        objective: None,
        iterations: 0,
        evaluations: 0,
        seconds: 0.0,
        unsound: None,
        taken: false,
    };
    if trial.voxel_dice_start == Some(0.0) {
        trial.unsound = Some("its boundary does not overlap the foreground".into());
        return Ok(trial);
    }
    let reused = (shared.as_ref()).and_then(|fit| fit.for_model(candidate.model.clone()).ok());
    let fit: &Fit = match &reused {
        Some(fit) => fit,
        None => match Fit::prepare(spec, candidate.model.clone(), vec![target.clone()], memory) {
            Ok(fit) => shared.insert(fit),
            Err(e @ Error::Memory { .. }) => return Err(e),
            Err(e) => {
                trial.unsound = Some(e.to_string());
                return Ok(trial);
            }
        },
    };
    let outcome = match fit.run(|_| {}) {
        Ok(mut outcomes) => outcomes.pop().expect("one stage"),
        Err(e) => {
            trial.unsound = Some(e.to_string());
            return Ok(trial);
        }
    };
    trial.iterations = outcome.iterations;
    trial.evaluations = outcome.evaluations;
    if let Some(stop) = &outcome.unsound {
        trial.unsound = Some(format!(
            "unsound at L-BFGS iteration {}: {}",
            stop.iteration, stop.cause
        ));
        return Ok(trial);
    }
    trial.objective = Some(outcome.evaluation.total);
    trial.voxel_dice = dice_of(&outcome.evaluation.final_positions);
    Ok(trial)
}

/// What [`choose`] decided.
pub struct Choice {
    /// The candidate taken.
    pub taken: Candidate,
    /// The other candidates, the order in which to try them where a fit from the one taken
    /// misses a part of its target ([`crate::fit::run::AutomaticStart::others`]): those whose
    /// trial was sound by their trials' objectives (lowest first; the order of preference on a
    /// tie), then those whose trial ran and ended unsound, in the order of preference. A
    /// candidate whose trial could not run (no overlap with the foreground, a model the stage
    /// refuses) is not among them.
    pub others: Vec<Candidate>,
    /// The trials that chose it; empty when there was one candidate.
    pub trials: Vec<StartTrial>,
    /// The trials' stage as they prepared it against the target (none without trials, or when
    /// none could be prepared): the fit's first stage takes its data from it
    /// ([`PreparedStage::for_stage`]) instead of reading and smoothing its image again.
    pub prepared: Option<PreparedStage>,
}

/// The candidate an automatic fit of `spec` to `target` starts from, and the trials that chose
/// it (see the module doc); `mask`, the target's foreground where it is an image, gives the
/// voxel Dice the trials report (none: not reported). One candidate is taken without a trial;
/// where no trial is sound the first candidate is taken (the fit's own recovery then deals with
/// its start). Candidates are in order of preference: the first wins a tie.
pub fn choose(
    mut candidates: Vec<Candidate>,
    spec: &FitSpec,
    target: &Target,
    mask: Option<&Volume>,
    memory: MemoryLimit,
) -> Result<Choice> {
    if candidates.len() <= 1 {
        let first = candidates
            .pop()
            .ok_or_else(|| Error::InvalidParameter("no candidate start to choose from".into()))?;
        return Ok(Choice {
            taken: first,
            others: Vec::new(),
            trials: Vec::new(),
            prepared: None,
        });
    }
    let short = trial_spec(spec)?;
    let mut shared = None;
    let mut trials = candidates
        .iter()
        .map(|c| {
            let clock = std::time::Instant::now();
            let mut trial = run_trial(c, &short, target, mask, &mut shared, memory)?;
            trial.seconds = clock.elapsed().as_secs_f64();
            Ok(trial)
        })
        .collect::<Result<Vec<_>>>()?;
    // The sound trials by objective; a stable sort keeps the order of preference on a tie.
    let mut ranked: Vec<(usize, f64)> = (trials.iter().enumerate())
        .filter_map(|(i, t)| t.objective.map(|e| (i, e)))
        .collect();
    ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
    let best = ranked.first().map_or(0, |&(i, _)| i);
    trials[best].taken = true;
    let mut candidates: Vec<Option<Candidate>> = candidates.into_iter().map(Some).collect();
    let taken = candidates[best]
        .take()
        .expect("each candidate is taken once");
    let sound: Vec<Candidate> = (ranked.iter())
        .filter_map(|&(i, _)| candidates[i].take())
        .collect();
    // Then those whose trial ran and ended unsound, in the order of preference: a trial runs
    // with the fit's first settings, and a fold there is what the fit's own retries with safer
    // settings are for ([`crate::fit::plan::safer`]). A start whose trial could not run (no
    // overlap, a model the stage refuses) is never tried.
    let unsound = (candidates.into_iter().zip(&trials))
        .filter(|(_, t)| t.evaluations > 0)
        .filter_map(|(c, _)| c);
    let others = sound.into_iter().chain(unsound).collect();
    Ok(Choice {
        taken,
        others,
        trials,
        prepared: shared.and_then(|fit| fit.into_stages().pop()),
    })
}

/// One line of notes for `trials` (empty when there was none): each start's overlap before and
/// after its trial, its objective, and which was taken.
pub fn describe(trials: &[StartTrial]) -> Option<String> {
    trials.first()?;
    let each: Vec<String> = trials
        .iter()
        .map(|t| {
            let dice = match (t.voxel_dice_start, t.voxel_dice) {
                (Some(a), Some(b)) => format!("voxel Dice {a:.3} → {b:.3}, "),
                (Some(a), None) => format!("voxel Dice {a:.3}, "),
                _ => String::new(),
            };
            let end = match (&t.unsound, t.objective) {
                (Some(why), _) => format!("not taken: {why}"),
                (None, Some(e)) => format!("E_AL {e:.4}"),
                (None, None) => "no objective".into(),
            };
            let taken = if t.taken { " [taken]" } else { "" };
            format!("{}: {dice}{end}{taken}", t.start)
        })
        .collect();
    Some(format!(
        "start chosen by a trial of the fit's first progress window from each candidate \
         ({} evaluations, {:.1} s in all): {}",
        trials.iter().map(|t| t.evaluations).sum::<usize>(),
        trials.iter().map(|t| t.seconds).sum::<f64>(),
        each.join("; ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::plan;
    use crate::image::rasterize::{grid_around, rasterize};
    use crate::model::MedialTemplate;
    use crate::testing::meshes::bipyramid;
    use crate::Vec3;

    /// The hexagonal bipyramid of half thickness `r` (× 10 mm), moved by `shift` mm.
    fn sheet(r: f64, shift: Vec3) -> MedialTemplate {
        let t = bipyramid(r);
        let moved: Vec<Vec3> = t.landmarks().iter().map(|p| p * 10.0 + shift).collect();
        t.with_landmarks(&moved).unwrap()
    }

    /// The segmentation of the bipyramid of half thickness 7 mm at 1 mm voxels.
    fn target() -> Target {
        let boundary = sheet(0.7, Vec3::zeros()).boundary_mesh().unwrap();
        let (dims, grid) = grid_around(&boundary, 1.0, 4.0).unwrap();
        Target::Image {
            volume: rasterize(&boundary, dims, grid).unwrap(),
            label: None,
        }
    }

    /// The foreground of an image target.
    fn mask(target: &Target) -> Volume {
        match target {
            Target::Image { volume, label } => volume.foreground(*label),
            _ => unreachable!("the tests' targets are images"),
        }
    }

    fn medial(name: &str, t: MedialTemplate) -> Candidate {
        Candidate::new(name, Model::Medial(Box::new(t)), Matrix4::identity())
    }

    /// A trial is the fit's first progress window: one AL iteration of the first stage for the
    /// window's iterations, in the coarse steps that AL iteration would run in, nothing added.
    #[test]
    fn a_trial_is_the_first_progress_window_of_the_fit() {
        let model = Model::Medial(Box::new(sheet(0.5, Vec3::zeros())));
        let spec = plan::automatic(&model, &target()).unwrap();
        let trial = trial_spec(&spec).unwrap();
        let (first, cut) = (&spec.stages[0], &trial.stages[0]);
        let window = first.lbfgs.progress.unwrap().window;
        assert_eq!(trial.stages.len(), 1);
        assert_eq!(cut.lbfgs.max_iterations, window);
        assert_eq!(cut.schedule.first_iterations, Some(window));
        assert_eq!(cut.schedule.iterations, 1);
        assert!(cut.schedule.extend.is_none() && cut.schedule.settle.is_none());
        assert!(cut.schedule.coarse.is_none());
        assert_eq!(cut.lbfgs.max_restarts, 0);
        assert_eq!(
            trial.flow.time_steps,
            first.schedule.coarse.unwrap().time_steps
        );
        assert_eq!(cut.schedule.mu, first.schedule.mu);
        assert_eq!(trial.flow.sigma, spec.flow.sigma);
        trial.check().unwrap();
    }

    /// Of a start off the foreground, one that cannot run (a plain mesh for a Dice fit), a thin
    /// one and one of the wall's own thickness, the trial takes the one whose trial ends at the
    /// lowest objective, in either order; the others are reported with why they were not taken.
    #[test]
    fn the_trial_takes_the_start_whose_first_window_ends_lowest_in_either_order() {
        let target = target();
        let model = Model::Medial(Box::new(sheet(0.5, Vec3::zeros())));
        let spec = plan::automatic(&model, &target).unwrap();
        let plain = Candidate::new(
            "plain",
            Model::Plain(sheet(0.7, Vec3::zeros()).boundary_mesh().unwrap()),
            Matrix4::identity(),
        );
        let mut candidates = vec![
            medial("away", sheet(0.5, Vec3::new(60.0, 0.0, 0.0))),
            plain,
            medial("thin", sheet(0.5, Vec3::zeros())),
            medial("wall", sheet(0.7, Vec3::zeros())),
        ];
        let Choice {
            taken,
            others,
            trials,
            prepared,
        } = choose(
            candidates.clone(),
            &spec,
            &target,
            Some(&mask(&target)),
            MemoryLimit::none(),
        )
        .unwrap();
        let by_name = |name: &str| trials.iter().find(|t| t.start == name).unwrap();
        let (away, plain, thin, wall) = (
            by_name("away"),
            by_name("plain"),
            by_name("thin"),
            by_name("wall"),
        );
        assert!(
            away.unsound
                .as_deref()
                .is_some_and(|m| m.contains("overlap")),
            "{away:?}"
        );
        assert!(
            plain
                .unsound
                .as_deref()
                .is_some_and(|m| m.contains("medial")),
            "{plain:?}"
        );
        assert_eq!((away.evaluations, plain.evaluations), (0, 0));
        assert_eq!(away.voxel_dice_start, Some(0.0));
        // The stage the trials prepared is handed on for the fit (the image smoothed once).
        assert!(prepared.is_some_and(|p| p.mask.is_some()));
        for t in [thin, wall] {
            assert!(t.evaluations > 0 && t.unsound.is_none(), "{t:?}");
            assert!(t.voxel_dice.unwrap() > 0.95, "{t:?}");
        }
        // The thin start is carried most of the way in the window.
        assert!(thin.voxel_dice.unwrap() > thin.voxel_dice_start.unwrap() + 0.2);
        let lowest = if thin.objective < wall.objective {
            thin
        } else {
            wall
        };
        assert_eq!(taken.name, lowest.start);
        assert!(lowest.taken);
        // The other sound start is the one to try next; never one whose trial could not run
        // (the start off the foreground, the plain mesh a Dice stage refuses).
        let other = if lowest.start == thin.start {
            wall
        } else {
            thin
        };
        let names: Vec<&str> = others.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, [other.start.as_str()]);
        assert_eq!(trials.iter().filter(|t| t.taken).count(), 1, "{trials:?}");
        let line = describe(&trials).unwrap();
        assert!(
            line.contains(&format!("{}: voxel Dice", taken.name)),
            "{line}"
        );
        assert!(
            line.contains("away: voxel Dice 0.000, not taken: "),
            "{line}"
        );
        // Reversed, the thin and the wall starts swap which is prepared afresh and which
        // shares the other's prepared stage: the same objectives say sharing changes no bit.
        candidates.reverse();
        let Choice {
            taken: again,
            trials: reversed,
            ..
        } = choose(
            candidates,
            &spec,
            &target,
            Some(&mask(&target)),
            MemoryLimit::none(),
        )
        .unwrap();
        assert_eq!(again.name, taken.name);
        let objectives = |t: &[StartTrial]| {
            let mut o: Vec<_> = t.iter().map(|t| (t.start.clone(), t.objective)).collect();
            o.sort_by(|a, b| a.0.cmp(&b.0));
            o
        };
        assert_eq!(objectives(&reversed), objectives(&trials));
    }

    /// Equal trials: the first candidate (the preferred one) is taken, the second is next; one
    /// candidate is taken without a trial and leaves none to try next.
    #[test]
    fn a_tie_goes_to_the_first_and_one_candidate_needs_no_trial() {
        let target = target();
        let model = Model::Medial(Box::new(sheet(0.5, Vec3::zeros())));
        let spec = plan::automatic(&model, &target).unwrap();
        let same = || medial("same", sheet(0.6, Vec3::zeros()));
        let mut second = same();
        second.name = "second".into();
        let Choice {
            taken,
            others,
            trials,
            ..
        } = choose(
            vec![same(), second],
            &spec,
            &target,
            None,
            MemoryLimit::none(),
        )
        .unwrap();
        assert_eq!(taken.name, "same");
        assert_eq!(trials[0].objective, trials[1].objective);
        assert_eq!(others.len(), 1);
        assert_eq!(others[0].name, "second");
        let Choice {
            taken,
            others,
            trials,
            ..
        } = choose(vec![same()], &spec, &target, None, MemoryLimit::none()).unwrap();
        assert_eq!(taken.name, "same");
        assert!(trials.is_empty() && describe(&trials).is_none() && others.is_empty());
    }
}
