//! Where a fitted model and its target disagree, and how far from each other: the voxel
//! overlap a fit reports, and the rule that tells a fit that missed a part of its target from
//! one that placed its boundary a voxel off.
//!
//! Voxel Dice counts every voxel on which the rasterized model `M` and the foreground `A`
//! differ the same, whether it lies along the boundary or in a part one has and the other
//! lacks. Along the boundary a disagreement of about a voxel is the segmentation's own
//! uncertainty (a boundary known to a voxel, a smooth surface against a staircase); a voxel of
//! `A` farther than that from `M` is a part of the target the model did not reach, and a voxel
//! of `M` farther than that from `A` a part the model has and the target lacks. A model moved by
//! a flow whose kernel has width `σ` is smooth at that scale, so a notch of the target narrower
//! than `σ` is detail the flow cannot enter, not a part missed either. [`Disagreement`] keeps
//! the distance of each differing voxel to the other set, so that the share beyond any reach can
//! be read, and judges a fit by the part of its target it missed beyond the larger of the two
//! ([`Disagreement::reach`], [`Miss`]). A target surface is judged the same way, its triangles
//! for voxels and its mean edge for the voxel's size ([`Disagreement::of_surfaces`]): a mesh
//! is known to about its sampling.
//!
//! ```
//! use medial_core::fit::agreement::Disagreement;
//! use medial_core::testing::meshes::octahedron;
//! use medial_core::TriMesh;
//! use medial_core::image::rasterize::{grid_around, rasterize};
//! // An octahedron of radius 1 on a grid of 0.1 mm voxels, and the same as its own target.
//! let (points, triangles) = octahedron();
//! let mesh = TriMesh::new(points, triangles).unwrap();
//! let (dims, grid) = grid_around(&mesh, 0.1, 0.2).unwrap();
//! let target = rasterize(&mesh, dims, grid).unwrap();
//! let d = Disagreement::new(&mesh, &target).unwrap();
//! assert_eq!(d.voxel_dice(), Some(1.0));
//! assert!(d.miss(0.1).is_none());
//! // Half the size: the target's outer shell is missed, 0.29 mm deep (0.5/√3, to the model's
//! // surface; a little more to its voxels), and more than a third of it beyond two voxels.
//! let small = TriMesh::new(mesh.points().iter().map(|p| p * 0.5).collect(),
//!     mesh.triangles().to_vec()).unwrap();
//! let d = Disagreement::new(&small, &target).unwrap();
//! let miss = d.miss(0.1).unwrap(); // a flow of σ = 0.1 mm: the reach is two voxels
//! assert_eq!(miss.reach, 0.2);
//! assert!(miss.share > 1.0 / 3.0 && miss.share < 0.875, "{miss:?}");
//! assert!(miss.distance > 0.29 && miss.distance < 0.29 + 0.3, "{miss:?}");
//! ```

use rayon::prelude::*;

use crate::image::distance::FeatureTransform;
use crate::image::rasterize::rasterize_box;
use crate::image::Volume;
use crate::mesh::distance::SurfaceDistance;
use crate::mesh::Bounds;
use crate::{Result, TriMesh, Vec3};

/// The least reach beyond which a voxel of the target outside the model is a part missed rather
/// than the boundary placed off, in voxels (of the grid's largest spacing). A segmentation's
/// boundary is known to about a voxel, and a smooth surface meets a staircase within about a
/// voxel: one voxel for each, so that a fit whose boundary runs within a voxel of the target's
/// everywhere has nothing beyond it (decision 0203).
pub const MISS_REACH_VOXELS: f64 = 2.0;

/// The largest share of the target that may lie outside the model beyond the reach
/// ([`Disagreement::reach`]) before the fit is judged to have missed its target (decision
/// 0203): a part of a few per cent of the structure is a part a reader of the result would see,
/// and it lies about twice what the fits that met their targets leave there (at most 0.96 %)
/// and half what the fits that ended in the wrong place or on another structure do (at least
/// 4.9 %).
pub const MAX_MISSED_SHARE: f64 = 0.02;

/// Parts of a model or a target: (distance to the other, mm; weight), by distance.
type Parts = Vec<(f64, f64)>;

/// Where a model and its target differ, each part with its distance (mm) to the other and its
/// weight: the voxels on which a rasterized model and a mask differ ([`Disagreement::new`]), or
/// the triangles of a model's boundary and of a target surface, each at its distance to the
/// other surface ([`Disagreement::of_surfaces`]); see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct Disagreement {
    /// The target's parts outside the model (voxels; for surfaces every triangle), by distance.
    missed: Parts,
    /// The model's parts outside the target (voxels; for surfaces every triangle), by distance.
    added: Parts,
    /// The target's whole weight (voxels, or area in mm²).
    target: f64,
    /// The model's whole weight.
    model: f64,
    /// The centre of the target's part farthest outside the model (none: nothing outside it).
    farthest_missed: Option<Vec3>,
    /// The target's sampling step, mm: the grid's largest voxel spacing, or the target
    /// surface's mean edge length.
    step: f64,
    /// What the parts are.
    part: Part,
}

/// What the parts of a [`Disagreement`] are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// Voxels of an image's grid, each of weight 1.
    Voxels,
    /// Triangles of a surface, each weighing its area (mm²) and placed at its centroid.
    Area,
}

/// A fit that missed a part of its target: more than [`MAX_MISSED_SHARE`] of the target (its
/// voxels, or its area) lies outside the model beyond the reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Miss {
    /// The share of the target outside the model beyond the reach.
    pub share: f64,
    /// What the share is of.
    pub part: Part,
    /// The reach, mm ([`Disagreement::reach`]).
    pub reach: f64,
    /// The centre of the target's part farthest from the model (world, mm).
    pub farthest: Vec3,
    /// Its distance to the model, mm.
    pub distance: f64,
}

impl std::fmt::Display for Miss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (what, step) = match self.part {
            Part::Voxels => ("voxels lie", "two voxels"),
            Part::Area => ("area lies", "two of its mean edges"),
        };
        let p = self.farthest;
        write!(
            f,
            "{:.1} % of the target's {what} outside the model farther than {:.2} mm from it \
             ({step} or the flow's σ, the larger), more than {} %; the farthest, at ({:.1}, \
             {:.1}, {:.1}) mm, is {:.1} mm from it",
            100.0 * self.share,
            self.reach,
            100.0 * MAX_MISSED_SHARE,
            p.x,
            p.y,
            p.z,
            self.distance
        )
    }
}

impl Disagreement {
    /// Rasterizes the closed mesh `mesh` on the grid of `mask` ([`rasterize_box`]) and measures
    /// it against the voxels of `mask` above ½. Both the rasterization and the distance
    /// transforms run on the box of the mesh's and the foreground's voxels, never on the whole
    /// grid (exact: every nearest voxel lies in it). Errors: those of [`rasterize_box`] and of
    /// [`FeatureTransform::new`].
    pub fn new(mesh: &TriMesh, mask: &Volume) -> Result<Self> {
        let s = mask.spacing();
        let mut disagreement = Self {
            missed: Vec::new(),
            added: Vec::new(),
            target: 0.0,
            model: 0.0,
            farthest_missed: None,
            step: s.max(),
            part: Part::Voxels,
        };
        let Some(crop) = Crop::around(mesh, mask) else {
            return Ok(disagreement);
        };
        let grid = *mask.voxel_to_world();
        let model = rasterize_box(mesh, mask.dims(), grid, crop.start, crop.dims)?;
        let target = crop.cut(mask);
        let spacing = [s.x, s.y, s.z];
        let (missed, farthest) = distances(&target, &model, crop.dims, spacing)?;
        disagreement.missed = missed;
        disagreement.added = distances(&model, &target, crop.dims, spacing)?.0;
        disagreement.target = target.iter().filter(|&&v| v).count() as f64;
        disagreement.model = model.iter().filter(|&&v| v).count() as f64;
        disagreement.farthest_missed = farthest.map(|n| mask.voxel_centre(crop.index(n)));
        Ok(disagreement)
    }

    /// Measures the boundary `model` against the surface `to_target` is prepared for (any
    /// triangles: open or closed): each triangle of either, at its centroid and weighing its
    /// area, with its exact distance to the other surface. Errors: `InvalidMesh` for a model
    /// without triangles.
    pub fn of_surfaces(model: &TriMesh, to_target: &SurfaceDistance) -> Result<Self> {
        let target = to_target.surface();
        let to_model = SurfaceDistance::new(model)?;
        let (missed, farthest) = triangle_distances(target, &to_model);
        let edges: Vec<f64> = (target.triangles().iter())
            .flat_map(|t| {
                (0..3).map(|e| (target.points()[t[e]] - target.points()[t[(e + 1) % 3]]).norm())
            })
            .collect();
        Ok(Self {
            missed,
            added: triangle_distances(model, to_target).0,
            target: areas(target).sum(),
            model: areas(model).sum(),
            farthest_missed: farthest,
            step: edges.iter().sum::<f64>() / edges.len() as f64,
            part: Part::Area,
        })
    }

    /// The voxel Dice `2 |M ∩ A| / (|M| + |A|)` (0 when both are empty) of a disagreement of
    /// voxels (none for surfaces).
    pub fn voxel_dice(&self) -> Option<f64> {
        let count = self.target + self.model;
        let both = self.target - self.missed.len() as f64;
        match (self.part, count > 0.0) {
            (Part::Area, _) => None,
            (Part::Voxels, false) => Some(0.0),
            (Part::Voxels, true) => Some(2.0 * both / count),
        }
    }

    /// The share of the target (its voxels, or its area) outside the model and farther than
    /// `reach` mm from it (0 for an empty target).
    pub fn missed_beyond(&self, reach: f64) -> f64 {
        share(&self.missed, reach, self.target)
    }

    /// The part of the model outside the target and farther than `reach` mm from it, as a
    /// share of the target (0 for an empty target).
    pub fn added_beyond(&self, reach: f64) -> f64 {
        share(&self.added, reach, self.target)
    }

    /// The reach of a model moved by a flow of kernel width `sigma` (mm): the larger of
    /// [`MISS_REACH_VOXELS`] sampling steps of the target (the grid's largest voxel spacing,
    /// or the target surface's mean edge length) and `sigma`, mm.
    pub fn reach(&self, sigma: f64) -> f64 {
        (MISS_REACH_VOXELS * self.step).max(sigma)
    }

    /// The part of the target that a model moved by a flow of kernel width `sigma` (mm)
    /// missed, where it is more than [`MAX_MISSED_SHARE`] of the target beyond
    /// [`Disagreement::reach`] (none: the model met its target).
    pub fn miss(&self, sigma: f64) -> Option<Miss> {
        let reach = self.reach(sigma);
        let share = self.missed_beyond(reach);
        let farthest = self.farthest_missed?;
        (share > MAX_MISSED_SHARE).then(|| Miss {
            share,
            part: self.part,
            reach,
            farthest,
            distance: self.missed.last().map_or(0.0, |m| m.0),
        })
    }
}

/// The box of a grid holding a mesh's voxels and a mask's foreground, one voxel wider on each
/// side where the grid allows.
struct Crop {
    /// The box's first voxel.
    start: [usize; 3],
    /// Its size.
    dims: [usize; 3],
    /// The whole grid's size.
    grid: [usize; 3],
}

impl Crop {
    /// The box around the voxels of `mask` above ½ and the part of the grid `mesh`'s bounding
    /// box covers (none: neither has a voxel).
    fn around(mesh: &TriMesh, mask: &Volume) -> Option<Self> {
        let grid = mask.dims();
        let [nx, ny, _] = grid;
        let foreground = (mask.data().iter().enumerate())
            .filter(|(_, &v)| v > 0.5)
            .map(|(n, _)| [n % nx, (n / nx) % ny, n / (nx * ny)])
            .map(|v| (v, v))
            .reduce(hull);
        let voxels: Vec<Vec3> = (mesh.points().iter())
            .map(|p| mask.world_to_voxel().transform_point(&(*p).into()).coords)
            .collect();
        let on_grid = Bounds::of(&voxels).and_then(|b| {
            let covers = (0..3).all(|a| b.max[a] >= 0.0 && b.min[a] <= (grid[a] - 1) as f64);
            // Clamped to the grid before the casts (a mesh far off it has huge coordinates).
            let at = |x: f64, a: usize| x.clamp(0.0, (grid[a] - 1) as f64) as usize;
            covers.then(|| {
                (
                    std::array::from_fn(|a| at(b.min[a].floor(), a)),
                    std::array::from_fn(|a| at(b.max[a].ceil(), a)),
                )
            })
        });
        let (lo, hi) = [foreground, on_grid].into_iter().flatten().reduce(hull)?;
        let start: [usize; 3] = std::array::from_fn(|a| lo[a].saturating_sub(1));
        let end: [usize; 3] = std::array::from_fn(|a| (hi[a] + 2).min(grid[a]));
        Some(Self {
            start,
            dims: std::array::from_fn(|a| end[a] - start[a]),
            grid,
        })
    }

    /// The voxels of `mask` above ½ in the box, x fastest.
    fn cut(&self, mask: &Volume) -> Vec<bool> {
        let [nx, ny, _] = self.grid;
        let [cx, cy, cz] = self.dims;
        let v = mask.data();
        (0..cx * cy * cz)
            .into_par_iter()
            .map(|n| {
                let [i, j, k] = self.index(n);
                v[i + nx * (j + ny * k)] > 0.5
            })
            .collect()
    }

    /// The grid index of the box's voxel `n`.
    fn index(&self, n: usize) -> [usize; 3] {
        let [cx, cy, _] = self.dims;
        let local = [n % cx, (n / cx) % cy, n / (cx * cy)];
        std::array::from_fn(|a| self.start[a] + local[a])
    }
}

/// The smallest box holding two boxes of voxels, each `(lowest, highest)`.
fn hull(a: ([usize; 3], [usize; 3]), b: ([usize; 3], [usize; 3])) -> ([usize; 3], [usize; 3]) {
    (
        std::array::from_fn(|i| a.0[i].min(b.0[i])),
        std::array::from_fn(|i| a.1[i].max(b.1[i])),
    )
}

/// The distances (mm, ascending, each of weight 1) of the voxels in `a` and not in `b` to the
/// nearest voxel of `b` (∞ for an empty `b`), and the index of the farthest (the first of
/// equals).
fn distances(
    a: &[bool],
    b: &[bool],
    dims: [usize; 3],
    spacing: [f64; 3],
) -> Result<(Parts, Option<usize>)> {
    let outside_b: Vec<bool> = b.par_iter().map(|&v| !v).collect();
    let transform = FeatureTransform::new(&outside_b, dims, spacing)?;
    let apart: Vec<(usize, f64)> = (0..a.len())
        .into_par_iter()
        .filter(|&n| a[n] && !b[n])
        .map(|n| (n, transform.squared_distance(n).sqrt()))
        .collect();
    let farthest = apart
        .iter()
        .fold(None, |best: Option<(usize, f64)>, &(n, d)| match best {
            Some((_, far)) if far >= d => best,
            _ => Some((n, d)),
        })
        .map(|(n, _)| n);
    let mut d: Parts = apart.into_iter().map(|(_, d)| (d, 1.0)).collect();
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok((d, farthest))
}

/// The areas of the triangles of `mesh`, mm².
fn areas(mesh: &TriMesh) -> impl Iterator<Item = f64> + '_ {
    let p = mesh.points();
    (mesh.triangles().iter())
        .map(move |t| 0.5 * (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]])).norm())
}

/// The distances to `other` (mm, ascending) of the centroids of the triangles of `mesh`, each
/// weighing its triangle's area, and the farthest centroid (the first of equals).
fn triangle_distances(mesh: &TriMesh, other: &SurfaceDistance) -> (Parts, Option<Vec3>) {
    let p = mesh.points();
    let centroids: Vec<Vec3> = (mesh.triangles().iter())
        .map(|t| (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0)
        .collect();
    let mut d: Parts = (centroids.par_iter())
        .map(|c| other.distance(c))
        .zip(areas(mesh).collect::<Vec<_>>())
        .collect();
    let farthest = (d.iter().zip(&centroids))
        .fold(
            None,
            |best: Option<(f64, Vec3)>, (&(dist, _), c)| match best {
                Some((far, _)) if far >= dist => best,
                _ => Some((dist, *c)),
            },
        )
        .map(|(_, c)| c);
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    (d, farthest)
}

/// The weight of `sorted` (by distance) farther than `reach`, over `of` (0 for `of` = 0).
fn share(sorted: &[(f64, f64)], reach: f64, of: f64) -> f64 {
    // Summed from +0 (an empty `Sum` of floats is −0).
    let beyond = sorted[sorted.partition_point(|&(d, _)| d <= reach)..]
        .iter()
        .fold(0.0, |sum, &(_, w)| sum + w);
    match of > 0.0 {
        true => beyond / of,
        false => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::rasterize::{rasterize, voxel_dice};
    use crate::testing::meshes::octahedron;
    use nalgebra::Matrix4;
    use proptest::prelude::*;

    /// The octahedron of radius `r` centred at `c`.
    fn octahedron_at(r: f64, c: Vec3) -> TriMesh {
        let (points, triangles) = octahedron();
        TriMesh::new(points.iter().map(|p| c + p * r).collect(), triangles).unwrap()
    }

    /// Every pair of voxels, for the distances of the voxels of `a` not in `b` to `b`.
    fn brute_distances(a: &[bool], b: &[bool], v: &Volume) -> Vec<f64> {
        let dims = v.dims();
        let centre = |n: usize| {
            v.voxel_centre([
                n % dims[0],
                (n / dims[0]) % dims[1],
                n / (dims[0] * dims[1]),
            ])
        };
        let mut d: Vec<f64> = (0..a.len())
            .filter(|&n| a[n] && !b[n])
            .map(|n| {
                (0..b.len())
                    .filter(|&m| b[m])
                    .map(|m| (centre(n) - centre(m)).norm())
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        d.sort_by(f64::total_cmp);
        d
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// The shares, the Dice and the farthest voxel against a count over every pair of
        /// voxels, on an anisotropic grid with a target of flipped voxels and a model moved
        /// and scaled off it.
        #[test]
        fn the_figures_match_a_count_over_every_pair_of_voxels(
            scale in 0.4..1.2f64,
            shift in prop::array::uniform3(-0.4..0.4f64),
            flips in prop::collection::vec(0usize..(14 * 12 * 10), 0..40),
        ) {
            let dims = [14, 12, 10];
            let grid = Matrix4::new(
                0.18, 0.0, 0.0, -1.2,
                0.0, 0.22, 0.0, -1.2,
                0.0, 0.0, 0.26, -1.2,
                0.0, 0.0, 0.0, 1.0,
            );
            let mut target = rasterize(&octahedron_at(0.9, Vec3::zeros()), dims, grid).unwrap();
            let mut data = target.data().to_vec();
            flips.iter().for_each(|&n| data[n] = 1.0 - data[n]);
            target = Volume::new(dims, data, grid).unwrap();
            let mesh = octahedron_at(0.9 * scale, Vec3::from(shift));
            let d = Disagreement::new(&mesh, &target).unwrap();

            let model: Vec<bool> =
                rasterize(&mesh, dims, grid).unwrap().data().iter().map(|&v| v > 0.5).collect();
            let mask: Vec<bool> = target.data().iter().map(|&v| v > 0.5).collect();
            let missed = brute_distances(&mask, &model, &target);
            let added = brute_distances(&model, &mask, &target);
            let count = mask.iter().filter(|&&v| v).count();
            let beyond = |d: &[f64], r: f64| d.iter().filter(|&&x| x > r).count() as f64;
            prop_assert_eq!(d.voxel_dice(), Some(voxel_dice(&mesh, &target).unwrap()));
            for r in [0.0, 0.2, 0.3, d.reach(0.1), 0.8] {
                let n = count as f64;
                prop_assert!((d.missed_beyond(r) - beyond(&missed, r) / n).abs() < 1e-12);
                prop_assert!((d.added_beyond(r) - beyond(&added, r) / n).abs() < 1e-12);
            }
            prop_assert!((d.reach(0.1) - 2.0 * 0.26).abs() < 1e-12);
            prop_assert_eq!(d.reach(0.6), 0.6);
            let farthest = missed.last().copied().unwrap_or_default();
            let share = beyond(&missed, d.reach(0.1)) / count as f64;
            match d.miss(0.1) {
                Some(m) => {
                    prop_assert!(share > MAX_MISSED_SHARE);
                    prop_assert!((m.distance - farthest).abs() < 1e-12);
                    let far: Vec<bool> = (0..mask.len()).map(|n| {
                        let [nx, ny, _] = dims;
                        (target.voxel_centre([n % nx, (n / nx) % ny, n / (nx * ny)]) - m.farthest)
                            .norm() < 1e-9
                    }).collect();
                    // The voxel named is at the farthest distance (another voxel may tie with
                    // it to the last bit of rounding).
                    let at = brute_distances(&far, &model, &target);
                    prop_assert!(at.len() == 1 && (at[0] - farthest).abs() < 1e-12, "{at:?}");
                }
                None => prop_assert!(share <= MAX_MISSED_SHARE),
            }
        }
    }

    /// Two unit squares five apart as the target, one of them as the model: half the target's
    /// area is missed, five away, and none of the model is added; the reach is two mean edges.
    #[test]
    fn a_surface_is_judged_by_its_area_and_its_mean_edge() {
        let square = |z: f64| {
            [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)].map(|(x, y)| Vec3::new(x, y, z))
        };
        let model = TriMesh::new(square(0.0).to_vec(), vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        let points = [square(0.0), square(5.0)].concat();
        let target =
            TriMesh::new(points, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]).unwrap();
        let d = Disagreement::of_surfaces(&model, &SurfaceDistance::new(&target).unwrap()).unwrap();
        assert_eq!(d.voxel_dice(), None);
        let mean_edge = (2.0 + 2f64.sqrt()) / 3.0;
        assert!((d.reach(0.1) - 2.0 * mean_edge).abs() < 1e-12);
        assert_eq!(d.reach(7.0), 7.0);
        assert!((d.missed_beyond(d.reach(0.1)) - 0.5).abs() < 1e-12);
        assert_eq!(d.added_beyond(1e-9), 0.0);
        let miss = d.miss(0.1).unwrap();
        assert_eq!((miss.part, miss.farthest.z), (Part::Area, 5.0));
        assert!((miss.distance - 5.0).abs() < 1e-12);
        assert!(miss
            .to_string()
            .starts_with("50.0 % of the target's area lies outside"));
        // A flow wider than the squares are apart reaches the second one.
        assert!(d.miss(5.5).is_none());
    }

    /// A model of nothing misses all of its target; a target of nothing is never missed.
    #[test]
    fn an_empty_model_or_target_is_measured_without_a_panic() {
        let mesh = octahedron_at(1.0, Vec3::zeros());
        let (dims, grid) = crate::image::rasterize::grid_around(&mesh, 0.2, 0.4).unwrap();
        let empty = Volume::new(dims, vec![0.0; dims.iter().product()], grid).unwrap();
        let d = Disagreement::new(&mesh, &empty).unwrap();
        assert_eq!((d.voxel_dice(), d.missed_beyond(0.0)), (Some(0.0), 0.0));
        assert!(d.miss(0.1).is_none());
        let far = octahedron_at(1.0, Vec3::new(100.0, 0.0, 0.0));
        let target = rasterize(&mesh, dims, grid).unwrap();
        let d = Disagreement::new(&far, &target).unwrap();
        let miss = d.miss(0.1).expect("nothing of the target is in the model");
        assert_eq!((d.voxel_dice(), miss.share), (Some(0.0), 1.0));
        assert_eq!(miss.distance, f64::INFINITY);
    }
}
