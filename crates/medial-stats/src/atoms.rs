//! Per-atom measures of fitted medial models, for a GLM on the template's medial sheet: every
//! subject's model has the template's atoms, so atom m is the same place of the anatomy in
//! every subject.
//!
//! | name | measure at atom m |
//! |---|---|
//! | `thickness` | 2 × the mean length of its spokes (mm), as `Thickness` in the medial VTK files |
//! | `spoke_pos`, `spoke_neg` | the length of its spoke on the + (−) side of the template's medial normal (sheet atoms); a free-edge atom's one spoke for both; NaN at seams and where they end |
//! | `spoke1`, `spoke2`, `spoke3` | the length of its k-th spoke in the template's order (ascending boundary index); NaN where it has fewer |
//! | `displacement` | (x̃ₘ − xₘ) · nₘ (mm): the fitted medial point x̃ₘ, aligned onto the template's medial points (rigidly by default), minus the template's xₘ, along the template's medial normal nₘ; NaN at seams and where they end |
//! | `ball_residual` | the atoms.csv column `fidelity` (the inscribed-ball residual) |
//!
//! Any other name is an atoms.csv column ([`AtomMeasure::Column`]), which the caller reads.
//!
//! **The medial normal** ([`SheetNormals`]): at a sheet atom (two spokes b₀ < b₁) the direction
//! of q(b₀) − q(b₁), normal to the medial sheet when its spokes are equal and normal to the
//! boundary. Its sign is made consistent across each sheet by a breadth-first walk over the
//! medial triangles from the sheet's lowest atom (which keeps the side of its spoke b₀); a
//! free-edge atom takes the normalised sum of its sheet neighbours' normals; a seam atom (three
//! spokes) has none, nor has a free-edge atom beside a seam (where the seam ends, the sheets
//! meet).

use std::collections::VecDeque;

use medial_core::model::metrics::SpokeMetrics;
use medial_core::MedialTemplate;
use nalgebra::Vector3;

use crate::shape::{procrustes, Similarity};
use crate::{Result, StatsError};

/// A measure at every atom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AtomMeasure {
    /// 2 × mean spoke length.
    Thickness,
    /// The spoke on the + side of the medial normal.
    SpokePositive,
    /// The spoke on the − side of the medial normal.
    SpokeNegative,
    /// The k-th spoke (0-based) in the template's order.
    Spoke(usize),
    /// The medial point's displacement from the template's along its normal.
    Displacement,
    /// A column of the fit's atoms.csv.
    Column(String),
}

impl AtomMeasure {
    /// The measure called `name` (see the module's table); an unknown name is an atoms.csv
    /// column, `ball_residual` the column `fidelity`.
    pub fn parse(name: &str) -> Self {
        match name {
            "thickness" => Self::Thickness,
            "spoke_pos" => Self::SpokePositive,
            "spoke_neg" => Self::SpokeNegative,
            "spoke1" => Self::Spoke(0),
            "spoke2" => Self::Spoke(1),
            "spoke3" => Self::Spoke(2),
            "displacement" => Self::Displacement,
            "ball_residual" => Self::Column("fidelity".into()),
            other => Self::Column(other.into()),
        }
    }
}

/// How a fitted model is placed on the template before its displacement is measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Alignment {
    /// As fitted (the subject's space).
    None,
    /// Rotation and translation (least squares over the medial points).
    #[default]
    Rigid,
    /// Rotation, translation and scale.
    Similarity,
}

impl Alignment {
    /// Its name: `none`, `rigid` or `similarity`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Rigid => "rigid",
            Self::Similarity => "similarity",
        }
    }
}

impl std::str::FromStr for Alignment {
    type Err = StatsError;

    /// The alignment of [`Alignment::name`] `name`.
    fn from_str(name: &str) -> Result<Self> {
        [Self::None, Self::Rigid, Self::Similarity]
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| {
                StatsError::parameter("alignment", name, "expected none, rigid or similarity")
            })
    }
}

/// The template's medial normal at every atom (`None` at seams and where undefined).
#[derive(Clone, Debug, PartialEq)]
pub struct SheetNormals {
    normals: Vec<Option<[f64; 3]>>,
    /// Per atom: whether its spoke b₀ lies on the + side.
    first_positive: Vec<bool>,
}

impl SheetNormals {
    /// The oriented medial normals of `template`.
    pub fn new(template: &MedialTemplate) -> Self {
        let q = template.landmarks();
        let m = template.medial_count();
        let across: Vec<Option<Vector3<f64>>> = (0..m)
            .map(|a| match template.spokes(a) {
                [b0, b1] => (q[*b0] - q[*b1]).try_normalize(0.0),
                _ => None,
            })
            .collect();
        let mut neighbours = vec![Vec::new(); m];
        for t in template.medial_triangles() {
            for i in 0..3 {
                for j in 0..3 {
                    if i != j && !neighbours[t[i]].contains(&t[j]) {
                        neighbours[t[i]].push(t[j]);
                    }
                }
            }
        }
        neighbours.iter_mut().for_each(|n| n.sort_unstable());
        // Orient each sheet by a breadth-first walk through its sheet atoms.
        let mut sign = vec![0.0f64; m];
        for start in 0..m {
            if across[start].is_none() || sign[start] != 0.0 {
                continue;
            }
            sign[start] = 1.0;
            let mut queue = VecDeque::from([start]);
            while let Some(a) = queue.pop_front() {
                let na = across[a].expect("sheet atom") * sign[a];
                for &b in &neighbours[a] {
                    if let (Some(nb), 0.0) = (across[b], sign[b]) {
                        sign[b] = if nb.dot(&na) < 0.0 { -1.0 } else { 1.0 };
                        queue.push_back(b);
                    }
                }
            }
        }
        let mut normals: Vec<Option<[f64; 3]>> = (0..m)
            .map(|a| across[a].map(|n| (n * sign[a]).into()))
            .collect();
        for a in 0..m {
            // A free-edge atom beside a seam is where sheets meet: no one normal.
            let by_seam = neighbours[a].iter().any(|&b| template.spokes(b).len() == 3);
            if template.spokes(a).len() == 1 && !by_seam {
                let sum = neighbours[a]
                    .iter()
                    .filter_map(|&b| across[b].map(|n| n * sign[b]))
                    .fold(Vector3::zeros(), |acc, n| acc + n);
                normals[a] = sum.try_normalize(1e-12).map(Into::into);
            }
        }
        Self {
            normals,
            first_positive: sign.iter().map(|&s| s > 0.0).collect(),
        }
    }

    /// Every atom's unit normal, `None` at seams.
    pub fn normals(&self) -> &[Option<[f64; 3]>] {
        &self.normals
    }
}

/// The measure `measure` (not a [`AtomMeasure::Column`]) at every atom of `fitted`, a model of
/// `template`'s structure; `normals` are the template's, `alignment` places `fitted` for
/// [`AtomMeasure::Displacement`].
pub fn atom_values(
    template: &MedialTemplate,
    normals: &SheetNormals,
    fitted: &MedialTemplate,
    measure: &AtomMeasure,
    alignment: Alignment,
) -> Result<Vec<f64>> {
    if fitted.medial_count() != template.medial_count()
        || fitted.boundary_count() != template.boundary_count()
    {
        return Err(StatsError::Shape {
            what: "atoms of a fitted model (the template's)",
            expected: template.medial_count(),
            found: fitted.medial_count(),
        });
    }
    let m = template.medial_count();
    let q = fitted.landmarks();
    let length = |b: usize, a: usize| (q[b] - q[fitted.atom_landmark(a)]).norm();
    let values = match measure {
        AtomMeasure::Thickness => SpokeMetrics::compute(fitted, q).thickness,
        AtomMeasure::Spoke(k) => (0..m)
            .map(|a| {
                template
                    .spokes(a)
                    .get(*k)
                    .map_or(f64::NAN, |&b| length(b, a))
            })
            .collect(),
        AtomMeasure::SpokePositive | AtomMeasure::SpokeNegative => {
            let positive = *measure == AtomMeasure::SpokePositive;
            (0..m)
                .map(|a| match template.spokes(a) {
                    [b] if normals.normals[a].is_some() => length(*b, a),
                    [b0, b1] => {
                        let first = normals.first_positive[a] == positive;
                        length(if first { *b0 } else { *b1 }, a)
                    }
                    _ => f64::NAN,
                })
                .collect()
        }
        AtomMeasure::Displacement => {
            let target: Vec<[f64; 3]> = template
                .medial_points()
                .iter()
                .map(|p| (*p).into())
                .collect();
            let source: Vec<[f64; 3]> =
                fitted.medial_points().iter().map(|p| (*p).into()).collect();
            let map = match alignment {
                Alignment::None => Similarity::identity(),
                Alignment::Rigid => procrustes(&source, &target, false)?,
                Alignment::Similarity => procrustes(&source, &target, true)?,
            };
            (0..m)
                .map(|a| match normals.normals[a] {
                    Some(n) => {
                        let p = map.apply(source[a]);
                        (0..3).map(|d| (p[d] - target[a][d]) * n[d]).sum()
                    }
                    None => f64::NAN,
                })
                .collect()
        }
        AtomMeasure::Column(name) => {
            return Err(StatsError::parameter(
                "array",
                name,
                "is a column of atoms.csv, read by the caller",
            ))
        }
    };
    Ok(values)
}
