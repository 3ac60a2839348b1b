//! Medial points with a radius from the feature transform of a mask: the ridge of the distance
//! map, found where the nearest boundary points of two neighbouring voxels spread widely.

use rayon::prelude::*;
use std::collections::{HashMap, HashSet};

use crate::construction::inflate::UnionFind;
use crate::image::distance::{FeatureTransform, NO_FEATURE};
use crate::image::Volume;
use crate::{Error, Result, Vec3};

/// Least spread `|f_x − f_y|` of the nearest boundary points of a medial point, voxels.
const SPREAD_VOXELS: f64 = 3.0;

/// A medial point: the centre of a ball inscribed in the shape, and the ball's radius (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MedialPoint {
    /// Position (mm).
    pub position: Vec3,
    /// Radius (mm).
    pub radius: f64,
}

/// The medial points of the mask `mask` (voxels > ½ inside), largest connected piece only:
/// [`medial_pieces`] without the share it leaves out.
///
/// Errors: those of [`medial_pieces`].
pub fn medial_points(mask: &Volume, min_angle_deg: f64) -> Result<Vec<MedialPoint>> {
    medial_pieces(mask, min_angle_deg).map(|(points, _)| points)
}

/// The medial points of the mask `mask` (voxels > ½ inside), largest connected piece only, and
/// the share of the largest piece left out: its points' summed radii over all points' (each
/// point stands for about a voxel face of sheet, so this is about its share of the shape's
/// volume). Small pieces are islands of boundary noise; a large one is a wall whose medial
/// points do not reach the rest, e.g. a thin wall joined to a thick one where the two sides
/// stop facing each other, which the sheet built from the largest piece leaves out. Two
/// points closer than the smaller of their radii ([`JOIN_RADII`]) are in one piece; two pieces
/// each holding more than [`LEFT_OUT_LIMIT`] of the shape (walls) join where two of their
/// points are closer than the larger radius, a gap the wide-angle rule leaves where a thin
/// wall widens into a thick one.
///
/// For every pair of face-neighbouring inside voxels `x, y` with nearest background voxels
/// `f_x, f_y`, the midpoint `m = (x + y)/2` is a medial point when the feature vectors
/// `f_x − m`, `f_y − m` make an angle of at least `min_angle_deg` and `|f_x − f_y| ≥ 3h`
/// (`h` the mean voxel size): the two neighbours see opposite sides of the shape. This is a
/// discrete λ-medial axis (Chazal & Lieutier 2005) with a scale-free angle in place of λ: it is
/// stable under boundary noise (a bump of a voxel spreads the features by less than `3h` or
/// by a small angle) and it ends where the two sides stop facing each other, so that a rim is
/// trimmed back to where a rounded inflation reproduces it. The radius is
/// `(|f_x − m| + |f_y − m|)/2 − h/2`: the background voxel centres lie on average half a voxel
/// beyond the boundary.
///
/// Errors: `InvalidVolume` for a grid whose axes are not orthogonal (the transform needs them),
/// a shape touching the border of its grid, or one without medial points.
pub fn medial_pieces(mask: &Volume, min_angle_deg: f64) -> Result<(Vec<MedialPoint>, f64)> {
    let spacing = orthogonal_spacing(mask)?;
    let dims = mask.dims();
    let inside: Vec<bool> = mask.data().iter().map(|&v| v > 0.5).collect();
    check_border(&inside, dims)?;
    let transform = FeatureTransform::new(&inside, dims, spacing)?;
    let h = spacing.iter().sum::<f64>() / 3.0;
    let cos_max = min_angle_deg.to_radians().cos();
    let stride = [1, dims[0], dims[0] * dims[1]];
    let centre = |n: usize| mask.voxel_centre(index_of(n, dims));
    let points: Vec<MedialPoint> = (0..dims[2])
        .into_par_iter()
        .flat_map_iter(|k| {
            let slice = k * stride[2]..(k + 1) * stride[2];
            let (inside, transform, centre) = (&inside, &transform, &centre);
            slice.flat_map(move |n| {
                (0..3).filter_map(move |a| {
                    let m = n + stride[a];
                    let neighbour = index_of(n, dims)[a] + 1 < dims[a];
                    if !(neighbour && inside[n] && inside[m]) {
                        return None;
                    }
                    let (fx, fy) = (transform.feature(n), transform.feature(m));
                    if fx == NO_FEATURE || fy == NO_FEATURE || fx == fy {
                        return None;
                    }
                    let mid = (centre(n) + centre(m)) / 2.0;
                    let (px, py) = (centre(fx as usize), centre(fy as usize));
                    let (u, v) = (px - mid, py - mid);
                    let wide = u.dot(&v) <= cos_max * u.norm() * v.norm();
                    (wide && (px - py).norm() >= SPREAD_VOXELS * h).then(|| MedialPoint {
                        position: mid,
                        radius: (u.norm() + v.norm()) / 2.0 - h / 2.0,
                    })
                })
            })
        })
        .collect();
    let (points, left_out) = largest_piece(points, h);
    if points.is_empty() {
        return Err(Error::InvalidVolume(
            "the shape has no medial points: it is empty or thinner than two voxels everywhere"
                .into(),
        ));
    }
    Ok((points, left_out))
}

/// The voxel sizes along i, j, k (mm), refusing a grid whose axes are not orthogonal.
fn orthogonal_spacing(mask: &Volume) -> Result<[f64; 3]> {
    let m = mask.voxel_to_world();
    let column = |a: usize| Vec3::new(m[(0, a)], m[(1, a)], m[(2, a)]);
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let (ca, cb) = (column(a), column(b));
        if ca.dot(&cb).abs() > 1e-6 * ca.norm() * cb.norm() {
            return Err(Error::InvalidVolume(format!(
                "the voxel axes {a} and {b} are not orthogonal; resample the mask onto an \
                 orthogonal grid first"
            )));
        }
    }
    Ok([0, 1, 2].map(|a| column(a).norm()))
}

fn index_of(n: usize, dims: [usize; 3]) -> [usize; 3] {
    [
        n % dims[0],
        (n / dims[0]) % dims[1],
        n / (dims[0] * dims[1]),
    ]
}

/// Refuses a mask with an inside voxel on the border of the grid: the boundary beyond it is not
/// known.
fn check_border(inside: &[bool], dims: [usize; 3]) -> Result<()> {
    let on_border = |n: usize| {
        let i = index_of(n, dims);
        (0..3).any(|a| i[a] == 0 || i[a] + 1 == dims[a])
    };
    match (0..inside.len()).find(|&n| inside[n] && on_border(n)) {
        Some(n) => Err(Error::InvalidVolume(format!(
            "the shape touches the border of its grid at voxel {:?}; pad the mask by a voxel",
            index_of(n, dims)
        ))),
        None => Ok(()),
    }
}

/// Two medial points closer than this many times the smaller of their radii are in one piece:
/// at 1, each centre lies in the other's inscribed ball, one part of the shape.
pub const JOIN_RADII: f64 = 1.0;

/// The largest share of the shape (by the medial points' summed radii, about area ×
/// thickness) that a piece of its medial points left out of the sheet may hold in a template
/// that meets its targets: islands of boundary noise and corners hold far less; a piece of a
/// twentieth of the shape is a wall whose medial points do not reach the rest (a thin wall
/// tapering into a thick one). Two such pieces also join by the larger of two points' radii,
/// not only the smaller ([`medial_pieces`]).
pub const LEFT_OUT_LIMIT: f64 = 0.05;

/// Joins (in `uf`, over the cells `cell_of` of `points`) the pieces with two points closer than
/// [`JOIN_RADII`] times the smaller of their radii: a gap in the ridge at the scale of the
/// wall, not of the voxel. Near where a thin wall meets a thick one its radius grows fast, the
/// wide-angle rule drops a short stretch of points (about a millimetre on a 4 mm wall), and a
/// join of a voxel or two bridged it on a coarse grid and not on a fine one.
///
/// Two pieces each holding more than [`LEFT_OUT_LIMIT`] of the shape are walls, not noise, and
/// join where a point of one lies within the inscribed ball of a point of the other (closer
/// than the larger radius; the segment between them is inside that ball, inside the shape).
/// Where a thin wall widens into a thick one, the stretch the wide-angle rule drops reaches up
/// to the thick wall's radius, which the thin wall's own does not span on a coarse grid (a
/// two-ventricle shape on 1 mm voxels: a gap of 3.2 mm between radii of 2.2 and 4.3 mm). A
/// smaller piece joins anything by the smaller radius only: an island of boundary noise joined
/// by the larger would be a spur (on the same shape sampled half a voxel over, one made it two
/// sheets).
///
/// Returns the bridges across the gaps only the larger radius spans: where two walls stay
/// apart by the smaller radius, each point of one that the larger joins to the other, with the
/// nearest such point of the other ([`bridged`] fills the segment between them with points).
fn join_at_their_scale(
    points: &[MedialPoint],
    cell_of: &[usize],
    uf: &mut UnionFind,
) -> Vec<(usize, usize)> {
    let reach = JOIN_RADII * points.iter().map(|p| p.radius).fold(0.0, f64::max);
    if reach.is_nan() || reach <= 0.0 {
        return Vec::new();
    }
    let key = |p: &Vec3| {
        let k = p.map(|c| (c / reach).floor() as i64);
        [k.x, k.y, k.z]
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(key(&p.position)).or_default().push(i);
    }
    // Only points off the largest piece can join anything: the search runs from them.
    let root: Vec<usize> = cell_of.iter().map(|&c| uf.find(c)).collect();
    let Some((largest, size)) = largest_of(points, &root) else {
        return Vec::new();
    };
    let whole: f64 = points.iter().map(|p| p.radius).sum();
    let wall = |i: usize| size[&root[i]] > LEFT_OUT_LIMIT * whole;
    let off: Vec<usize> = (0..points.len()).filter(|&i| root[i] != largest).collect();
    // Per point off the largest piece: the pairs of join cells with two points within the
    // smaller radius, those of two walls within the larger only, and the nearest point of
    // another wall within the larger radius only (the union is order-free, so the parallel
    // search gives the same pieces).
    let found: Vec<Joins> = off
        .par_iter()
        .map(|&i| {
            let k = key(&points[i].position);
            let mut joins = Joins::default();
            for d in 0..27 {
                let o = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
                let Some(others) = grid.get(&[k[0] + o[0], k[1] + o[1], k[2] + o[2]]) else {
                    continue;
                };
                for &j in others {
                    if root[i] == root[j] {
                        continue;
                    }
                    let (ri, rj) = (points[i].radius, points[j].radius);
                    let d = (points[i].position - points[j].position).norm();
                    let cells = (cell_of[i], cell_of[j]);
                    if d <= JOIN_RADII * ri.min(rj) {
                        joins.near.insert(cells);
                    } else if wall(i) && wall(j) && d <= JOIN_RADII * ri.max(rj) {
                        joins.walls.insert(cells);
                        if joins.bridge.map_or(true, |(_, e)| d < e) {
                            joins.bridge = Some((j, d));
                        }
                    }
                }
            }
            joins
        })
        .collect();
    for joins in &found {
        joins.near.iter().for_each(|&(a, b)| uf.union(a, b));
    }
    let bridges = (off.iter().zip(&found))
        .filter_map(|(&i, joins)| joins.bridge.map(|(j, _)| (i, j)))
        .filter(|&(i, j)| uf.find(cell_of[i]) != uf.find(cell_of[j]))
        .collect();
    for joins in &found {
        joins.walls.iter().for_each(|&(a, b)| uf.union(a, b));
    }
    bridges
}

/// What a point off the largest piece joins ([`join_at_their_scale`]).
#[derive(Default)]
struct Joins {
    /// Pairs of cells with two points within the smaller of their radii.
    near: HashSet<(usize, usize)>,
    /// Pairs of cells of two walls with two points within the larger radius only.
    walls: HashSet<(usize, usize)>,
    /// The nearest point of another wall within the larger radius only, and its distance.
    bridge: Option<(usize, f64)>,
}

/// Points about every `step` mm along the segments `bridges` (pairs of indices into
/// `points`), the radius linear between the ends', each with its segment's first end: the
/// medial points of the stretch where a thin wall widens into a thick one, which the
/// wide-angle rule dropped. Without them the walls joined there meet without a junction, and
/// no seam is seen where they meet.
fn bridged(
    points: &[MedialPoint],
    bridges: &[(usize, usize)],
    step: f64,
) -> Vec<(usize, MedialPoint)> {
    (bridges.iter())
        .flat_map(|&(i, j)| {
            let (a, b) = (points[i], points[j]);
            let n = ((b.position - a.position).norm() / step).floor() as usize;
            (1..n).map(move |s| {
                let t = s as f64 / n as f64;
                let point = MedialPoint {
                    position: a.position + t * (b.position - a.position),
                    radius: a.radius + t * (b.radius - a.radius),
                };
                (i, point)
            })
        })
        .collect()
}

/// The piece (root) of the largest total radius `Σ r` over `points` whose pieces are `root`
/// (ties to the smallest root), with every piece's `Σ r`; none without points.
fn largest_of(points: &[MedialPoint], root: &[usize]) -> Option<(usize, HashMap<usize, f64>)> {
    let mut size: HashMap<usize, f64> = HashMap::new();
    for (p, &r) in points.iter().zip(root) {
        *size.entry(r).or_default() += p.radius;
    }
    let best = (size.iter())
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(&r, _)| r)?;
    Some((best, size))
}

/// The points of the largest piece by total radius `Σ r` (so that thin spurs weigh little), two
/// points being joined when their cells of 1.5 voxels (`voxel`, mm) touch (26-neighbourhood)
/// or when they are closer than the smaller of their radii, or the larger between walls
/// ([`join_at_their_scale`], whose bridges add points a voxel apart); ties to the piece with
/// the smallest root. Drops the islands that boundary noise and corners make, and says what
/// share of the whole `Σ r` the largest of them held (0 with one piece).
fn largest_piece(points: Vec<MedialPoint>, voxel: f64) -> (Vec<MedialPoint>, f64) {
    let cell = 1.5 * voxel;
    let key = |p: &Vec3| p.map(|c| (c / cell).floor() as i64);
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let mut cell_of = Vec::with_capacity(points.len());
    for p in &points {
        let k = key(&p.position);
        let next = cells.len();
        cell_of.push(*cells.entry([k.x, k.y, k.z]).or_insert(next));
    }
    let mut uf = UnionFind::new(cells.len());
    for (k, &c) in &cells {
        for d in 0..27 {
            let offset = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
            let other = [k[0] + offset[0], k[1] + offset[1], k[2] + offset[2]];
            if let Some(&o) = cells.get(&other) {
                uf.union(c, o);
            }
        }
    }
    let bridges = join_at_their_scale(&points, &cell_of, &mut uf);
    let bridge_points = bridged(&points, &bridges, voxel);
    let cells_of_bridges = bridge_points.iter().map(|&(i, _)| cell_of[i]);
    let all_cells: Vec<usize> = cell_of.iter().copied().chain(cells_of_bridges).collect();
    let root: Vec<usize> = all_cells.iter().map(|&c| uf.find(c)).collect();
    let mut points = points;
    points.extend(bridge_points.into_iter().map(|(_, p)| p));
    let Some((best, size)) = largest_of(&points, &root) else {
        return (points, 0.0);
    };
    let whole: f64 = points.iter().map(|p| p.radius).sum();
    let left_out = (size.iter())
        .filter(|&(&r, _)| r != best)
        .map(|(_, &s)| s / whole)
        .fold(0.0, f64::max);
    let kept = (points.into_iter().zip(root))
        .filter(|&(_, r)| r == best)
        .map(|(p, _)| p)
        .collect();
    (kept, left_out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    /// A slab `|z| ≤ half` of a grid of voxel `h`, padded.
    fn slab(half: f64, h: f64) -> Volume {
        let n = 21;
        let mut m = Matrix4::new_scaling(h);
        m[(3, 3)] = 1.0;
        let o = -(n as f64 - 1.0) / 2.0 * h;
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&Vec3::repeat(o));
        let data = (0..n * n * n)
            .map(|v| {
                let (i, j, k) = (v % n, (v / n) % n, v / (n * n));
                let p = m * nalgebra::Vector4::new(i as f64, j as f64, k as f64, 1.0);
                let interior = i > 1 && j > 1 && i < n - 2 && j < n - 2;
                f64::from(u8::from(interior && p.z.abs() <= half))
            })
            .collect();
        Volume::new([n, n, n], data, m).unwrap()
    }

    #[test]
    fn a_slab_has_its_mid_plane_with_its_half_thickness() {
        let (half, h) = (3.2, 0.5);
        let points = medial_points(&slab(half, h), 110.0).unwrap();
        assert!(!points.is_empty());
        // The mid-plane z = 0 (midpoints of voxel pairs straddle it) away from the slab's ends.
        let far: Vec<&MedialPoint> = points
            .iter()
            .filter(|p| p.position.x.abs() < 2.0 && p.position.y.abs() < 2.0)
            .collect();
        assert!(!far.is_empty());
        for p in far {
            assert!(p.position.z.abs() <= h / 2.0 + 1e-9, "{p:?}");
            assert!((p.radius - half).abs() <= h, "{p:?}");
        }
    }

    #[test]
    fn refuses_a_shape_on_the_border_and_an_empty_one() {
        let full = Volume::new([3, 3, 3], vec![1.0; 27], Matrix4::identity()).unwrap();
        assert!(matches!(
            medial_points(&full, 100.0),
            Err(Error::InvalidVolume(_))
        ));
        let empty = Volume::new([3, 3, 3], vec![0.0; 27], Matrix4::identity()).unwrap();
        assert!(matches!(
            medial_points(&empty, 100.0),
            Err(Error::InvalidVolume(_))
        ));
    }
}
