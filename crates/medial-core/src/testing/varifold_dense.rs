//! An independent dense implementation of the varifold attachment
//! ([`crate::attachment::varifold`]): the three inner products `⟨S, S⟩`, `⟨S, T⟩`, `⟨T, T⟩`
//! term by term over ordered pairs with `f64::exp`, the normal kernels written on the
//! area-weighted normals themselves, and the gradient from their derivatives:
//!
//! ```text
//! ∂g/∂x_f = 2 Σ_{g∈S} ∂₁[K(c_f, c_g) k(n_f, n_g)] − 2 Σ_{g∈T} ∂₁[K(c_f, c_g) k(n_f, n_g)]
//! ```
//!
//! for `x_f = c_f, n_f`, then to the corners. The reference the fused implementation is tested
//! against and the baseline of its benchmark. Faces of zero area are not supported.
//!
//! Also a fixture for surfaces without correspondence: [`subdivided`], the same surface with
//! other vertices and four times the triangles.

use crate::attachment::varifold::Kind;
use crate::{TriMesh, Vec3};
use nalgebra::DMatrix;
use std::collections::HashMap;

/// Every triangle of `mesh` split in four at its edge midpoints (an edge shared by two
/// triangles is split once), with the orientation kept: the same surface, new vertices after
/// the old ones.
pub fn subdivided(mesh: &TriMesh) -> TriMesh {
    let mut points = mesh.points().to_vec();
    let mut split = HashMap::new();
    let mut midpoint = |a: usize, b: usize| {
        *split.entry((a.min(b), a.max(b))).or_insert_with(|| {
            points.push((points[a] + points[b]) / 2.0);
            points.len() - 1
        })
    };
    let triangles = (mesh.triangles().iter())
        .flat_map(|&[a, b, c]| {
            let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
            [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        })
        .collect();
    TriMesh::new(points, triangles).expect("the midpoints of a valid mesh make a valid mesh")
}

/// `g = ⟨S, S⟩ − 2⟨S, T⟩ + ⟨T, T⟩` and its gradient with respect to `q` (zero off the source
/// triangles) for the source triangles `source` over `q`, the target mesh
/// (`target_points`, `target`), the distance `kind` and the width `width` (`σ_w`).
pub fn attachment(
    q: &[Vec3],
    source: &[[usize; 3]],
    target_points: &[Vec3],
    target: &[[usize; 3]],
    kind: Kind,
    width: f64,
) -> (f64, Vec<Vec3>) {
    let s = Measure::new(q, source);
    let t = Measure::new(target_points, target);
    let pair = Pair { kind, width };
    let value = pair.inner(&s, &s) - 2.0 * pair.inner(&s, &t) + pair.inner(&t, &t);
    let (gc_ss, gn_ss) = pair.first_derivatives(&s, &s);
    let (gc_st, gn_st) = pair.first_derivatives(&s, &t);
    let gc = 2.0 * (gc_ss - gc_st);
    let gn = 2.0 * (gn_ss - gn_st);
    let mut grad = vec![Vec3::zeros(); q.len()];
    for (f, &[ia, ib, ic]) in source.iter().enumerate() {
        let (a, b, c) = (q[ia], q[ib], q[ic]);
        let dc = Vec3::new(gc[(f, 0)], gc[(f, 1)], gc[(f, 2)]) / 3.0;
        let dn = Vec3::new(gn[(f, 0)], gn[(f, 1)], gn[(f, 2)]);
        // n = ½ (a×b + b×c + c×a): ∂(dn·n)/∂a = ½ dn × (c − b), and so on.
        grad[ia] += dc + 0.5 * dn.cross(&(c - b));
        grad[ib] += dc + 0.5 * dn.cross(&(a - c));
        grad[ic] += dc + 0.5 * dn.cross(&(b - a));
    }
    (value, grad)
}

/// Centres and area-weighted normals of the triangles, one row per triangle.
struct Measure {
    centres: DMatrix<f64>,
    normals: DMatrix<f64>,
}

impl Measure {
    fn new(points: &[Vec3], triangles: &[[usize; 3]]) -> Self {
        let corner = |f: usize, k: usize| points[triangles[f][k]];
        let f = triangles.len();
        let centres = DMatrix::from_fn(f, 3, |f, x| {
            (corner(f, 0)[x] + corner(f, 1)[x] + corner(f, 2)[x]) / 3.0
        });
        let normals = DMatrix::from_fn(f, 3, |f, x| {
            ((corner(f, 1) - corner(f, 0)).cross(&(corner(f, 2) - corner(f, 0))) / 2.0)[x]
        });
        Self { centres, normals }
    }

    fn len(&self) -> usize {
        self.centres.nrows()
    }

    fn centre(&self, f: usize) -> Vec3 {
        Vec3::from_fn(|x, _| self.centres[(f, x)])
    }

    fn normal(&self, f: usize) -> Vec3 {
        Vec3::from_fn(|x, _| self.normals[(f, x)])
    }
}

/// The kernel `K(x, y) k(n, m)` of a kind and width.
struct Pair {
    kind: Kind,
    width: f64,
}

impl Pair {
    /// `K(x, y) = exp(−|x − y|²/σ_w²)`.
    fn spatial(&self, x: &Vec3, y: &Vec3) -> f64 {
        (-(x - y).norm_squared() / (self.width * self.width)).exp()
    }

    /// `k(n, m)` and `∂k/∂n`.
    fn normal(&self, n: &Vec3, m: &Vec3) -> (f64, Vec3) {
        let (ln, lm, nm) = (n.norm(), m.norm(), n.dot(m));
        match self.kind {
            Kind::Current => (nm, *m),
            Kind::Varifold => (
                nm * nm / (ln * lm),
                2.0 * nm / (ln * lm) * m - nm * nm / (ln.powi(3) * lm) * n,
            ),
            Kind::OrientedVarifold { normal_width } => {
                let (u, v) = (n / ln, m / lm);
                let s2 = normal_width * normal_width;
                let e = (-(u - v).norm_squared() / s2).exp();
                (ln * lm * e, lm * e * (u + 2.0 / s2 * (v - u.dot(&v) * u)))
            }
        }
    }

    /// `Σ_f Σ_g K(c_f, c_g) k(n_f, n_g)`.
    fn inner(&self, x: &Measure, y: &Measure) -> f64 {
        let terms = DMatrix::from_fn(x.len(), y.len(), |f, g| {
            self.spatial(&x.centre(f), &y.centre(g)) * self.normal(&x.normal(f), &y.normal(g)).0
        });
        terms.sum()
    }

    /// Per face `f` of `x`: `Σ_g ∂/∂c_f` and `Σ_g ∂/∂n_f` of `K(c_f, c_g) k(n_f, n_g)` over the
    /// faces `g` of `y` (rows of two `F_x × 3` matrices).
    fn first_derivatives(&self, x: &Measure, y: &Measure) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut by_centre = DMatrix::zeros(x.len(), 3);
        let mut by_normal = DMatrix::zeros(x.len(), 3);
        for f in 0..x.len() {
            let (cf, nf) = (x.centre(f), x.normal(f));
            for g in 0..y.len() {
                let (cg, ng) = (y.centre(g), y.normal(g));
                let kernel = self.spatial(&cf, &cg);
                let (k, dk) = self.normal(&nf, &ng);
                let dc = -2.0 / (self.width * self.width) * kernel * k * (cf - cg);
                let dn = kernel * dk;
                for c in 0..3 {
                    by_centre[(f, c)] += dc[c];
                    by_normal[(f, c)] += dn[c];
                }
            }
        }
        (by_centre, by_normal)
    }
}
