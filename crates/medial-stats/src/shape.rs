//! Shapes in correspondence: Procrustes alignment of one point set onto another, generalised
//! Procrustes analysis (GPA) of a cohort of medial models (atom positions and radii), and
//! principal component analysis of the aligned shapes.
//!
//! - **Procrustes** (Umeyama's least squares): the rotation R (det R = +1), translation t and,
//!   with scaling, scale s minimising Σᵢ |s R xᵢ + t − yᵢ|². With H = Σ x̃ᵢ ỹᵢᵀ of the centred
//!   points and H = U S Vᵀ, R = V D Uᵀ with D = diag(1, 1, sign det(V Uᵀ)) and
//!   s = tr(S D) / Σ|x̃ᵢ|².
//! - **GPA**: every shape aligned onto the current mean, the mean recomputed, until the mean
//!   moves by less than 1e-10 of its size (at most 100 rounds). With scaling the mean is kept at
//!   the average centroid size of the shapes as given (so lengths stay in mm), and each shape's
//!   radii are multiplied by its scale, the same factor as its positions.
//! - **PCA**: the aligned shapes as rows [x₁ y₁ z₁ … xₙ yₙ zₙ r₁ … rₙ] (mm), centred; the thin
//!   SVD of the centred matrix (subjects × coordinates) gives the modes (right singular vectors),
//!   the variances σₖ² / (subjects − 1) and the scores (U Σ). A mode's sign makes its largest
//!   coordinate (in magnitude) positive.

use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::{Result, StatsError};

/// A similarity transform x ↦ s R x + t.
#[derive(Clone, Debug, PartialEq)]
pub struct Similarity {
    /// The rotation R (det +1).
    pub rotation: Matrix3<f64>,
    /// The translation t.
    pub translation: Vector3<f64>,
    /// The scale s (1 for a rigid transform).
    pub scale: f64,
}

impl Similarity {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// s R p + t.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let q = self.scale * (self.rotation * Vector3::from(p)) + self.translation;
        [q.x, q.y, q.z]
    }
}

fn centroid(points: &[[f64; 3]]) -> Vector3<f64> {
    points
        .iter()
        .fold(Vector3::zeros(), |acc, p| acc + Vector3::from(*p))
        / points.len() as f64
}

/// The root of the summed squared distances of the points from their centroid.
pub fn centroid_size(points: &[[f64; 3]]) -> f64 {
    let c = centroid(points);
    points
        .iter()
        .map(|p| (Vector3::from(*p) - c).norm_squared())
        .sum::<f64>()
        .sqrt()
}

/// The similarity (rigid without `scaling`) that maps `source` onto `target` (corresponding
/// points, the same count, at least 3) in the least-squares sense.
///
/// ```
/// use medial_stats::shape::procrustes;
///
/// let source = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]];
/// // A quarter turn about z, doubled, shifted.
/// let target = source.map(|[x, y, z]| [-2.0 * y + 1.0, 2.0 * x, 2.0 * z - 1.0]);
/// let map = procrustes(&source, &target, true)?;
/// assert!((map.scale - 2.0).abs() < 1e-12);
/// for (s, t) in source.iter().zip(&target) {
///     let m = map.apply(*s);
///     assert!((0..3).all(|d| (m[d] - t[d]).abs() < 1e-12));
/// }
/// # Ok::<(), medial_stats::StatsError>(())
/// ```
pub fn procrustes(source: &[[f64; 3]], target: &[[f64; 3]], scaling: bool) -> Result<Similarity> {
    if source.len() != target.len() {
        return Err(StatsError::Shape {
            what: "corresponding points",
            expected: target.len(),
            found: source.len(),
        });
    }
    if source.len() < 3 {
        return Err(StatsError::Data(format!(
            "Procrustes alignment needs at least 3 corresponding points, found {}",
            source.len()
        )));
    }
    if source
        .iter()
        .chain(target)
        .flatten()
        .any(|v| !v.is_finite())
    {
        return Err(StatsError::Data(
            "Procrustes alignment: a point is not finite".into(),
        ));
    }
    let (cs, ct) = (centroid(source), centroid(target));
    let mut h = Matrix3::zeros();
    let mut spread = 0.0;
    for (s, t) in source.iter().zip(target) {
        let (x, y) = (Vector3::from(*s) - cs, Vector3::from(*t) - ct);
        h += x * y.transpose();
        spread += x.norm_squared();
    }
    if spread == 0.0 {
        return Err(StatsError::Data(
            "Procrustes alignment: the points all coincide".into(),
        ));
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (
        svd.u.expect("SVD with U"),
        svd.v_t.expect("SVD with V transposed"),
    );
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d));
    let rotation = v * flip * u.transpose();
    let scale = if scaling {
        (svd.singular_values[0] + svd.singular_values[1] + d * svd.singular_values[2]) / spread
    } else {
        1.0
    };
    Ok(Similarity {
        translation: ct - scale * (rotation * cs),
        rotation,
        scale,
    })
}

/// A medial model's atoms: positions (mm) and radii (mm, the mean spoke length); or a boundary's
/// points, without radii.
#[derive(Clone, Debug, PartialEq)]
pub struct AtomShape {
    /// The atoms' (or boundary points') positions.
    pub points: Vec<[f64; 3]>,
    /// The atoms' radii, one per point, or none.
    pub radii: Vec<f64>,
}

impl AtomShape {
    /// The shape moved by `map`, its radii scaled by its scale.
    pub fn transformed(&self, map: &Similarity) -> Self {
        Self {
            points: self.points.iter().map(|&p| map.apply(p)).collect(),
            radii: self.radii.iter().map(|r| r * map.scale).collect(),
        }
    }

    /// The coordinates x₁ y₁ z₁ … xₙ yₙ zₙ r₁ … rₙ.
    pub fn to_vector(&self) -> Vec<f64> {
        self.points
            .iter()
            .flatten()
            .copied()
            .chain(self.radii.iter().copied())
            .collect()
    }

    /// The shape of coordinates `v` (as [`Self::to_vector`] writes them) of `n` points.
    pub fn from_vector(v: &[f64], n: usize) -> Self {
        Self {
            points: (0..n)
                .map(|i| [v[3 * i], v[3 * i + 1], v[3 * i + 2]])
                .collect(),
            radii: v[3 * n..].to_vec(),
        }
    }
}

/// Generalised Procrustes analysis of a cohort.
#[derive(Clone, Debug, PartialEq)]
pub struct Gpa {
    /// The mean of the aligned shapes.
    pub mean: AtomShape,
    /// Every shape aligned onto the mean.
    pub aligned: Vec<AtomShape>,
    /// The map of every shape onto the mean.
    pub maps: Vec<Similarity>,
    /// Rounds of alignment.
    pub rounds: usize,
}

/// Rounds of GPA at most.
const GPA_ROUNDS: usize = 100;
/// GPA stops when the mean moves by less than this fraction of its centroid size.
const GPA_TOLERANCE: f64 = 1e-10;

/// Aligns `shapes` (at least 2, the same atoms each, all with radii or all without) onto their
/// common mean: rotations and translations, and with `scaling` scales.
pub fn generalised_procrustes(shapes: &[AtomShape], scaling: bool) -> Result<Gpa> {
    if shapes.len() < 2 {
        return Err(StatsError::Data(format!(
            "Procrustes analysis needs at least 2 shapes, found {}",
            shapes.len()
        )));
    }
    let n = shapes[0].points.len();
    let radii = shapes[0].radii.len();
    for (k, s) in shapes.iter().enumerate() {
        if s.points.len() != n || s.radii.len() != radii || (radii != 0 && radii != n) {
            return Err(StatsError::Data(format!(
                "shape {} has {} points and {} radii where the first has {n} and {radii}",
                k + 1,
                s.points.len(),
                s.radii.len()
            )));
        }
        if s.radii.iter().any(|r| !r.is_finite()) {
            return Err(StatsError::Data(format!(
                "shape {}: a radius is not finite",
                k + 1
            )));
        }
    }
    let size = shapes.iter().map(|s| centroid_size(&s.points)).sum::<f64>() / shapes.len() as f64;
    // The first shape, centred, is the first mean.
    let c = centroid(&shapes[0].points);
    let mut mean = shapes[0].transformed(&Similarity {
        translation: -c,
        ..Similarity::identity()
    });
    let mut rounds = 0;
    loop {
        rounds += 1;
        let maps = shapes
            .iter()
            .map(|s| procrustes(&s.points, &mean.points, scaling))
            .collect::<Result<Vec<_>>>()?;
        let aligned: Vec<AtomShape> = shapes
            .iter()
            .zip(&maps)
            .map(|(s, m)| s.transformed(m))
            .collect();
        let mut next = average(&aligned);
        if scaling {
            // Keep the mean at the cohort's size (GPA with scaling would otherwise shrink it).
            let c = centroid(&next.points);
            let factor = size / centroid_size(&next.points);
            next = next.transformed(&Similarity {
                translation: -factor * c,
                scale: factor,
                rotation: Matrix3::identity(),
            });
        }
        let moved = next
            .points
            .iter()
            .zip(&mean.points)
            .map(|(a, b)| (Vector3::from(*a) - Vector3::from(*b)).norm_squared())
            .sum::<f64>()
            .sqrt();
        mean = next;
        if moved <= GPA_TOLERANCE * size.max(f64::MIN_POSITIVE) || rounds >= GPA_ROUNDS {
            // The last alignment was onto the previous mean: align once more onto this one.
            let maps = shapes
                .iter()
                .map(|s| procrustes(&s.points, &mean.points, scaling))
                .collect::<Result<Vec<_>>>()?;
            let aligned = shapes
                .iter()
                .zip(&maps)
                .map(|(s, m)| s.transformed(m))
                .collect();
            return Ok(Gpa {
                mean,
                aligned,
                maps,
                rounds,
            });
        }
    }
}

/// The coordinate-wise mean of shapes with the same atoms.
pub(crate) fn average(shapes: &[AtomShape]) -> AtomShape {
    let k = shapes.len() as f64;
    let sum = shapes.iter().skip(1).fold(shapes[0].to_vector(), |acc, s| {
        acc.iter().zip(s.to_vector()).map(|(a, b)| a + b).collect()
    });
    AtomShape::from_vector(
        &sum.iter().map(|v| v / k).collect::<Vec<_>>(),
        shapes[0].points.len(),
    )
}

/// Principal components of rows of coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// The mean row.
    pub mean: Vec<f64>,
    /// The modes, unit vectors, by decreasing variance (those with a variance above 1e-12 of
    /// the total and above the rounding level of the coordinates, 1e-24 of their mean square).
    pub modes: Vec<Vec<f64>>,
    /// Each mode's variance (σ² / (rows − 1)).
    pub variances: Vec<f64>,
    /// The total variance (the trace of the covariance).
    pub total_variance: f64,
    /// Every row's score on every mode (rows × modes): its coordinate along the mode.
    pub scores: DMatrix<f64>,
}

impl Pca {
    /// The fraction of the total variance each mode explains.
    pub fn explained(&self) -> Vec<f64> {
        self.variances
            .iter()
            .map(|v| v / self.total_variance)
            .collect()
    }

    /// The mean plus `sd` standard deviations of mode `k`.
    pub fn along(&self, k: usize, sd: f64) -> Vec<f64> {
        let step = sd * self.variances[k].sqrt();
        self.mean
            .iter()
            .zip(&self.modes[k])
            .map(|(m, v)| m + step * v)
            .collect()
    }
}

/// The principal components of `data` (one row per observation, at least 2).
///
/// ```
/// use medial_stats::shape::pca;
/// use nalgebra::dmatrix;
///
/// // Points along (1, 1) with a little spread across.
/// let data = dmatrix![0.0, 0.1; 1.0, 1.0; 2.0, 1.9; 3.0, 3.0];
/// let p = pca(&data)?;
/// assert!(p.explained()[0] > 0.99);
/// assert!((p.modes[0][0] - p.modes[0][1]).abs() < 0.05);
/// # Ok::<(), medial_stats::StatsError>(())
/// ```
pub fn pca(data: &DMatrix<f64>) -> Result<Pca> {
    let (rows, cols) = data.shape();
    if rows < 2 || cols == 0 {
        return Err(StatsError::Data(format!(
            "principal components need at least 2 shapes, found {rows}"
        )));
    }
    if data.iter().any(|v| !v.is_finite()) {
        return Err(StatsError::Data(
            "principal components: a coordinate is not finite".into(),
        ));
    }
    let mean: Vec<f64> = (0..cols).map(|j| data.column(j).mean()).collect();
    let centred = DMatrix::from_fn(rows, cols, |i, j| data[(i, j)] - mean[j]);
    let total_variance = centred.norm_squared() / (rows - 1) as f64;
    let svd = centred.clone().svd(false, true);
    let v_t = svd.v_t.expect("SVD with V transposed");
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    // Variances at the rounding level of the coordinates are not modes.
    let floor = (1e-12 * total_variance).max(1e-24 * data.norm_squared() / rows as f64);
    let mut modes = Vec::new();
    let mut variances = Vec::new();
    for k in order {
        let variance = svd.singular_values[k].powi(2) / (rows - 1) as f64;
        if variance <= floor || variance == 0.0 {
            continue;
        }
        let mut mode: Vec<f64> = v_t.row(k).iter().copied().collect();
        let largest = mode
            .iter()
            .copied()
            .fold(0.0f64, |a, v| if v.abs() > a.abs() { v } else { a });
        if largest < 0.0 {
            mode.iter_mut().for_each(|v| *v = -*v);
        }
        modes.push(mode);
        variances.push(variance);
    }
    let scores = DMatrix::from_fn(rows, modes.len(), |i, k| {
        centred
            .row(i)
            .iter()
            .zip(&modes[k])
            .map(|(a, b)| a * b)
            .sum()
    });
    Ok(Pca {
        mean,
        modes,
        variances,
        total_variance,
        scores,
    })
}
