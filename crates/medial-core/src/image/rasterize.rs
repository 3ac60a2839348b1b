//! Binary rasterization of a closed triangle mesh on a voxel grid.
//!
//! A voxel centre is inside when a ray from it along the voxel `−i` axis crosses the surface an
//! odd number of times. The test runs in voxel coordinates (the mesh is mapped by the inverse of
//! the grid's affine map, which keeps inside and outside), where the rays are the grid lines
//! `(·, j, k)`. Whether a line pierces a triangle is decided with exact orientation predicates
//! on the projections to the `(j, k)` plane and *simulation of simplicity*: the line is moved by
//! `(ε, ε²)` with `ε → 0⁺`, so that a line through an edge or a vertex is counted in exactly one
//! of the triangles around it. The answer is therefore exact for every voxel centre that is not
//! on the surface itself, for any closed mesh (orientation and self-intersections do not
//! matter: crossing parity).

use nalgebra::Matrix4;
use rayon::prelude::*;
use std::ops::Range;

use crate::image::volume::{check_affine, voxel_count, Volume};
use crate::mesh::topology::{check_edges, MeshDefect, Orientation};
use crate::mesh::Bounds;
use crate::{Error, Result, TriMesh, Vec3};

/// Rasterizes the closed mesh `mesh` on the grid `dims`, `voxel_to_world`: 1 at voxel centres
/// inside, 0 outside. Refuses a mesh without triangles or with an edge not shared by exactly two
/// triangles, and an invalid grid (see [`Volume::new`]). Parallel over `k` slices, deterministic.
pub fn rasterize(mesh: &TriMesh, dims: [usize; 3], voxel_to_world: Matrix4<f64>) -> Result<Volume> {
    let slices = Slices::of(mesh, dims, &voxel_to_world)?;
    let mut data = vec![0.0; dims.iter().product()];
    data.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slice)| {
            for (row, crossings) in slice.chunks_mut(dims[0]).zip(slices.crossings(k)) {
                for run in inside_runs(&crossings, dims[0]) {
                    row[run].fill(1.0);
                }
            }
        });
    Volume::new(dims, data, voxel_to_world)
}

/// The voxels of the box of `size` voxels from voxel `start` of the grid `dims`,
/// `voxel_to_world` whose centres lie inside the closed mesh `mesh` (x fastest): the very
/// voxels [`rasterize`] marks there (the mesh is mapped to the whole grid's voxel coordinates
/// alike), without writing out the whole grid. Errors: those of [`rasterize`]; a box past the
/// grid is `InvalidParameter`.
pub fn rasterize_box(
    mesh: &TriMesh,
    dims: [usize; 3],
    voxel_to_world: Matrix4<f64>,
    start: [usize; 3],
    size: [usize; 3],
) -> Result<Vec<bool>> {
    if (0..3).any(|a| start[a] + size[a] > dims[a]) {
        return Err(Error::InvalidParameter(format!(
            "a box of {size:?} voxels from {start:?} is not within a grid of {dims:?}"
        )));
    }
    let slices = Slices::of(mesh, dims, &voxel_to_world)?;
    let [cx, cy, _] = size;
    let mut inside = vec![false; size.iter().product()];
    inside
        .par_chunks_mut((cx * cy).max(1))
        .enumerate()
        .for_each(|(k, slab)| {
            let rows = slices.crossings(start[2] + k);
            for (row, crossings) in slab.chunks_mut(cx).zip(&rows[start[1]..start[1] + cy]) {
                for run in inside_runs(crossings, dims[0]) {
                    let (a, b) = (run.start.max(start[0]), run.end.min(start[0] + cx));
                    if a < b {
                        row[a - start[0]..b - start[0]].fill(true);
                    }
                }
            }
        });
    Ok(inside)
}

/// The Dice coefficient `2 |M ∩ A| / (|M| + |A|)` between the voxels whose centres lie inside
/// the closed mesh `mesh` (`M`, see [`rasterize`]) and the voxels of `mask` above ½ (`A`), on
/// the grid of `mask`: the overlap a segmentation tool would report. 0 when both are empty.
/// Errors: those of [`rasterize`]. `M` is counted run by run along the rows, never written out
/// (the same counts as the rasterized volume's).
pub fn voxel_dice(mesh: &TriMesh, mask: &Volume) -> Result<f64> {
    let dims = mask.dims();
    let slices = Slices::of(mesh, dims, mask.voxel_to_world())?;
    let [nx, ny, _] = dims;
    let (both, inside) = mask
        .data()
        .par_chunks(nx * ny)
        .enumerate()
        .map(|(k, slice)| {
            let (mut both, mut inside) = (0usize, 0usize);
            for (row, crossings) in slice.chunks(nx).zip(slices.crossings(k)) {
                for run in inside_runs(&crossings, nx) {
                    inside += run.len();
                    both += row[run].iter().filter(|&&a| a > 0.5).count();
                }
            }
            (both, inside)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let foreground = mask.data().par_iter().filter(|&&a| a > 0.5).count();
    let count = inside + foreground;
    Ok(if count == 0 {
        0.0
    } else {
        2.0 * both as f64 / count as f64
    })
}

/// An axis-aligned grid of isotropic spacing `spacing_mm` covering the bounding box of `mesh`
/// plus `margin_mm` on every side ([`grid_around_bounds`]). Returns `(dims, voxel_to_world)`.
/// Refuses a non-positive or non-finite spacing, a negative or non-finite margin and a mesh
/// without points.
pub fn grid_around(
    mesh: &TriMesh,
    spacing_mm: f64,
    margin_mm: f64,
) -> Result<([usize; 3], Matrix4<f64>)> {
    let bounds = Bounds::of(mesh.points()).ok_or_else(|| {
        Error::InvalidMesh("cannot build a grid around a mesh without points".into())
    })?;
    grid_around_bounds(&bounds, spacing_mm, margin_mm)
}

/// An axis-aligned grid of isotropic spacing `spacing_mm` covering `bounds` plus `margin_mm`
/// on every side, centred on the box: `n_a = ⌈(extent_a + 2·margin)/h⌉ + 1` voxels along axis
/// `a`. Returns `(dims, voxel_to_world)`. Refuses a non-positive or non-finite spacing and a
/// negative or non-finite margin.
pub fn grid_around_bounds(
    bounds: &Bounds,
    spacing_mm: f64,
    margin_mm: f64,
) -> Result<([usize; 3], Matrix4<f64>)> {
    if !(spacing_mm.is_finite() && spacing_mm > 0.0) {
        return Err(Error::InvalidParameter(format!(
            "grid spacing must be a positive number of mm, got {spacing_mm}"
        )));
    }
    if !(margin_mm.is_finite() && margin_mm >= 0.0) {
        return Err(Error::InvalidParameter(format!(
            "grid margin must be a finite number of mm ≥ 0, got {margin_mm}"
        )));
    }
    let extent = bounds.extent() + Vec3::repeat(2.0 * margin_mm);
    let steps = extent.map(|e| (e / spacing_mm).ceil());
    if steps.iter().any(|&s| s > 1e7) {
        return Err(Error::InvalidParameter(format!(
            "a grid of spacing {spacing_mm} mm around extent {:?} mm would be too large",
            extent.as_slice()
        )));
    }
    let dims = [0, 1, 2].map(|a| steps[a] as usize + 1);
    let origin = bounds.centre() - steps * (spacing_mm / 2.0);
    let mut m = Matrix4::new_scaling(spacing_mm);
    m[(3, 3)] = 1.0;
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&origin);
    Ok((dims, m))
}

/// Refuses a mesh without triangles or with an edge used by other than two triangles (in
/// either direction: crossing parity does not need an orientation).
fn check_closed(triangles: &[[usize; 3]]) -> Result<()> {
    if triangles.is_empty() {
        return Err(Error::InvalidMesh(
            "cannot rasterize a mesh without triangles".into(),
        ));
    }
    let (a, b, uses, problem_edges) = match check_edges(triangles, Orientation::Any) {
        Ok(()) => return Ok(()),
        Err(MeshDefect::OpenEdge {
            a,
            b,
            problem_edges,
            ..
        }) => (a, b, 1, problem_edges),
        Err(MeshDefect::NonManifoldEdge {
            a,
            b,
            triangles,
            problem_edges,
        }) => (a, b, triangles.len(), problem_edges),
        Err(other) => return Err(other.into()),
    };
    Err(Error::InvalidMesh(format!(
        "cannot rasterize an open or non-manifold mesh: edge ({a}, {b}) is used by {uses} \
         triangle(s) instead of 2 ({problem_edges} such edges)"
    )))
}

/// For each slice `k`, the triangles whose `k` range (in voxel coordinates) contains `k`.
fn slice_buckets(points: &[Vec3], triangles: &[[usize; 3]], nz: usize) -> Vec<Vec<usize>> {
    let mut buckets = vec![Vec::new(); nz];
    for (t, tri) in triangles.iter().enumerate() {
        for k in index_range(tri.map(|v| points[v].z), nz) {
            buckets[k].push(t);
        }
    }
    buckets
}

/// The grid indices `n ∈ [0, len)` with `min(values) ≤ n ≤ max(values)`.
fn index_range(values: [f64; 3], len: usize) -> std::ops::Range<usize> {
    let lo = values
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .ceil()
        .max(0.0);
    let hi = values
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
        .floor()
        + 1.0;
    let hi = hi.clamp(0.0, len as f64);
    (lo as usize).min(hi as usize)..hi as usize
}

/// A closed mesh in voxel coordinates, its triangles sorted into the `k` slices they may cross.
struct Slices<'a> {
    points: Vec<Vec3>,
    triangles: &'a [[usize; 3]],
    buckets: Vec<Vec<usize>>,
    dims: [usize; 3],
}

impl<'a> Slices<'a> {
    /// `mesh` on the grid `dims`, `voxel_to_world`; refuses what [`rasterize`] refuses.
    fn of(mesh: &'a TriMesh, dims: [usize; 3], voxel_to_world: &Matrix4<f64>) -> Result<Self> {
        check_closed(mesh.triangles())?;
        voxel_count(dims)?;
        let to_voxel = check_affine(voxel_to_world)?;
        let points: Vec<Vec3> = mesh
            .points()
            .iter()
            .map(|p| (to_voxel * p.push(1.0)).xyz())
            .collect();
        let buckets = slice_buckets(&points, mesh.triangles(), dims[2]);
        Ok(Self {
            points,
            triangles: mesh.triangles(),
            buckets,
            dims,
        })
    }

    /// The sorted crossings of each of the `ny` rows of slice `k` with the mesh.
    fn crossings(&self, k: usize) -> Vec<Vec<f64>> {
        let ny = self.dims[1];
        let mut crossings = vec![Vec::new(); ny];
        for &t in &self.buckets[k] {
            let tri = self.triangles[t];
            for j in index_range(tri.map(|v| self.points[v].y), ny) {
                if let Some(x) = line_crossing(&self.points, tri, j as f64, k as f64) {
                    crossings[j].push(x);
                }
            }
        }
        for xs in &mut crossings {
            xs.sort_unstable_by(f64::total_cmp);
        }
        crossings
    }
}

/// The runs of voxels `i` of a row of `len` with an odd number of the sorted crossings below
/// them (the centres inside), disjoint and in order.
fn inside_runs(sorted_crossings: &[f64], len: usize) -> impl Iterator<Item = Range<usize>> + '_ {
    sorted_crossings.chunks(2).map(move |pair| {
        // The first voxel above the entering crossing, and the first not below the leaving one
        // (none: the row's end); `as` saturates a negative end at 0.
        let start = pair[0].max(-1.0).floor() + 1.0;
        let end = pair
            .get(1)
            .copied()
            .unwrap_or(f64::INFINITY)
            .min(len as f64)
            .ceil() as usize;
        (start as usize).min(end)..end
    })
}

/// Where the (perturbed) grid line `(·, y, z)` pierces triangle `tri`: its `x`, or `None`.
fn line_crossing(points: &[Vec3], tri: [usize; 3], y: f64, z: f64) -> Option<f64> {
    let side = |e: usize| edge_side(points, tri[e], tri[(e + 1) % 3], y, z);
    let signs = [side(0), side(1), side(2)];
    if signs[0] == 0 || signs[0] != signs[1] || signs[1] != signs[2] {
        return None;
    }
    // Barycentric coordinates from the (approximate) orientations; clamped so that the
    // crossing stays within the triangle's x range even for a nearly edge-on triangle.
    let p = tri.map(|v| points[v]);
    let q = Vec3::new(0.0, y, z);
    let weights = [
        orient_approx(&p[1], &p[2], &q),
        orient_approx(&p[2], &p[0], &q),
        orient_approx(&p[0], &p[1], &q),
    ]
    .map(|w| (w * f64::from(signs[0])).max(0.0));
    let total: f64 = weights.iter().sum();
    if total == 0.0 {
        return Some(p.iter().map(|p| p.x).sum::<f64>() / 3.0);
    }
    Some((0..3).map(|c| weights[c] * p[c].x).sum::<f64>() / total)
}

/// Side of the perturbed point `(y + ε, z + ε²)` with respect to the directed edge `a → b` of
/// the projection on the `(y, z)` plane: `+1` left, `−1` right, `0` only when the projected edge
/// has zero length. Evaluated for the edge in increasing index order and negated otherwise, so
/// that the two triangles sharing an edge always agree.
fn edge_side(points: &[Vec3], a: usize, b: usize, y: f64, z: f64) -> i8 {
    let (lo, hi, flip) = if a < b { (a, b, 1) } else { (b, a, -1) };
    let (p, q) = (&points[lo], &points[hi]);
    let exact = orient_sign(p.y, p.z, q.y, q.z, y, z);
    let sign = if exact != 0 {
        exact
    } else if q.z != p.z {
        // d/dε of orient = −(q.z − p.z).
        if q.z < p.z {
            1
        } else {
            -1
        }
    } else if q.y != p.y {
        // d/dε² of orient = (q.y − p.y).
        if q.y > p.y {
            1
        } else {
            -1
        }
    } else {
        0
    };
    sign * flip
}

/// `(b − a) × (c − a)` in the `(y, z)` plane, in floating point.
fn orient_approx(a: &Vec3, b: &Vec3, c: &Vec3) -> f64 {
    (b.y - a.y) * (c.z - a.z) - (b.z - a.z) * (c.y - a.y)
}

/// Exact sign of `(by − ay)(cz − az) − (bz − az)(cy − ay)`: a floating-point filter, and
/// error-free transformations (two-sum, fused two-product) summed into a non-overlapping
/// expansion when the filter cannot decide.
fn orient_sign(ay: f64, az: f64, by: f64, bz: f64, cy: f64, cz: f64) -> i8 {
    let (l, r) = ((by - ay) * (cz - az), (bz - az) * (cy - ay));
    let det = l - r;
    // Each difference and product has relative error ≤ 2⁻⁵³; 1e-14 is a safe bound.
    if det.abs() > 1e-14 * (l.abs() + r.abs()) {
        return sign_of(det);
    }
    let mut expansion = Expansion::default();
    for (u, v, w, x, s) in [(by, ay, cz, az, 1.0), (bz, az, cy, ay, -1.0)] {
        let (d1, e1) = two_diff(u, v);
        let (d2, e2) = two_diff(w, x);
        for (f, g) in [(d1, d2), (d1, e2), (e1, d2), (e1, e2)] {
            let (p, e) = two_product(f, g);
            expansion.add(s * p);
            expansion.add(s * e);
        }
    }
    expansion.sign()
}

fn sign_of(v: f64) -> i8 {
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

/// `a − b = d + e` exactly (Knuth's two-sum).
fn two_diff(a: f64, b: f64) -> (f64, f64) {
    let d = a - b;
    let bv = a - d;
    let av = d + bv;
    (d, (a - av) + (bv - b))
}

/// `a · b = p + e` exactly (fused multiply-add).
fn two_product(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

/// `a + b = s + e` exactly (Knuth's two-sum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bv = s - a;
    let av = s - bv;
    (s, (a - av) + (b - bv))
}

/// An exact sum of up to 16 doubles as a non-overlapping expansion of increasing magnitude
/// (Shewchuk's Grow-Expansion with zero elimination).
#[derive(Default)]
struct Expansion {
    terms: [f64; 16],
    len: usize,
}

impl Expansion {
    fn add(&mut self, b: f64) {
        let mut q = b;
        let mut out = 0;
        for n in 0..self.len {
            let (s, e) = two_sum(q, self.terms[n]);
            q = s;
            if e != 0.0 {
                self.terms[out] = e;
                out += 1;
            }
        }
        if q != 0.0 {
            self.terms[out] = q;
            out += 1;
        }
        self.len = out;
    }

    /// The sign of the sum: that of the largest (last) non-zero term.
    fn sign(&self) -> i8 {
        self.terms[..self.len].last().map_or(0, |&v| sign_of(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector4;

    /// The octahedron of [`crate::testing::meshes::octahedron`] scaled by r and centred at c.
    fn octahedron(c: Vec3, r: f64) -> TriMesh {
        let (points, triangles) = crate::testing::meshes::octahedron();
        TriMesh::new(points.iter().map(|p| c + r * p).collect(), triangles).unwrap()
    }

    /// A box of the grid holds the very voxels the whole grid's rasterization marks there,
    /// centres on the octahedron's faces (lattice planes of the grid) included; a box past the
    /// grid is refused.
    #[test]
    fn a_box_is_rasterized_as_the_whole_grid_is_there() {
        let mesh = octahedron(Vec3::zeros(), 1.0);
        let (dims, grid) = grid_around(&mesh, 0.1, 0.2).unwrap();
        let whole = rasterize(&mesh, dims, grid).unwrap();
        for (start, size) in [
            ([0, 0, 0], dims),
            ([3, 7, 11], [9, 4, 6]),
            ([12, 0, 5], [1, 25, 1]),
        ] {
            let part = rasterize_box(&mesh, dims, grid, start, size).unwrap();
            let [cx, cy, _] = size;
            for (n, &inside) in part.iter().enumerate() {
                let [i, j, k] = [
                    n % cx + start[0],
                    (n / cx) % cy + start[1],
                    n / (cx * cy) + start[2],
                ];
                let at = whole.data()[i + dims[0] * (j + dims[1] * k)];
                assert_eq!(
                    inside,
                    at > 0.5,
                    "voxel {:?} of the box {start:?}, {size:?}",
                    [i, j, k]
                );
            }
        }
        assert!(rasterize_box(&mesh, dims, grid, [1, 0, 0], dims).is_err());
    }

    #[test]
    fn exact_orientation_sees_tiny_determinants() {
        // Points on a line with a perturbation far below the filter's resolution.
        let up = f64::from_bits(0.7f64.to_bits() + 1);
        let down = f64::from_bits(0.7f64.to_bits() - 1);
        assert_eq!(orient_sign(0.1, 0.1, 0.3, 0.3, 0.7, up), 1);
        assert_eq!(orient_sign(0.1, 0.1, 0.3, 0.3, 0.7, down), -1);
        assert_eq!(orient_sign(0.1, 0.1, 0.3, 0.3, 0.7, 0.7), 0);
        assert_eq!(orient_sign(1.0, 1.0, 3.0, 3.0, 7.0, 7.0), 0);
        // 0.1 and 0.3 are not exactly collinear with 0.7 in binary: the exact sign is decided.
        let s = orient_sign(0.1, 0.1, 0.3, 0.30000000000000004, 0.7, 0.7);
        assert_ne!(s, 0);
    }

    #[test]
    fn lines_through_vertices_and_edges_count_once() {
        // The octahedron's vertices and edges sit exactly on grid lines: every voxel centre
        // strictly inside must be 1, every one strictly outside 0 (|x|+|y|+|z| < 4 or > 4).
        let mesh = octahedron(Vec3::new(4.0, 4.0, 4.0), 4.0);
        let v = rasterize(&mesh, [9, 9, 9], Matrix4::identity()).unwrap();
        for (n, &value) in v.data().iter().enumerate() {
            let (i, j, k) = ((n % 9) as f64, ((n / 9) % 9) as f64, (n / 81) as f64);
            let l1 = (i - 4.0).abs() + (j - 4.0).abs() + (k - 4.0).abs();
            if l1 < 4.0 {
                assert_eq!(value, 1.0, "voxel ({i}, {j}, {k})");
            } else if l1 > 4.0 {
                assert_eq!(value, 0.0, "voxel ({i}, {j}, {k})");
            }
        }
    }

    /// `voxel_dice` counts runs along the rows; it must give the counts of the rasterized
    /// volume, on grids the mesh leaves on either side, with rows through its vertices, and
    /// against a graded mask cut at ½.
    #[test]
    fn voxel_dice_counts_what_rasterize_writes() {
        let counted = |mesh: &TriMesh, mask: &Volume| {
            let model = rasterize(mesh, mask.dims(), *mask.voxel_to_world()).unwrap();
            let (mut both, mut count) = (0usize, 0usize);
            for (&m, &a) in model.data().iter().zip(mask.data()) {
                both += usize::from(m > 0.5 && a > 0.5);
                count += usize::from(m > 0.5) + usize::from(a > 0.5);
            }
            2.0 * both as f64 / count as f64
        };
        let mut grid = Matrix4::new_scaling(0.3);
        grid[(3, 3)] = 1.0;
        grid[(0, 3)] = -0.7;
        let graded: Vec<f64> = (0..17 * 13 * 11)
            .map(|n| ((n * 7919) % 101) as f64 / 100.0)
            .collect();
        let mask = Volume::new([17, 13, 11], graded, grid).unwrap();
        for mesh in [
            octahedron(Vec3::new(2.2, 1.9, 1.5), 1.7),
            octahedron(Vec3::new(-0.4, 3.5, 1.2), 2.5),
            octahedron(Vec3::new(1.4, 1.2, 1.5), 0.9),
        ] {
            let dice = voxel_dice(&mesh, &mask).unwrap();
            assert!(dice > 0.0);
            assert_eq!(dice, counted(&mesh, &mask));
        }
        let on_lines = octahedron(Vec3::new(4.0, 4.0, 4.0), 4.0);
        let binary = rasterize(
            &octahedron(Vec3::new(4.5, 4.0, 3.0), 3.5),
            [9, 9, 9],
            Matrix4::identity(),
        )
        .unwrap();
        assert_eq!(
            voxel_dice(&on_lines, &binary).unwrap(),
            counted(&on_lines, &binary)
        );
    }

    #[test]
    fn orientation_of_the_mesh_does_not_matter() {
        let mesh = octahedron(Vec3::new(2.2, 1.9, 2.05), 1.7);
        let (points, triangles) = mesh.clone().into_parts();
        let flipped = TriMesh::new(
            points,
            triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
        )
        .unwrap();
        let mut grid = Matrix4::new_scaling(0.25);
        grid[(3, 3)] = 1.0;
        let a = rasterize(&mesh, [20, 20, 20], grid).unwrap();
        let b = rasterize(&flipped, [20, 20, 20], grid).unwrap();
        // Every voxel centre off the surface is classified right, whatever the orientation
        // (centres exactly on a face may go either way).
        for (n, (&va, &vb)) in a.data().iter().zip(b.data()).enumerate() {
            let p = a.voxel_centre([n % 20, (n / 20) % 20, n / 400]);
            let l1 = (p - Vec3::new(2.2, 1.9, 2.05)).abs().sum();
            if (l1 - 1.7).abs() > 1e-9 {
                let expected = f64::from(u8::from(l1 < 1.7));
                assert!(
                    va == expected && vb == expected,
                    "voxel {n}: |p − c|₁ = {l1}"
                );
            }
        }
        // Volume of the octahedron: 4/3 r³.
        let exact = 4.0 / 3.0 * 1.7f64.powi(3);
        assert!(
            (a.integral() - exact).abs() < 0.1 * exact,
            "{} vs {exact}",
            a.integral()
        );
    }

    #[test]
    fn refuses_open_meshes_and_bad_grids() {
        let (points, mut triangles) = octahedron(Vec3::zeros(), 1.0).into_parts();
        triangles.pop();
        let open = TriMesh::new(points, triangles).unwrap();
        let err = rasterize(&open, [4, 4, 4], Matrix4::identity())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("edge (0, 3)") && err.contains("3 such edges"),
            "{err}"
        );
        let mesh = octahedron(Vec3::zeros(), 1.0);
        assert!(rasterize(&mesh, [4, 0, 4], Matrix4::identity()).is_err());
        assert!(grid_around(&mesh, 0.0, 1.0).is_err());
        assert!(grid_around(&mesh, 1.0, -1.0).is_err());
    }

    #[test]
    fn grid_around_covers_the_mesh_with_margin() {
        let mesh = octahedron(Vec3::new(10.0, -3.0, 2.0), 2.0);
        let (dims, m) = grid_around(&mesh, 0.5, 1.0).unwrap();
        assert_eq!(dims, [13, 13, 13]);
        let first = (m * Vector4::new(0.0, 0.0, 0.0, 1.0)).xyz();
        let last = (m * Vector4::new(12.0, 12.0, 12.0, 1.0)).xyz();
        assert!((first - Vec3::new(7.0, -6.0, -1.0)).norm() < 1e-12);
        assert!((last - Vec3::new(13.0, 0.0, 5.0)).norm() < 1e-12);
    }
}
