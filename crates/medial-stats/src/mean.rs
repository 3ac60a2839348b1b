//! A population template from a cohort's fitted models, one round of `medial mean`: the models'
//! landmarks (boundary and medial points, in correspondence) aligned by generalised Procrustes
//! analysis and averaged, the mean placed on the round's template (rigidly, least squares), then
//! projected onto the medial constraints
//! ([`medial_core::construction::project()`]) so that they hold within its tolerances. The
//! change of the round is the root-mean-square move of the landmarks from the round's template
//! to the new one, and its parts along the round's boundary normals (the shape change) and
//! across them (the slide); rounds (each fitting the cohort again from the new template) repeat
//! until the shape change is small. A Dice fit ties the surface to the image, not a boundary
//! point to its place on the surface: every round's fits re-place the points along the surface
//! a little, a slide that shrinks slowly while the shape has stopped changing (decision 0102).

use medial_core::construction::project::{project, ConstraintFigures, ProjectOptions};
use medial_core::{MedialTemplate, Vec3};

use crate::atoms::Alignment;
use crate::shape::{average, generalised_procrustes, procrustes, AtomShape};
use crate::{Result, StatsError};

/// The result of a round ([`mean_template`]).
#[derive(Clone, Debug)]
pub struct MeanTemplate {
    /// The projected mean, placed on the round's template.
    pub template: MedialTemplate,
    /// Root-mean-square landmark move from the round's template, mm.
    pub change: f64,
    /// Root-mean-square over the boundary points of their move along the round's template's
    /// outward boundary normals (its Loop normals), mm: to first order the distance between
    /// the two surfaces, the change of shape.
    pub shape_change: f64,
    /// Root-mean-square over the boundary points of the rest of their move (along the
    /// surface), mm: how the points slid on it.
    pub slide: f64,
    /// The constraints of the mean before projection.
    pub before: ConstraintFigures,
    /// The constraints of the projected mean.
    pub after: ConstraintFigures,
    /// Root-mean-square landmark move of the projection, mm.
    pub projection_rms: f64,
}

/// The landmarks of `model` as points.
fn landmarks(model: &MedialTemplate) -> AtomShape {
    AtomShape {
        points: model.landmarks().iter().map(|&p| p.into()).collect(),
        radii: Vec::new(),
    }
}

/// The mean of `models` (at least 2, of `reference`'s structure) aligned as `alignment` says,
/// placed on `reference` and projected onto its medial constraints with `options`.
///
/// Errors: fewer than 2 models, a model of another structure, what Procrustes refuses, and a
/// projection that misses its tolerances.
pub fn mean_template(
    models: &[MedialTemplate],
    reference: &MedialTemplate,
    alignment: Alignment,
    options: &ProjectOptions,
) -> Result<MeanTemplate> {
    if models.len() < 2 {
        return Err(StatsError::Data(format!(
            "a mean template needs at least 2 fitted models, found {}",
            models.len()
        )));
    }
    for model in models {
        if model.medial_index() != reference.medial_index()
            || model.landmark_count() != reference.landmark_count()
        {
            return Err(StatsError::Shape {
                what: "landmarks of a fitted model (the template's)",
                expected: reference.landmark_count(),
                found: model.landmark_count(),
            });
        }
    }
    let shapes: Vec<AtomShape> = models.iter().map(landmarks).collect();
    let mean = match alignment {
        Alignment::None => average(&shapes),
        Alignment::Rigid => generalised_procrustes(&shapes, false)?.mean,
        Alignment::Similarity => generalised_procrustes(&shapes, true)?.mean,
    };
    let target = landmarks(reference);
    let onto = procrustes(&mean.points, &target.points, false)?;
    let placed: Vec<Vec3> = mean
        .points
        .iter()
        .map(|&p| Vec3::from(onto.apply(p)))
        .collect();
    let model_error = |e: medial_core::Error| StatsError::Data(format!("mean template: {e}"));
    let averaged = reference.with_landmarks(&placed).map_err(model_error)?;
    let projection = project(&averaged, options).map_err(model_error)?;
    let moved: f64 = projection
        .template
        .landmarks()
        .iter()
        .zip(reference.landmarks())
        .map(|(a, b)| (a - b).norm_squared())
        .sum();
    let (shape_change, slide) = normal_and_tangential(reference, projection.template.landmarks());
    Ok(MeanTemplate {
        change: (moved / reference.landmark_count() as f64).sqrt(),
        shape_change,
        slide,
        before: projection.before,
        after: projection.after,
        projection_rms: projection.rms_displacement,
        template: projection.template,
    })
}

/// The root-mean-square over `reference`'s boundary points of their move to `moved` (landmarks
/// of the same structure) along `reference`'s outward Loop normals there, and across them, mm.
pub fn normal_and_tangential(reference: &MedialTemplate, moved: &[Vec3]) -> (f64, f64) {
    let q = reference.landmarks();
    let normals = reference.tangents().normals(q);
    let nb = reference.boundary_count();
    let (normal, tangential) = (0..nb).fold((0.0, 0.0), |(n, t), b| {
        let d = moved[b] - q[b];
        let along = d.dot(&normals[b]);
        (
            n + along * along,
            t + (d - along * normals[b]).norm_squared(),
        )
    });
    ((normal / nb as f64).sqrt(), (tangential / nb as f64).sqrt())
}
