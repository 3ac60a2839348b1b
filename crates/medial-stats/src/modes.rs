//! Shape modes of a cohort of fitted medial models (models of one template, so that atom m and
//! boundary point b are the same place in every subject).
//!
//! - **The shapes** ([`ShapeOf`]): the medial atoms, positions and radii (the radius of atom m
//!   is half its thickness, the mean length of its spokes), or the boundary points.
//! - **Alignment**: generalised Procrustes analysis ([`generalised_procrustes`]) with rotations
//!   and translations ([`Alignment::Rigid`]), and scales ([`Alignment::Similarity`]: a
//!   subject's radii scale with its positions); or none ([`Alignment::None`]: the shapes as
//!   given, their mean the coordinate-wise average).
//! - **Modes**: [`pca()`] of the aligned shapes' coordinates (mm): modes by decreasing
//!   variance, each subject's score on each.
//! - **Shapes along a mode**: the mean plus `sd` standard deviations of mode k,
//!   x̄ + sd √λₖ vₖ. Of atoms, the boundary of such a shape puts boundary point b at
//!   xₘ + rₘ ūᵦ (m its atom), ūᵦ the mean over subjects of b's aligned spoke divided by its
//!   atom's mean radius: at the mean shape, the mean aligned spoke.

use nalgebra::{DMatrix, Vector3};

use medial_core::model::metrics::SpokeMetrics;
use medial_core::MedialTemplate;

use crate::atoms::Alignment;
use crate::shape::{average, generalised_procrustes, pca, AtomShape, Gpa, Pca, Similarity};
use crate::{Result, StatsError};

/// What a subject's shape is made of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ShapeOf {
    /// The medial atoms: positions and radii.
    #[default]
    Atoms,
    /// The boundary points.
    Boundary,
}

impl ShapeOf {
    /// Its name: `atoms` or `boundary`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Atoms => "atoms",
            Self::Boundary => "boundary",
        }
    }

    /// The shape of `model`.
    pub fn shape(self, model: &MedialTemplate) -> AtomShape {
        let points = |p: &[medial_core::Vec3]| p.iter().map(|&p| p.into()).collect();
        match self {
            Self::Atoms => AtomShape {
                points: points(model.medial_points()),
                radii: SpokeMetrics::compute(model, model.landmarks())
                    .thickness
                    .iter()
                    .map(|t| t / 2.0)
                    .collect(),
            },
            Self::Boundary => AtomShape {
                points: points(model.boundary_points()),
                radii: Vec::new(),
            },
        }
    }
}

impl std::str::FromStr for ShapeOf {
    type Err = StatsError;

    /// The shapes of [`ShapeOf::name`] `name`.
    fn from_str(name: &str) -> Result<Self> {
        [Self::Atoms, Self::Boundary]
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| StatsError::parameter("of", name, "expected atoms or boundary"))
    }
}

/// The shape modes of a cohort ([`shape_modes`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeModes {
    /// What the shapes are made of.
    pub of: ShapeOf,
    /// How they were aligned.
    pub alignment: Alignment,
    /// The aligned shapes and their mean.
    pub gpa: Gpa,
    /// The principal components of the aligned shapes' coordinates (one row per subject).
    pub pca: Pca,
    /// Of atoms: every boundary point's atom.
    atom_of: Vec<usize>,
    /// Of atoms: every boundary point's mean aligned spoke over its atom's mean radius.
    spokes: Vec<Vector3<f64>>,
}

/// The shape modes of `models` (at least 2, all of one template): their shapes as `of` says,
/// aligned as `alignment` says, and the principal components.
///
/// Errors: fewer than 2 models, models of different templates, or what
/// [`generalised_procrustes`] and [`pca()`] refuse.
pub fn shape_modes(
    models: &[MedialTemplate],
    of: ShapeOf,
    alignment: Alignment,
) -> Result<ShapeModes> {
    if models.len() < 2 {
        return Err(StatsError::Data(format!(
            "shape modes need at least 2 fitted models, found {}",
            models.len()
        )));
    }
    let first = &models[0];
    for model in models {
        if model.medial_index() != first.medial_index()
            || model.medial_count() != first.medial_count()
        {
            return Err(StatsError::Shape {
                what: "atoms of a fitted model (the first model's)",
                expected: first.medial_count(),
                found: model.medial_count(),
            });
        }
    }
    let shapes: Vec<AtomShape> = models.iter().map(|m| of.shape(m)).collect();
    let gpa = match alignment {
        Alignment::None => Gpa {
            mean: average(&shapes),
            maps: vec![Similarity::identity(); shapes.len()],
            aligned: shapes,
            rounds: 0,
        },
        Alignment::Rigid => generalised_procrustes(&shapes, false)?,
        Alignment::Similarity => generalised_procrustes(&shapes, true)?,
    };
    let columns = gpa.mean.to_vector().len();
    let rows: Vec<f64> = gpa.aligned.iter().flat_map(|a| a.to_vector()).collect();
    let pca = pca(&DMatrix::from_row_slice(gpa.aligned.len(), columns, &rows))?;
    let (atom_of, spokes) = match of {
        ShapeOf::Boundary => (Vec::new(), Vec::new()),
        ShapeOf::Atoms => {
            let atom_of = first.medial_index().to_vec();
            let k = models.len() as f64;
            let spokes = atom_of
                .iter()
                .enumerate()
                .map(|(b, &m)| {
                    let sum =
                        models
                            .iter()
                            .zip(&gpa.maps)
                            .fold(Vector3::zeros(), |acc, (model, map)| {
                                let q = model.landmarks();
                                let spoke = q[b] - q[model.atom_landmark(m)];
                                acc + map.scale * (map.rotation * spoke)
                            });
                    sum / (k * gpa.mean.radii[m])
                })
                .collect();
            (atom_of, spokes)
        }
    };
    Ok(ShapeModes {
        of,
        alignment,
        gpa,
        pca,
        atom_of,
        spokes,
    })
}

impl ShapeModes {
    /// The shape at the mean plus `sd` standard deviations of mode `k` (0-based; the mean for
    /// `sd` = 0).
    ///
    /// Errors: no mode `k`.
    pub fn shape_at(&self, k: usize, sd: f64) -> Result<AtomShape> {
        if k >= self.pca.modes.len() {
            return Err(StatsError::Data(format!(
                "mode {} asked for, the cohort has {}",
                k + 1,
                self.pca.modes.len()
            )));
        }
        Ok(AtomShape::from_vector(
            &self.pca.along(k, sd),
            self.gpa.mean.points.len(),
        ))
    }

    /// Of atoms, every boundary point's atom (empty for boundaries).
    pub fn atom_of(&self) -> &[usize] {
        &self.atom_of
    }

    /// The boundary points of `shape` (one of these modes' shapes): its points for a
    /// boundary's, for atoms every boundary point at its atom's position plus its atom's
    /// radius times its mean aligned spoke over its atom's mean radius.
    pub fn boundary(&self, shape: &AtomShape) -> Vec<[f64; 3]> {
        match self.of {
            ShapeOf::Boundary => shape.points.clone(),
            ShapeOf::Atoms => self
                .atom_of
                .iter()
                .zip(&self.spokes)
                .map(|(&m, u)| (Vector3::from(shape.points[m]) + shape.radii[m] * u).into())
                .collect(),
        }
    }
}
