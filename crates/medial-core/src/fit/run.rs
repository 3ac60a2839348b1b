//! A whole fit made ready and run in memory: the model it starts from, the flow of a
//! [`FitSpec`], each stage prepared against its data, and the fold guard each stage needs
//! ([`Fit`]); and the automatic fit of a template to one target, its plan and initial alignment
//! included ([`automatic`]), which is what `medial fit --template T --image SEG` runs.
//!
//! ```no_run
//! use medial_core::fit::{run::automatic, Target};
//! use medial_core::memory::MemoryLimit;
//! use medial_core::model::Model;
//! # fn read() -> (medial_core::MedialTemplate, medial_core::image::Volume) { unimplemented!() }
//! let (template, segmentation) = read();
//! let target = Target::Image { volume: segmentation, label: None };
//! let start = automatic(&Model::Medial(Box::new(template)), &target, MemoryLimit::none()).unwrap();
//! let fit = start.fit(target, MemoryLimit::none()).unwrap();
//! let outcomes = fit.run(|_| {}).unwrap();
//! let fitted = fit.flow().shoot(fit.model().landmarks(), &outcomes.last().unwrap().momenta);
//! ```

use crate::construction::inflate::LIMIT_ROUNDS;
use crate::fit::augmented_lagrangian::{Constraints, Stage, StageOutcome};
use crate::fit::guard::Guard;
use crate::fit::initial::{
    align_template, initial_alignment, thickened, AlignedTemplate, InitialAlignment,
    THICKEN_AT_LEAST,
};
use crate::fit::plan::{self, Geometry};
use crate::fit::prepare::{PreparedStage, Target};
use crate::fit::spec::FitSpec;
use crate::fit::stages::{run_stages, FitEvent, PlannedStage};
use crate::fit::trial::{choose, describe, Candidate, StartTrial};
use crate::flow::Flow;
use crate::image::rasterize::voxel_dice;
use crate::memory::MemoryLimit;
use crate::mesh::PrincipalAxes;
use crate::model::MedialTemplate;
use crate::model::Model;
use crate::Result;
use nalgebra::Matrix4;

/// A fit ready to run: the model it starts from, its flow and its prepared stages.
pub struct Fit {
    model: Model,
    flow: Flow,
    stages: Vec<PreparedStage>,
    prisms: Guard,
    surface: Guard,
}

impl Fit {
    /// The fit of `model` by `flow` through `stages` (prepared for `model`).
    pub fn new(model: Model, flow: Flow, stages: Vec<PreparedStage>) -> Self {
        let (prisms, surface) = (Guard::new(&model), Guard::of_surface(&model));
        Self {
            model,
            flow,
            stages,
            prisms,
            surface,
        }
    }

    /// The fit of `spec` for `model`, each stage against its target (one per stage), within
    /// `memory` ([`FitSpec::flow_estimate`], [`PreparedStage::new`]).
    pub fn prepare(
        spec: &FitSpec,
        model: Model,
        targets: Vec<Target>,
        memory: MemoryLimit,
    ) -> Result<Self> {
        Self::prepare_sharing(spec, model, targets, memory, &[])
    }

    /// [`Fit::prepare`], each stage's data taken from `earlier` where it serves
    /// ([`PreparedStage::shared`]): stages prepared against the same target as every stage of
    /// `spec`.
    fn prepare_sharing(
        spec: &FitSpec,
        model: Model,
        targets: Vec<Target>,
        memory: MemoryLimit,
        earlier: &[PreparedStage],
    ) -> Result<Self> {
        spec.check()?;
        if targets.len() != spec.stages.len() {
            return Err(crate::Error::ShapeMismatch {
                what: "targets of the stages of a fit".into(),
                expected: spec.stages.len(),
                found: targets.len(),
            });
        }
        let k = model.landmarks().len();
        memory.check(&spec.flow_estimate(k), || {
            format!(
                "a fit of {} time steps × {k} landmarks",
                spec.flow.time_steps
            )
        })?;
        let flow = spec.flow.flow(k)?;
        let stages = spec
            .stages
            .iter()
            .zip(targets)
            .map(
                |(stage, target)| match PreparedStage::shared(earlier, stage, &model)? {
                    Some(shared) => Ok(shared),
                    None => PreparedStage::new(stage, &model, target, memory),
                },
            )
            .collect::<Result<Vec<_>>>()?;
        Ok(Self::new(model, flow, stages))
    }

    /// The same fit from `model`, a model of the same topology at other landmarks (another
    /// start): its stages' attachments and target data shared, not prepared again
    /// ([`PreparedStage::for_model`]).
    pub fn for_model(&self, model: Model) -> Result<Self> {
        let stages = (self.stages.iter())
            .map(|p| p.for_model(&model))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self::new(model, self.flow.clone(), stages))
    }

    /// The model the fit starts from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The flow.
    pub fn flow(&self) -> &Flow {
        &self.flow
    }

    /// The prepared stages.
    pub fn stages(&self) -> &[PreparedStage] {
        &self.stages
    }

    /// The prepared stages, the fit given up.
    pub fn into_stages(self) -> Vec<PreparedStage> {
        self.stages
    }

    /// The stages as the engine runs them ([`crate::fit::run_stages_resumable`]). Constrained
    /// and Dice stages rely on the medial points staying inside (Dice samples the prisms): their
    /// guard is the prisms' ([`Guard::new`]); the others only rely on the boundary surface
    /// ([`Guard::of_surface`]).
    pub fn planned(&self) -> Vec<PlannedStage<'_>> {
        self.stages
            .iter()
            .map(|p| PlannedStage {
                stage: Stage {
                    flow: &self.flow,
                    initial: self.model.landmarks(),
                    attachment: p.attachment.as_ref(),
                    data_weight: p.data_weight,
                    constraints: p.constraints.as_ref().zip(self.model.medial()).map(
                        |(set, template)| Constraints {
                            set,
                            template,
                            tolerance: p.tolerance,
                        },
                    ),
                    guard: Some(if p.constraints.is_some() || p.mask.is_some() {
                        &self.prisms
                    } else {
                        &self.surface
                    }),
                },
                schedule: p.schedule,
                lbfgs: p.lbfgs,
            })
            .collect()
    }

    /// Runs the stages in order ([`run_stages`]); `report` sees every L-BFGS iteration and the
    /// end of every stage. The last outcome holds the fit's momenta.
    pub fn run(&self, report: impl FnMut(FitEvent<'_>)) -> Result<Vec<StageOutcome>> {
        run_stages(&self.planned(), report)
    }
}

/// The thickened start of a fit of the aligned template `aligned` to a foreground that is
/// `ratio` times as thick (by volume, after the similarity), named with its factor: where the
/// ratio passes [`THICKEN_AT_LEAST`] (or its inverse), the template with its spokes scaled by
/// the ratio, or by less of it (ratio^{3/4}, ^{1/2}, ^{1/4}), the first that is sound
/// ([`thickened`]). The wall's thickness is then its own factor of the alignment rather than a
/// long way for the flow to go along the normals, where thin prisms fold; whether the fit
/// starts from it is for the trial to say ([`choose`]).
///
/// A uniform factor first: it changes the template's thickness and not its pattern (decision
/// 0037's addendum). Only where no uniform factor is sound (a narrow seam, a curved thin wall),
/// the factors again limited at the atoms where the sheet cannot hold them
/// ([`LIMIT_ROUNDS`]), so that the wall is thickened where it can be.
fn thicker_start(
    aligned: &MedialTemplate,
    ratio: f64,
    notes: &mut Vec<String>,
) -> Option<(String, MedialTemplate)> {
    if !(ratio.is_finite() && (ratio >= THICKEN_AT_LEAST || ratio <= 1.0 / THICKEN_AT_LEAST)) {
        return None;
    }
    let found = [0, LIMIT_ROUNDS].iter().find_map(|&rounds| {
        [1.0, 0.75, 0.5, 0.25]
            .iter()
            .map(|power| ratio.powf(*power))
            .find_map(|factor| {
                thickened(aligned, factor, rounds).map(|(t, limited)| match limited {
                    0 => (format!("thickened {factor:.2}×"), t),
                    n => (format!("thickened {factor:.2}× (limited at {n} atoms)"), t),
                })
            })
    });
    if found.is_none() {
        notes.push(format!(
            "the wall {ratio:.2}× as thick as the template: no thickened template (up to that \
             factor, limited where the sheet cannot hold it) is sound; the flow thickens it"
        ));
    }
    found
}

/// The least share of the best candidate's starting overlap (voxel Dice) at which a start is
/// tried at all ([`choose`]): a start must otherwise more than double its overlap in the
/// trial's window to be worth the trial, which no first window measured does (decision 0037).
pub const TRIAL_OVERLAP_SHARE: f64 = 0.5;

/// The candidate starts of a fit of `template` to the foreground `mask` (see
/// [`crate::fit::trial`]): `aligned` (the template carried by the initial map); the template
/// carried by the similarity alone where the affine map needed large projection moves
/// ([`AlignedTemplate::similarity`]); the latter (else the aligned one) thickened to the
/// foreground's wall ([`thicker_start`], `ratio` as thick); and the template where it was
/// given, projected onto its constraints where it is not medial, when the alignment moved it.
/// A start whose voxel Dice is under [`TRIAL_OVERLAP_SHARE`] of the best start's is not a
/// candidate (noted).
fn image_candidates(
    template: &MedialTemplate,
    aligned: AlignedTemplate,
    ratio: f64,
    mask: &crate::image::Volume,
    notes: &mut Vec<String>,
) -> Result<Vec<Candidate>> {
    let matrix = aligned.matrix;
    let similarity = (aligned.similarity).map(|(t, m)| ("similarity".to_string(), t, m));
    let aligned = aligned.template;
    // Thickened from the similarity where there is one: an affine map that needs large
    // projection moves may already be fitting the wall's thickness (decision 0201).
    let (thin, thin_matrix) = match &similarity {
        Some((_, t, m)) => (t, *m),
        None => (&aligned, matrix),
    };
    let thick = thicker_start(thin, ratio, notes).map(|(name, thick)| (name, thick, thin_matrix));
    let unmoved = (matrix != Matrix4::identity())
        .then(|| {
            let unmoved = InitialAlignment::similarity(Matrix4::identity(), Vec::new());
            align_template(template, &unmoved)
                .map(|a| ("as given".to_string(), a.template, Matrix4::identity()))
        })
        .transpose()?;
    let starts: Vec<(String, MedialTemplate, Matrix4<f64>)> =
        std::iter::once(("aligned".to_string(), aligned, matrix))
            .chain(similarity)
            .chain(thick)
            .chain(unmoved)
            .collect();
    let overlaps = starts
        .iter()
        .map(|(_, t, _)| voxel_dice(&t.boundary_mesh()?, mask))
        .collect::<Result<Vec<_>>>()?;
    let best = overlaps.iter().copied().fold(0.0, f64::max);
    let mut candidates = Vec::new();
    for ((name, start, matrix), dice) in starts.into_iter().zip(overlaps) {
        if dice >= TRIAL_OVERLAP_SHARE * best {
            let mut candidate = Candidate::new(name, Model::Medial(Box::new(start)), matrix);
            candidate.overlap = Some(dice);
            candidates.push(candidate);
        } else {
            notes.push(format!(
                "start {name} not tried: voxel Dice {dice:.3}, under {TRIAL_OVERLAP_SHARE} of \
                 the best start's {best:.3}"
            ));
        }
    }
    Ok(candidates)
}

/// Where an automatic fit starts: its plan, and the template carried by the initial alignment.
pub struct AutomaticStart {
    /// The fit's settings ([`plan::automatic`]).
    pub spec: FitSpec,
    /// The template the fit starts from: the given one carried by [`AutomaticStart::alignment`]
    /// (a medial template projected back onto its constraints after an affine map).
    pub model: Model,
    /// The initial map, template → subject.
    pub alignment: Matrix4<f64>,
    /// What the alignment did, one line per step.
    pub notes: Vec<String>,
    /// The trials that chose the start among several candidates ([`choose`]); empty when
    /// there was one.
    pub trials: Vec<StartTrial>,
    /// The other starts, best first ([`crate::fit::trial::Choice::others`]): where the fit from
    /// this start misses a part of its target ([`crate::fit::agreement`]), a wrong start is the
    /// likely cause, and the next of these the one to try.
    pub others: Vec<Candidate>,
    /// The stage the trials prepared against the target
    /// ([`crate::fit::trial::Choice::prepared`]): a stage of the fit with the same data
    /// settings takes its data from it.
    pub prepared: Option<PreparedStage>,
}

impl AutomaticStart {
    /// The fit from this start against `target`, the target the start was chosen against
    /// (every stage of an automatic plan fits the one target; a stage's data prepared by the
    /// trials serves it again).
    pub fn fit(self, target: Target, memory: MemoryLimit) -> Result<Fit> {
        let targets = vec![target; self.spec.stages.len()];
        let earlier = self.prepared.as_slice();
        Fit::prepare_sharing(&self.spec, self.model, targets, memory, earlier)
    }
}

/// The automatic fit of `model` to `target`: the plan chosen from the data
/// ([`plan::automatic`], from the model as given: the kernel width is a property of the
/// template's own geometry, not of the alignment's guess at the target's thickness; decision
/// 0032) and the initial alignment
/// ([`initial_alignment`]; a medial template carried by [`align_template`], a plain mesh by the
/// whole map), its grids within `memory`. Against an image, a medial template's start is
/// chosen among the candidates (the aligned, the thickened, the given template) by a short
/// trial of the fit from each ([`choose`]). Voxels for rasterizing a closed surface to align
/// to: half the mean spoke ([`Geometry::alignment_spacing`]), or a 128th of a plain mesh's long
/// extent. Whether the kernel is truncated ([`plan::kernel_tolerance`]) is decided again at the
/// start taken: what the truncated sweep skips depends on where the landmarks the fit moves
/// are, and the alignment may have scaled the template (the trials run with the plan's choice:
/// truncation changes their objectives by at most the kernel's tolerance).
pub fn automatic(model: &Model, target: &Target, memory: MemoryLimit) -> Result<AutomaticStart> {
    let mut spec = plan::automatic(model, target)?;
    let (mut trials, mut prepared, mut others) = (Vec::new(), None, Vec::new());
    let (alignment, start): (InitialAlignment, Model) = match model {
        Model::Medial(template) => {
            let boundary = template.boundary_mesh()?;
            let axes = PrincipalAxes::of(boundary.points())?;
            let spacing = Geometry::of(template, &boundary, &axes).alignment_spacing();
            let mut alignment = initial_alignment(&boundary, target, spacing, memory)?;
            let mut aligned = align_template(template, &alignment)?;
            let mask = match target {
                Target::Image { volume, label } => Some(volume.foreground(*label)),
                _ => None,
            };
            // Starts are judged by a trial only against an image (filled shapes' moments).
            let trial = mask.as_ref().zip(alignment.thickness_ratio);
            if trial.is_none() {
                aligned = aligned.similarity_alone();
            }
            alignment.notes.append(&mut aligned.notes);
            alignment.matrix = aligned.matrix;
            let candidates = match trial {
                Some((mask, ratio)) => {
                    image_candidates(template, aligned, ratio, mask, &mut alignment.notes)?
                }
                None => vec![Candidate::new(
                    "aligned",
                    Model::Medial(Box::new(aligned.template)),
                    alignment.matrix,
                )],
            };
            let choice = choose(candidates, &spec, target, mask.as_ref(), memory)?;
            alignment.notes.extend(describe(&choice.trials));
            (trials, prepared, others) = (choice.trials, choice.prepared, choice.others);
            alignment.matrix = choice.taken.alignment;
            (alignment, choice.taken.model)
        }
        Model::Plain(mesh) => {
            let axes = PrincipalAxes::of(mesh.points())?;
            let alignment = initial_alignment(mesh, target, axes.extent.z / 128.0, memory)?;
            let carried = mesh.carried(&alignment.matrix);
            (alignment, Model::Plain(carried))
        }
    };
    spec.flow.kernel_tolerance = plan::kernel_tolerance(spec.flow.sigma, start.landmarks());
    Ok(AutomaticStart {
        spec,
        model: start,
        alignment: alignment.matrix,
        notes: alignment.notes,
        trials,
        others,
        prepared,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::octahedron;

    /// The plan decides truncation on the model as given; the start the alignment carries it to
    /// may spread its landmarks far wider against the same σ, and the fit truncates then.
    #[test]
    fn truncation_is_decided_at_the_start_taken() {
        let (points, triangles) = octahedron();
        let mesh = crate::TriMesh::new(points.clone(), triangles).unwrap();
        let model = Model::Plain(mesh);
        let target = Target::Points(points.iter().map(|p| p * 4.0).collect());
        let plan = plan::automatic(&model, &target).unwrap();
        assert_eq!(plan.flow.kernel_tolerance, 0.0, "every pair near as given");
        let start = automatic(&model, &target, MemoryLimit::none()).unwrap();
        let spread = |m: &Model| (m.landmarks()[0] - m.landmarks()[5]).norm();
        assert!(spread(&start.model) > 3.9 * spread(&model));
        assert_eq!(start.spec.flow.sigma, plan.flow.sigma);
        assert_eq!(start.spec.flow.kernel_tolerance, plan::KERNEL_TOLERANCE);
    }
}
