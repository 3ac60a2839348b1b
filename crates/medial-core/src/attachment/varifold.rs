//! Surfaces compared without correspondence (issue 9): the varifold, oriented-varifold and
//! current distances between the model's boundary and a target triangle mesh of any vertex
//! count and order.
//!
//! ## Surfaces as measures
//!
//! A triangle `f` with corners `a, b, c` is a Dirac at its centre `c_f = (a + b + c)/3` carrying
//! its area-weighted normal `n_f = ½ (b − a) × (c − a)` (`|n_f|` is its area, mm²; the unit
//! normal is `u_f = n_f/|n_f|`). Two surfaces `S` (the source: the model's boundary triangles
//! over the landmarks `q`) and `T` (the fixed target) have the inner product
//!
//! ```text
//! ⟨S, T⟩ = Σ_{f∈S} Σ_{g∈T} K(c_f, c_g) |n_f| |n_g| φ(u_f·u_g),    K(x, y) = exp(−|x − y|²/σ_w²)
//! ```
//!
//! with the spatial width `σ_w` ([`VarifoldParams::width`], mm; note the convention: no factor 2,
//! as in Charon–Trouvé, deformetrica and KeOps, so this `σ_w` is √2 times the `σ` of
//! [`crate::flow::kernel::GaussianKernel`] for the same kernel) and a kernel `φ` on the unit
//! normals chosen by the [`Kind`]:
//!
//! - [`Kind::Varifold`] (the default): `φ(t) = t²`,
//!   `⟨S, T⟩ = Σ K(c_f, c_g) (n_f·n_g)² / (|n_f| |n_g|)`;
//! - [`Kind::OrientedVarifold`]: `φ(t) = exp(−2(1 − t)/σ_n²)`,
//!   `⟨S, T⟩ = Σ K(c_f, c_g) exp(−|u_f − u_g|²/σ_n²) |n_f| |n_g|`;
//! - [`Kind::Current`]: `φ(t) = t`, `⟨S, T⟩ = Σ K(c_f, c_g) n_f·n_g`
//!
//! (the unoriented varifold of Charon & Trouvé 2013 with the Binet kernel on the normals, the
//! oriented varifold with the Gaussian kernel on the sphere of Kaltenmark, Charlier & Charon
//! 2017, normalised to 1 at `t = 1`, and the current of Vaillant & Glaunès 2005). The
//! attachment is the squared distance
//!
//! ```text
//! g(q) = ‖S − T‖² = ⟨S, S⟩ − 2 ⟨S, T⟩ + ⟨T, T⟩ ≥ 0     (mm⁴ for every kind)
//! ```
//!
//! which is ≥ 0 because each kernel is positive definite, and 0 when `S` and `T` are the same
//! triangles in any order. The target's orientation does not matter to the varifold (`φ` is
//! even); it does to the other two.
//!
//! ## Gradient
//!
//! Let the source and target faces form one set with signs `ε = +1` (source) and `ε = −1`
//! (target), so that `g = Σ_a Σ_b ε_a ε_b K_ab |n_a| |n_b| φ(t_ab)` over all ordered pairs,
//! `t_ab = u_a·u_b`. Every `φ` has `φ(1) = 1`: a face with itself contributes `|n_a|²`. For a
//! source face `f`, with the sums over the other faces `b ≠ f` of both surfaces,
//!
//! ```text
//! ∂g/∂c_f = −(4/σ_w²) |n_f| Σ_b ε_b K_fb |n_b| φ(t_fb) (c_f − c_b)
//! ∂g/∂n_f = 2 n_f + 2 Σ_b ε_b K_fb |n_b| [(φ − tφ')(t_fb) u_f + φ'(t_fb) u_b]
//! ```
//!
//! and by the chain rule to its corners `a, b, c` (cyclically)
//! `∂g/∂a = ⅓ ∂g/∂c_f + ½ (b − c) × ∂g/∂n_f`, summed over the faces of a landmark; the
//! gradient is 0 for landmarks on no source triangle (the medial points). At a face of zero
//! area, where `u_f` is undefined, `u_f = 0` is used (the varifold is not differentiable there).
//!
//! ## Computation
//!
//! One [`PairSweep`](crate::flow::kernel) over the signed set of `F_S + F_T` faces gives every
//! sum above: each unordered pair once, with one exponential (two for the oriented kind, whose
//! `φ` is an exponential too), in parallel, and with a reduction in a fixed order, so that the
//! result has the same bits for any number of threads. The sweep is bipartite: it leaves out
//! the pairs of two target faces, whose sum `⟨T, T⟩` is constant and computed once, when the
//! attachment is made (`F_S²/2 + F_S F_T` pairs instead of `(F_S + F_T)²/2`: on a target of
//! four times the model's faces, 4.5 instead of 12.5 times `F_S²`). The target faces' own sums
//! then hold their pairs with the source only, and
//! `g = Σ_{a∈S} |n_a| (|n_a| + s_a) − Σ_{a∈T} |n_a| s_a + ⟨T, T⟩`, `s_a` the swept sum
//! `Σ_b ε_b K_ab |n_b| φ(t_ab)` of face `a`.
//!
//! ## The width `σ_w`
//!
//! It sets the scale of the features compared: details finer than `σ_w` are blurred, surfaces
//! further apart than a few `σ_w` do not see each other, and it must exceed the spacing of the
//! vertices for the sums over triangles to stand for the surfaces. When not given, it is
//! [`default_width`]: a tenth of the diagonal of the target's bounding box, or twice the mean
//! edge length of the target if that is larger.
//!
//! ## Which kind
//!
//! - [`Kind::Varifold`]: the target may be open, inconsistently oriented or of unknown
//!   orientation (meshes from segmentations, other software); thin parts do not cancel out.
//!   It cannot tell the two sides of a surface apart.
//! - [`Kind::OrientedVarifold`]: consistently oriented targets with thin parts (a sheet whose two
//!   sides are closer than `σ_w`): orientation is used, and opposite sides do not cancel.
//! - [`Kind::Current`]: consistently oriented, smooth closed targets, the cheapest; opposite
//!   normals within `σ_w` cancel, so thin parts and noise are invisible to it.

use super::{Attachment, AttachmentValue};
use crate::flow::kernel::{exp_neg_scaled, F64Lanes, GaussianKernel, PairSweep, PairTerms, LANES};
use crate::{Error, Result, TriMesh, Vec3};

/// The default width of the normal kernel of [`Kind::OrientedVarifold`] (that of geomstats):
/// `φ(0) = e⁻²`, `φ(−1) = e⁻⁴`.
pub const DEFAULT_NORMAL_WIDTH: f64 = 1.0;

/// Which distance between surfaces (see the [module documentation](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Kind {
    /// Unoriented varifold, `φ(t) = t²`.
    #[default]
    Varifold,
    /// Oriented varifold, `φ(t) = exp(−2(1 − t)/σ_n²)`.
    OrientedVarifold {
        /// `σ_n > 0` (dimensionless): how fast normals that differ by an angle `θ` part,
        /// `|u_f − u_g| = 2 sin(θ/2)`; usually [`DEFAULT_NORMAL_WIDTH`].
        normal_width: f64,
    },
    /// Current, `φ(t) = t`.
    Current,
}

/// The choices of a [`Varifold`] attachment.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VarifoldParams {
    /// The distance.
    pub kind: Kind,
    /// The spatial width `σ_w` (mm); [`default_width`] of the target when `None`.
    pub width: Option<f64>,
}

/// Fraction of the target's bounding-box diagonal taken as the default width.
const WIDTH_PER_DIAGONAL: f64 = 0.1;
/// Least default width, in mean target edge lengths.
const WIDTH_PER_EDGE: f64 = 2.0;

/// The width `σ_w` (mm) used when none is given: `max(d/10, 2ē)` with `d` the diagonal of the
/// bounding box of the target's triangle corners and `ē` the mean length of the triangles'
/// edges (each triangle's three). Refuses a mesh without triangles and one whose triangles all
/// lie at one point.
pub fn default_width(target: &TriMesh) -> Result<f64> {
    let points = target.points();
    let triangles = target.triangles();
    let mut corners = triangles.iter().flatten().map(|&v| points[v]);
    let first = corners
        .next()
        .ok_or_else(|| Error::InvalidMesh("the varifold target has no triangles".into()))?;
    let (lo, hi) = corners.fold((first, first), |(lo, hi), p| (lo.inf(&p), hi.sup(&p)));
    let edges: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| points[v]);
            (b - a).norm() + (c - b).norm() + (a - c).norm()
        })
        .sum();
    let width = (WIDTH_PER_DIAGONAL * (hi - lo).norm())
        .max(WIDTH_PER_EDGE * edges / (3 * triangles.len()) as f64);
    if width > 0.0 {
        Ok(width)
    } else {
        Err(Error::InvalidMesh(
            "the varifold target's triangles all lie at one point".into(),
        ))
    }
}

/// `g(q) = ‖S(q) − T‖²` between the source triangles over the landmarks and a fixed target
/// surface, as a varifold, oriented varifold or current (see the [module documentation](self)).
#[derive(Clone, Debug)]
pub struct Varifold {
    kind: Kind,
    width: f64,
    /// `exp(−r²/σ_w²)`: width `σ_w/√2` in the convention of [`GaussianKernel`].
    kernel: GaussianKernel,
    landmark_count: usize,
    triangles: Vec<[usize; 3]>,
    /// The numbers of the target faces in the sweep, with the sign `ε = −1` in `|n|`.
    target: Vec<FaceNumbers>,
    target_norm2: f64,
}

impl Varifold {
    /// The attachment of the surface `source_triangles` (corner indices into the `q` of
    /// [`Attachment::evaluate`], which has `landmark_count` points: for a template, its boundary
    /// triangles over the boundary points `0..nb`) to `target`.
    ///
    /// Refuses (`InvalidMesh`): a source or target without triangles, a source corner
    /// `≥ landmark_count` or a repeated corner, a target of zero area; (`InvalidParameter`) a
    /// width or normal width that is not a positive finite number.
    pub fn new(
        source_triangles: &[[usize; 3]],
        landmark_count: usize,
        target: &TriMesh,
        params: VarifoldParams,
    ) -> Result<Self> {
        check_source(source_triangles, landmark_count)?;
        if let Kind::OrientedVarifold { normal_width } = params.kind {
            check_width("normal width σ_n", normal_width)?;
        }
        let width = match params.width {
            Some(width) => check_width("width σ_w", width)?,
            None => default_width(target)?,
        };
        let points = target.points();
        let target_faces: Vec<FaceNumbers> = target
            .triangles()
            .iter()
            .map(|t| Face::new(t.map(|v| points[v])).numbers(-1.0))
            .collect();
        if target_faces.iter().all(|f| f[AREA] == 0.0) {
            return Err(Error::InvalidMesh(
                "the varifold target has no triangles or only triangles of zero area".into(),
            ));
        }
        let mut varifold = Self {
            kind: params.kind,
            width,
            kernel: GaussianKernel::new(width * std::f64::consts::FRAC_1_SQRT_2)?,
            landmark_count,
            triangles: source_triangles.to_vec(),
            target: Vec::new(),
            target_norm2: 0.0,
        };
        let sweep = PairSweep::new(&varifold.kernel, target_faces.len());
        varifold.target_norm2 = varifold.sweep(sweep, &target_faces).value(&target_faces);
        varifold.target = target_faces;
        Ok(varifold)
    }

    /// The distance.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// The spatial width `σ_w` (mm): as given, or [`default_width`].
    pub fn width(&self) -> f64 {
        self.width
    }

    /// Number of landmarks `k` expected by [`Attachment::evaluate`].
    pub fn landmark_count(&self) -> usize {
        self.landmark_count
    }

    /// `⟨T, T⟩` (mm⁴): `g` when the source is empty, the scale against which to read `g`.
    pub fn target_norm2(&self) -> f64 {
        self.target_norm2
    }

    /// `sweep` of the faces `faces` with the pair terms of the kind, run.
    fn sweep(&self, mut sweep: PairSweep<7, 8>, faces: &[FaceNumbers]) -> Sweep {
        for (i, &f) in faces.iter().enumerate() {
            sweep.set_point(i, f);
        }
        match self.kind {
            Kind::Varifold => sweep.run(&VarifoldTerms(Binet)),
            Kind::OrientedVarifold { normal_width } => sweep.run(&VarifoldTerms(SphereGaussian {
                scale: 2.0 / (normal_width * normal_width),
            })),
            Kind::Current => sweep.run(&VarifoldTerms(Linear)),
        }
        Sweep(sweep)
    }

    /// `q` and `grad` of the sizes [`Self::landmark_count`], `q` finite.
    fn check_inputs(&self, q: &[Vec3], grad: Option<&[Vec3]>) -> Result<()> {
        let sizes =
            std::iter::once(("landmarks", q.len())).chain(grad.map(|g| ("gradient", g.len())));
        for (what, found) in sizes {
            if found != self.landmark_count {
                return Err(Error::ShapeMismatch {
                    what: format!("varifold attachment {what}"),
                    expected: self.landmark_count,
                    found,
                });
            }
        }
        match q.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            Some(i) => Err(Error::NonFinite(format!(
                "landmark {i} is {:?} in the varifold attachment",
                q[i].as_slice()
            ))),
            None => Ok(()),
        }
    }
}

impl Attachment for Varifold {
    fn evaluate(&self, q: &[Vec3], grad: Option<&mut [Vec3]>) -> Result<AttachmentValue> {
        self.check_inputs(q, grad.as_deref())?;
        let source: Vec<Face> = (self.triangles.iter())
            .map(|t| Face::new(t.map(|v| q[v])))
            .collect();
        let mut faces: Vec<FaceNumbers> = source.iter().map(|f| f.numbers(1.0)).collect();
        faces.extend_from_slice(&self.target);
        let pairs = PairSweep::bipartite(&self.kernel, source.len(), self.target.len());
        let sweep = self.sweep(pairs, &faces);
        if let Some(grad) = grad {
            grad.fill(Vec3::zeros());
            let centre_factor = -4.0 / (self.width * self.width);
            for (i, (face, tri)) in source.iter().zip(&self.triangles).enumerate() {
                let sums = sweep.0.sums(i);
                let by_centre = centre_factor * face.area * Vec3::new(sums[1], sums[2], sums[3]);
                let by_normal = 2.0
                    * (face.normal + sums[4] * face.unit + Vec3::new(sums[5], sums[6], sums[7]));
                face.add_corner_gradients(tri, &by_centre, &by_normal, grad);
            }
        }
        Ok(AttachmentValue {
            value: sweep.bipartite_value(&faces, source.len(), self.target_norm2),
            dice: None,
        })
    }
}

/// Refuses an empty source, corners out of range and repeated corners.
fn check_source(triangles: &[[usize; 3]], landmark_count: usize) -> Result<()> {
    if triangles.is_empty() {
        return Err(Error::InvalidMesh(
            "the varifold source has no triangles".into(),
        ));
    }
    for (t, &[a, b, c]) in triangles.iter().enumerate() {
        if a.max(b).max(c) >= landmark_count {
            return Err(Error::InvalidMesh(format!(
                "varifold source triangle {t} = {:?} has a corner beyond the {landmark_count} landmarks",
                [a, b, c]
            )));
        }
        if a == b || b == c || a == c {
            return Err(Error::InvalidMesh(format!(
                "varifold source triangle {t} = {:?} repeats a corner",
                [a, b, c]
            )));
        }
    }
    Ok(())
}

/// `width` if it is a positive finite number whose `1/width²` is finite too.
fn check_width(what: &str, width: f64) -> Result<f64> {
    if width.is_finite() && width > 0.0 && (width * width).recip().is_finite() {
        Ok(width)
    } else {
        Err(Error::InvalidParameter(format!(
            "the varifold {what} must be a positive number, got {width}"
        )))
    }
}

/// The numbers of a face in the sweep: centre (3), unit normal (3), signed area `ε|n|`.
type FaceNumbers = [f64; 7];

/// Where the signed area sits in [`FaceNumbers`].
const AREA: usize = 6;

/// A triangle's corners and its centre, normal, area and unit normal.
#[derive(Clone, Copy, Debug)]
struct Face {
    corners: [Vec3; 3],
    /// `n = ½ (b − a) × (c − a)`.
    normal: Vec3,
    /// `|n|`.
    area: f64,
    /// `n/|n|`, or 0 if `|n| = 0`.
    unit: Vec3,
}

impl Face {
    fn new(corners: [Vec3; 3]) -> Self {
        let [a, b, c] = corners;
        let normal = 0.5 * (b - a).cross(&(c - a));
        let area = normal.norm();
        let unit = if area > 0.0 {
            normal / area
        } else {
            Vec3::zeros()
        };
        Self {
            corners,
            normal,
            area,
            unit,
        }
    }

    /// The numbers of the face in the sweep, with the sign `sign` (±1).
    fn numbers(&self, sign: f64) -> FaceNumbers {
        let [a, b, c] = self.corners;
        let centre = (a + b + c) / 3.0;
        let u = self.unit;
        [
            centre.x,
            centre.y,
            centre.z,
            u.x,
            u.y,
            u.z,
            sign * self.area,
        ]
    }

    /// Adds to `grad` at the corners `tri` the gradient from `∂g/∂c` (`by_centre`) and `∂g/∂n`
    /// (`by_normal`): `⅓ ∂g/∂c + ½ (b − c) × ∂g/∂n` at `a`, cyclically.
    fn add_corner_gradients(
        &self,
        tri: &[usize; 3],
        by_centre: &Vec3,
        by_normal: &Vec3,
        grad: &mut [Vec3],
    ) {
        let third = by_centre / 3.0;
        for (k, &v) in tri.iter().enumerate() {
            let (next, prev) = (self.corners[(k + 1) % 3], self.corners[(k + 2) % 3]);
            grad[v] += third + 0.5 * (next - prev).cross(by_normal);
        }
    }
}

/// A run sweep over faces: per face `a`, the sums over the others `b` of
/// `K_ab ε_b|n_b| ×` `[φ, φ·(c_a − c_b) (3), φ − tφ', φ' u_b (3)]`.
struct Sweep(PairSweep<7, 8>);

impl Sweep {
    /// `Σ_a Σ_b ε_a ε_b K_ab |n_a||n_b| φ(t_ab)` over all ordered pairs of `faces`, the faces
    /// swept: `Σ_a ε_a|n_a| (ε_a|n_a| + Σ_{b≠a} K_ab ε_b|n_b| φ)`, in face order.
    fn value(&self, faces: &[FaceNumbers]) -> f64 {
        (faces.iter().enumerate())
            .map(|(a, f)| f[AREA] * (f[AREA] + self.0.sums(a)[0]))
            .sum()
    }

    /// The same sum from a bipartite sweep whose faces `source..` are the target's, of
    /// `⟨T, T⟩ = target_norm2`: `Σ_{a<source} ε_a|n_a| (ε_a|n_a| + s_a) + Σ_{a≥source}
    /// ε_a|n_a| s_a + ⟨T, T⟩`, in face order.
    fn bipartite_value(&self, faces: &[FaceNumbers], source: usize, target_norm2: f64) -> f64 {
        let swept: f64 = (faces.iter().enumerate())
            .map(|(a, f)| {
                let own = if a < source { f[AREA] } else { 0.0 };
                f[AREA] * (own + self.0.sums(a)[0])
            })
            .sum();
        swept + target_norm2
    }
}

/// A kernel `φ(t)` on the unit normals, `t = u_a·u_b`, lane by lane.
trait NormalKernel: Sync {
    /// `[φ(t), φ'(t), φ(t) − tφ'(t)]`.
    fn eval<V: F64Lanes>(&self, t: V) -> [V; 3];
}

/// `φ(t) = t²` (unoriented varifold).
struct Binet;

impl NormalKernel for Binet {
    #[inline(always)]
    fn eval<V: F64Lanes>(&self, t: V) -> [V; 3] {
        let t2 = t * t;
        [t2, t * V::splat(2.0), V::splat(0.0) - t2]
    }
}

/// `φ(t) = exp(−s (1 − t))`, `s = 2/σ_n²` (oriented varifold).
struct SphereGaussian {
    scale: f64,
}

impl NormalKernel for SphereGaussian {
    #[inline(always)]
    fn eval<V: F64Lanes>(&self, t: V) -> [V; 3] {
        let phi = exp_neg_scaled(V::splat(1.0) - t, self.scale);
        let slope = phi * V::splat(self.scale);
        [phi, slope, t.neg_mul_add(slope, phi)]
    }
}

/// `φ(t) = t` (current).
struct Linear;

impl NormalKernel for Linear {
    #[inline(always)]
    fn eval<V: F64Lanes>(&self, t: V) -> [V; 3] {
        [t, V::splat(1.0), V::splat(0.0)]
    }
}

/// The pair terms of [`Sweep`] for the normal kernel `N`; a face carries [`FaceNumbers`].
struct VarifoldTerms<N>(N);

impl<N: NormalKernel> PairTerms<7, 8> for VarifoldTerms<N> {
    #[inline(always)]
    fn accumulate<V: F64Lanes>(
        &self,
        row: &[f64; 7],
        chunk: &[f64],
        kernel: V,
        d: &[V; 3],
        row_sums: &mut [V; 8],
        col_sums: &mut [f64],
    ) {
        let lanes = |f: usize| V::load(&chunk[LANES * f..]);
        let ui = [V::splat(row[3]), V::splat(row[4]), V::splat(row[5])];
        let uj = [lanes(3), lanes(4), lanes(5)];
        let t = ui[2].mul_add(uj[2], ui[1].mul_add(uj[1], ui[0] * uj[0]));
        let [phi, slope, rest] = self.0.eval(t);
        // K ε|n| of the other face, seen from the row and from the columns.
        let (kj, ki) = (kernel * lanes(AREA), kernel * V::splat(row[AREA]));
        let (ej, ei) = (kj * phi, ki * phi);
        row_sums[0] = kj.mul_add(phi, row_sums[0]);
        ki.mul_add_to(phi, col_sums);
        row_sums[4] = kj.mul_add(rest, row_sums[4]);
        ki.mul_add_to(rest, &mut col_sums[4 * LANES..]);
        let (sj, si) = (kj * slope, ki * slope);
        for c in 0..3 {
            row_sums[1 + c] = ej.mul_add(d[c], row_sums[1 + c]);
            ei.neg_mul_add_to(d[c], &mut col_sums[(1 + c) * LANES..]);
            row_sums[5 + c] = sj.mul_add(uj[c], row_sums[5 + c]);
            si.mul_add_to(ui[c], &mut col_sums[(5 + c) * LANES..]);
        }
    }
}
