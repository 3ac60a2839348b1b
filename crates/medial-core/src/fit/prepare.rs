//! A stage of a [`FitSpec`](crate::fit::FitSpec) made ready to run against its data: the
//! attachment built from the [`Target`] (the image smoothed, the varifold width chosen), the
//! medial constraints in the stage's units, the μ schedule and the L-BFGS options; and the
//! figures a fit reports of the data term (voxel overlap, distance to the surface).
//!
//! ```
//! use medial_core::fit::{AttachmentSpec, PreparedStage, StageSpec, Target};
//! use medial_core::memory::MemoryLimit;
//! use medial_core::model::Model;
//! use medial_core::testing::meshes::octahedron;
//! use medial_core::TriMesh;
//! let (points, triangles) = octahedron();
//! let mesh = TriMesh::new(points, triangles).unwrap();
//! let targets = Target::Points(mesh.points().iter().map(|p| p * 1.1).collect());
//! let model = Model::Plain(mesh);
//! let stage = StageSpec::new("points", AttachmentSpec::Ssd);
//! let prepared = PreparedStage::new(&stage, &model, targets, MemoryLimit::none()).unwrap();
//! assert!(prepared.constraints.is_none());
//! assert_eq!(prepared.data_weight, 1.0);
//! ```

use crate::attachment::dice::{DiceAttachment, DiceParams};
use crate::attachment::ssd::Ssd;
use crate::attachment::varifold::{Varifold, VarifoldParams};
use crate::attachment::Attachment;
use crate::fit::agreement::Disagreement;
use crate::fit::augmented_lagrangian::AlSchedule;
use crate::fit::optimize::LbfgsOptions;
use crate::fit::spec::{AttachmentSpec, DiceSpec, MedialTolerance, StageSpec, VarifoldSpec};
use crate::image::volume::Volume;
use crate::memory::{Estimate, MemoryLimit};
use crate::mesh::distance::SurfaceDistance;
use crate::mesh::Bounds;
use crate::model::constraints::MedialConstraints;
use crate::model::Model;
use crate::{Error, Result, TriMesh, Vec3};
use std::sync::Arc;

/// What a stage is fitted to, in memory.
// A target is made once per stage and moved into it: the size of the image variant's header
// does not matter, and boxing it would only add a step to every match.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Target {
    /// Points in correspondence with the template's boundary points (same count and order):
    /// an SSD stage.
    Points(Vec<Vec3>),
    /// An image whose foreground a Dice stage fits.
    Image {
        /// The image.
        volume: Volume,
        /// The foreground's label (none: every voxel > 0).
        label: Option<f64>,
    },
    /// A surface without correspondence (any vertex count and order): a varifold stage.
    Surface(TriMesh),
}

impl Target {
    /// What the target is, in words (`points`, `an image`, `a surface`).
    pub fn kind(&self) -> &'static str {
        match self {
            Target::Points(_) => "points",
            Target::Image { .. } => "an image",
            Target::Surface(_) => "a surface",
        }
    }
}

/// A stage ready to run (a clone shares its data term and target data).
#[derive(Clone)]
pub struct PreparedStage {
    /// The data term (shared by the stages prepared for models of one topology:
    /// [`PreparedStage::for_model`]).
    pub attachment: Arc<dyn Attachment>,
    /// Its weight `w_data` (a varifold's divided by the target's squared norm).
    pub data_weight: f64,
    /// SSD targets, to report the mean distance.
    pub ssd: Option<Ssd>,
    /// Dice stages: the binary foreground of the image (before smoothing), to report the voxel
    /// overlap of the rasterized model.
    pub mask: Option<Arc<Volume>>,
    /// Varifold stages: the target surface, to report the distance of the model's boundary to it
    /// and the part of it the model missed.
    pub surface: Option<Arc<SurfaceDistance>>,
    /// Varifold stages: the kernel width in use, mm (given, or chosen from the target surface).
    pub varifold_width: Option<f64>,
    /// The medial constraints, when they apply.
    pub constraints: Option<MedialConstraints>,
    /// What counts as medial at the end (constrained stages).
    pub tolerance: MedialTolerance,
    /// The μ schedule.
    pub schedule: AlSchedule,
    /// L-BFGS options.
    pub lbfgs: LbfgsOptions,
    /// The topology of the model it was prepared for.
    topology: Topology,
    /// The settings its data term was prepared with ([`PreparedStage::for_stage`]).
    data_settings: DataSettings,
}

/// The settings of a stage its data term depends on: the attachment and its weight.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DataSettings {
    attachment: AttachmentSpec,
    weight: Option<f64>,
}

impl DataSettings {
    fn of(stage: &StageSpec) -> Self {
        Self {
            attachment: stage.attachment,
            weight: stage.weight,
        }
    }
}

/// What a prepared stage's attachment depends on in a model: its boundary triangles, the atom
/// of each boundary point and the number of landmarks (not where the landmarks are).
#[derive(Clone, Debug, PartialEq)]
struct Topology {
    triangles: Vec<[usize; 3]>,
    medial_index: Option<Vec<usize>>,
    landmarks: usize,
}

impl Topology {
    fn of(model: &Model) -> Self {
        Self {
            triangles: model.boundary_triangles().to_vec(),
            medial_index: model.medial().map(|t| t.medial_index().to_vec()),
            landmarks: model.landmarks().len(),
        }
    }
}

impl PreparedStage {
    /// Prepares `stage` for `model` against `target`. A Dice stage past `memory`
    /// ([`Estimate::dice`]) is refused before its image is refined or smoothed; so is an image
    /// whose foreground no sample of the template's interior sees.
    pub fn new(
        stage: &StageSpec,
        model: &Model,
        target: Target,
        memory: MemoryLimit,
    ) -> Result<Self> {
        let constraints = constraints_of(stage, model)?;
        let weight = stage.data_weight();
        let (mut ssd, mut mask, mut surface, mut varifold_width) = (None, None, None, None);
        let wrong = || Error::WrongTarget {
            attachment: stage.attachment.name(),
            target: target.kind(),
        };
        let (attachment, data_weight): (Arc<dyn Attachment>, _) = match (&stage.attachment, &target)
        {
            (AttachmentSpec::Ssd, Target::Points(_)) => {
                let Target::Points(points) = target else {
                    unreachable!("matched above")
                };
                let expected = model.boundary_count();
                if points.len() != expected {
                    return Err(Error::PointCount {
                        expected,
                        found: points.len(),
                    });
                }
                let points = Ssd::new(points)?;
                (Arc::new(ssd.insert(points).clone()), weight)
            }
            (AttachmentSpec::Dice(spec), Target::Image { .. }) => {
                let Target::Image { volume, label } = target else {
                    unreachable!("matched above")
                };
                let (dice, foreground) = dice(spec, model, volume, label, memory)?;
                mask = Some(Arc::new(foreground));
                (Arc::new(dice), weight)
            }
            (AttachmentSpec::Varifold(spec), Target::Surface(mesh)) => {
                let varifold = varifold(spec, model, mesh)?;
                surface = Some(Arc::new(SurfaceDistance::new(mesh)?));
                varifold_width = Some(varifold.width());
                let weight = weight / varifold.target_norm2();
                (Arc::new(varifold), weight)
            }
            _ => return Err(wrong()),
        };
        Ok(Self {
            data_weight,
            attachment,
            ssd,
            mask,
            surface,
            varifold_width,
            constraints,
            tolerance: stage.tolerance,
            schedule: stage.schedule,
            lbfgs: stage.lbfgs,
            topology: Topology::of(model),
            data_settings: DataSettings::of(stage),
        })
    }

    /// `stage` for `model` from the first of `earlier` (stages prepared against the target
    /// `stage` fits) whose data term serves it ([`PreparedStage::for_stage`]); none when none
    /// does (prepare it with [`PreparedStage::new`]).
    pub fn shared<'a>(
        earlier: impl IntoIterator<Item = &'a PreparedStage>,
        stage: &StageSpec,
        model: &Model,
    ) -> Result<Option<Self>> {
        for e in earlier {
            if let Some(shared) = e.for_stage(stage, model)? {
                return Ok(Some(shared));
            }
        }
        Ok(None)
    }

    /// `stage` prepared for `model` against the target this stage was prepared against, its
    /// data term shared (an image read and smoothed once for the trials of the starts, the fit
    /// and its retries), when `stage`'s data term has the same settings (attachment, weight)
    /// and `model` the same topology; none otherwise (prepare it with [`PreparedStage::new`]).
    /// Everything else (constraints, schedule, L-BFGS options, tolerance) is `stage`'s.
    pub fn for_stage(&self, stage: &StageSpec, model: &Model) -> Result<Option<Self>> {
        if DataSettings::of(stage) != self.data_settings || Topology::of(model) != self.topology {
            return Ok(None);
        }
        Ok(Some(Self {
            constraints: constraints_of(stage, model)?,
            tolerance: stage.tolerance,
            schedule: stage.schedule,
            lbfgs: stage.lbfgs,
            ..self.clone()
        }))
    }

    /// This stage prepared for `model` instead, a model of the same topology (boundary
    /// triangles, medial index, landmark count) at other landmarks: the attachment and the
    /// target's data shared (an image smoothed once for several starts), the constraints taken
    /// at `model` (relative units are scaled at its landmarks). A model of another topology is
    /// refused.
    pub fn for_model(&self, model: &Model) -> Result<Self> {
        let topology = Topology::of(model);
        if topology != self.topology {
            return Err(Error::InvalidParameter(
                "a stage prepared for one model cannot serve a model of another topology".into(),
            ));
        }
        let constraints = match (&self.constraints, model.medial()) {
            (Some(c), Some(template)) => Some(MedialConstraints::with_units(template, c.units())?),
            _ => None,
        };
        Ok(Self {
            constraints,
            ..self.clone()
        })
    }

    /// Where the model's boundary at landmarks `q` and the stage's target disagree, and the
    /// part of the target the model missed ([`Disagreement`]): in Dice stages of a medial
    /// template the boundary rasterized on the image's grid against its foreground (with the
    /// voxel overlap), in varifold stages the boundary against the target surface (none for
    /// other stages).
    pub fn disagreement(&self, model: &Model, q: &[Vec3]) -> Result<Option<Disagreement>> {
        let boundary = || {
            TriMesh::new(
                q[..model.boundary_count()].to_vec(),
                model.boundary_triangles().to_vec(),
            )
        };
        match (&self.mask, model.medial(), &self.surface) {
            (Some(mask), Some(_), _) => Ok(Some(Disagreement::new(&boundary()?, mask)?)),
            (None, _, Some(target)) => Ok(Some(Disagreement::of_surfaces(&boundary()?, target)?)),
            _ => Ok(None),
        }
    }

    /// Varifold stages: the mean distance of the model's boundary at landmarks `q` to the
    /// target surface, mm.
    pub fn surface_distance(&self, model: &Model, q: &[Vec3]) -> Option<f64> {
        self.surface
            .as_ref()
            .map(|s| s.mean_distance(&q[..model.boundary_count()]))
    }

    /// SSD stages: the mean distance of the model's boundary at landmarks `q` to its targets, mm.
    pub fn ssd_distance(&self, q: &[Vec3]) -> Option<f64> {
        self.ssd.as_ref().map(|s| s.mean_distance(q))
    }
}

/// The varifold attachment of the model's boundary against `target`.
fn varifold(spec: &VarifoldSpec, model: &Model, target: &TriMesh) -> Result<Varifold> {
    let params = VarifoldParams {
        kind: spec.kind,
        width: spec.width,
    };
    Varifold::new(
        model.boundary_triangles(),
        model.landmarks().len(),
        target,
        params,
    )
}

/// Voxels kept around the foreground when an image is refined: the reach of the smoothing
/// (4 σ) and two voxels more.
fn refine_margin(spec: &DiceSpec, volume: &Volume) -> usize {
    (4.0 * spec.image_sigma / volume.spacing().min()).ceil() as usize + 2
}

/// The medial constraints of `stage` for `model`, in the stage's units: where the stage asks
/// for them (by default for a medial template); a plain mesh asked for them is refused.
fn constraints_of(stage: &StageSpec, model: &Model) -> Result<Option<MedialConstraints>> {
    let constrained = stage.constraints.unwrap_or(model.medial().is_some());
    match (constrained, model.medial()) {
        (false, _) => Ok(None),
        (true, None) => Err(Error::NeedsMedial("constraints = true")),
        (true, Some(template)) => Ok(Some(MedialConstraints::with_units(
            template,
            stage.constraint_units,
        )?)),
    }
}

/// The Dice attachment of the model against the foreground of `volume`, smoothed, and the
/// foreground itself (before smoothing).
fn dice(
    spec: &DiceSpec,
    model: &Model,
    volume: Volume,
    label: Option<f64>,
    memory: MemoryLimit,
) -> Result<(DiceAttachment, Volume)> {
    if spec.image_refine > 1 && label.is_some() {
        return Err(Error::InvalidParameter(
            "image_refine interpolates intensities: it does not apply to a label".into(),
        ));
    }
    let template = model.medial().ok_or(Error::NeedsMedial(
        "the dice attachment (its interior is sampled between boundary and medial sheet)",
    ))?;
    let margin = refine_margin(spec, &volume);
    let refined_voxels: usize = match spec.image_refine {
        1 => 0,
        f => volume.refined_dims(f, margin).iter().product(),
    };
    let estimate = Estimate::dice(
        spec.subdivision,
        spec.layers,
        template.boundary_triangles().len(),
        template.landmark_count(),
        volume.data().len() + refined_voxels,
    );
    memory.check(&estimate, || "the Dice attachment".into())?;
    let mask = volume.foreground(label);
    let fine = match spec.image_refine {
        1 => None,
        f => Some(volume.refined(f, margin)?.foreground(label)),
    };
    drop(volume); // Not needed past its masks: freed before the smoothing copies.
    let image = fine
        .as_ref()
        .unwrap_or(&mask)
        .smoothed(spec.image_sigma)
        .map_err(|e| Error::Setting {
            setting: "image_sigma",
            source: Box::new(e),
        })?;
    drop(fine);
    let params = DiceParams {
        subdivision: spec.subdivision,
        layers: spec.layers,
    };
    let attachment = DiceAttachment::for_template(template, image, params)?;
    if attachment.dice(template.landmarks(), None)?.overlap <= 0.0 {
        // The attachment has refused an empty foreground, the template has boundary points.
        let foreground = mask
            .support_bounds()
            .ok_or_else(|| Error::InvalidVolume("the image has no foreground voxel".into()))?;
        let template = Bounds::of(template.boundary_points())
            .ok_or_else(|| Error::InvalidTemplate("the template has no boundary point".into()))?;
        return Err(Error::NoOverlap {
            foreground: Box::new(foreground),
            template: Box::new(template),
        });
    }
    Ok((attachment, mask))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::run::Fit;
    use crate::fit::spec::FlowSettings;
    use crate::image::rasterize::{grid_around, rasterize};
    use crate::testing::meshes::{bipyramid, octahedron};

    /// The bipyramid of half thickness `r` scaled to 10 mm, and an image of it at half
    /// thickness 0.7 at 1 mm voxels.
    fn sheet(r: f64) -> Model {
        let t = bipyramid(r);
        let scaled: Vec<Vec3> = t.landmarks().iter().map(|p| p * 10.0).collect();
        Model::Medial(Box::new(t.with_landmarks(&scaled).unwrap()))
    }

    fn image() -> Target {
        let Model::Medial(wall) = sheet(0.7) else {
            unreachable!("a medial template")
        };
        let boundary = wall.boundary_mesh().unwrap();
        let (dims, grid) = grid_around(&boundary, 1.0, 4.0).unwrap();
        Target::Image {
            volume: rasterize(&boundary, dims, grid).unwrap(),
            label: None,
        }
    }

    /// A stage's data (the image smoothed) serves a stage of the same attachment and weight
    /// for a model of the same topology elsewhere, with that stage's schedule and options and
    /// its constraints at that model: a fit from it runs to the same bits as one prepared
    /// afresh. Another attachment setting, another weight or another topology is not served.
    #[test]
    fn a_stage_shares_its_data_only_with_the_same_data_settings() {
        let stage = StageSpec::new("dice", AttachmentSpec::Dice(DiceSpec::default()));
        let (thin, thick) = (sheet(0.5), sheet(0.6));
        let first = PreparedStage::new(&stage, &thin, image(), MemoryLimit::none()).unwrap();
        let mut later = stage.clone();
        later.schedule.mu = 7.0;
        later.lbfgs.max_iterations = 4;
        let shared = PreparedStage::shared([&first], &later, &thick)
            .unwrap()
            .unwrap();
        assert!(Arc::ptr_eq(&shared.attachment, &first.attachment));
        assert_eq!(
            (shared.schedule, shared.lbfgs),
            (later.schedule, later.lbfgs)
        );
        let fresh = PreparedStage::new(&later, &thick, image(), MemoryLimit::none()).unwrap();
        let flow = FlowSettings {
            sigma: 4.0,
            time_steps: 4,
            ..FlowSettings::default()
        };
        let run = |p: PreparedStage| {
            let flow = flow.flow(thick.landmarks().len()).unwrap();
            let outcome = Fit::new(thick.clone(), flow, vec![p]).run(|_| {}).unwrap();
            (outcome[0].evaluation.total, outcome[0].momenta.clone())
        };
        assert_eq!(run(shared), run(fresh));

        let mut sigma = stage.clone();
        sigma.attachment = AttachmentSpec::Dice(DiceSpec {
            image_sigma: 2.0 * DiceSpec::default().image_sigma + 0.1,
            ..DiceSpec::default()
        });
        let mut weight = stage.clone();
        weight.weight = Some(3.0);
        for other in [&sigma, &weight] {
            assert!(first.for_stage(other, &thick).unwrap().is_none());
        }
        let (points, triangles) = octahedron();
        let plain = Model::Plain(TriMesh::new(points, triangles).unwrap());
        let mut unconstrained = stage.clone();
        unconstrained.constraints = Some(false);
        assert!(first.for_stage(&unconstrained, &plain).unwrap().is_none());
    }
}
