//! Where a closed model surface and a segmentation disagree, and how far from each other: the
//! voxel overlap a fit reports, and the rule that tells a fit that missed a part of its target
//! from one that placed its boundary a voxel off.
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
//! ([`Disagreement::reach`], [`Miss`]).
//!
//! ```
//! use medial_core::image::agreement::Disagreement;
//! use medial_core::testing::meshes::octahedron;
//! use medial_core::TriMesh;
//! use medial_core::image::rasterize::{grid_around, rasterize};
//! // An octahedron of radius 1 on a grid of 0.1 mm voxels, and the same as its own target.
//! let (points, triangles) = octahedron();
//! let mesh = TriMesh::new(points, triangles).unwrap();
//! let (dims, grid) = grid_around(&mesh, 0.1, 0.2).unwrap();
//! let target = rasterize(&mesh, dims, grid).unwrap();
//! let d = Disagreement::new(&mesh, &target).unwrap();
//! assert_eq!(d.voxel_dice(), 1.0);
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
use crate::image::rasterize::rasterize;
use crate::image::Volume;
use crate::{Result, TriMesh, Vec3};

/// The least reach beyond which a voxel of the target outside the model is a part missed rather
/// than the boundary placed off, in voxels (of the grid's largest spacing). A segmentation's
/// boundary is known to about a voxel, and a smooth surface meets a staircase within about a
/// voxel: one voxel for each, so that a fit whose boundary runs within a voxel of the target's
/// everywhere has nothing beyond it (decision 0203).
pub const MISS_REACH_VOXELS: f64 = 2.0;

/// The largest share of the target's voxels that may lie outside the model beyond
/// [`MISS_REACH_VOXELS`] before the fit is judged to have missed its target (decision 0203): a
/// part of a few per cent of the structure is a part a reader of the result would see, and it
/// lies several times above what fits that met their targets leave there, and several times
/// below what fits that ended in the wrong place or on another structure do.
pub const MAX_MISSED_SHARE: f64 = 0.02;

/// The voxels on which a rasterized model and a mask differ, each with its distance (mm) to the
/// nearest voxel of the other set; see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct Disagreement {
    /// Distances of the voxels of the foreground outside the model, to the model, ascending.
    missed: Vec<f64>,
    /// Distances of the voxels of the model outside the foreground, to the foreground, ascending.
    added: Vec<f64>,
    /// Voxels of the foreground.
    foreground: usize,
    /// Voxels of the model.
    model: usize,
    /// The centre of the voxel of the foreground farthest outside the model (none: no voxel of
    /// the foreground is outside it).
    farthest_missed: Option<Vec3>,
    /// The grid's largest voxel spacing, mm.
    voxel: f64,
}

/// A fit that missed a part of its target: more than [`MAX_MISSED_SHARE`] of the target's
/// voxels lie outside the model beyond the reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Miss {
    /// The share of the target's voxels outside the model beyond the reach.
    pub share: f64,
    /// The reach, mm ([`Disagreement::reach`]).
    pub reach: f64,
    /// The centre of the target's voxel farthest from the model (world, mm).
    pub farthest: Vec3,
    /// Its distance to the model, mm.
    pub distance: f64,
}

impl std::fmt::Display for Miss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = self.farthest;
        write!(
            f,
            "{:.1} % of the target's voxels lie outside the model farther than {:.2} mm from it \
             (two voxels or the flow's σ, the larger), more than {} %; the farthest, at ({:.1}, \
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
    /// Rasterizes the closed mesh `mesh` on the grid of `mask` (see [`rasterize`]) and measures
    /// it against the voxels of `mask` above ½. The distance transforms run on the box of the
    /// voxels of either set (exact: every nearest voxel lies in it). Errors: those of
    /// [`rasterize`] and of [`FeatureTransform::new`].
    pub fn new(mesh: &TriMesh, mask: &Volume) -> Result<Self> {
        let dims = mask.dims();
        let model = rasterize(mesh, dims, *mask.voxel_to_world())?;
        let s = mask.spacing();
        let mut disagreement = Self {
            missed: Vec::new(),
            added: Vec::new(),
            foreground: 0,
            model: 0,
            farthest_missed: None,
            voxel: s.max(),
        };
        let Some(crop) = Crop::around(dims, model.data(), mask.data()) else {
            return Ok(disagreement);
        };
        let (model, target) = (crop.cut(model.data()), crop.cut(mask.data()));
        let spacing = [s.x, s.y, s.z];
        let (missed, farthest) = distances(&target, &model, crop.dims, spacing)?;
        disagreement.missed = missed;
        disagreement.added = distances(&model, &target, crop.dims, spacing)?.0;
        disagreement.foreground = target.iter().filter(|&&v| v).count();
        disagreement.model = model.iter().filter(|&&v| v).count();
        disagreement.farthest_missed = farthest.map(|n| mask.voxel_centre(crop.index(n)));
        Ok(disagreement)
    }

    /// The voxel Dice `2 |M ∩ A| / (|M| + |A|)` (0 when both are empty).
    pub fn voxel_dice(&self) -> f64 {
        let count = self.foreground + self.model;
        let both = self.foreground - self.missed.len();
        match count {
            0 => 0.0,
            _ => 2.0 * both as f64 / count as f64,
        }
    }

    /// The share of the foreground's voxels outside the model and farther than `reach` mm
    /// from it (0 for an empty foreground).
    pub fn missed_beyond(&self, reach: f64) -> f64 {
        share(&self.missed, reach, self.foreground)
    }

    /// The model's voxels outside the foreground and farther than `reach` mm from it, as a
    /// share of the foreground's voxels (0 for an empty foreground).
    pub fn added_beyond(&self, reach: f64) -> f64 {
        share(&self.added, reach, self.foreground)
    }

    /// The reach of a model moved by a flow of kernel width `sigma` (mm): the larger of
    /// [`MISS_REACH_VOXELS`] voxels of the grid's largest spacing and `sigma`, mm.
    pub fn reach(&self, sigma: f64) -> f64 {
        (MISS_REACH_VOXELS * self.voxel).max(sigma)
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
            reach,
            farthest,
            distance: self.missed.last().copied().unwrap_or_default(),
        })
    }
}

/// The box of the voxels in either of two volumes, one voxel wider on each side where the grid
/// allows.
struct Crop {
    /// The box's first voxel.
    start: [usize; 3],
    /// Its size.
    dims: [usize; 3],
    /// The whole grid's size.
    grid: [usize; 3],
}

impl Crop {
    /// The box around the voxels above ½ of `a` or `b` (none: both empty).
    fn around(grid: [usize; 3], a: &[f64], b: &[f64]) -> Option<Self> {
        let [nx, ny, _] = grid;
        let (lo, hi) = (0..a.len())
            .filter(|&n| a[n] > 0.5 || b[n] > 0.5)
            .map(|n| [n % nx, (n / nx) % ny, n / (nx * ny)])
            .fold(None, |acc: Option<([usize; 3], [usize; 3])>, v| {
                Some(acc.map_or((v, v), |(lo, hi)| {
                    (
                        std::array::from_fn(|a| lo[a].min(v[a])),
                        std::array::from_fn(|a| hi[a].max(v[a])),
                    )
                }))
            })?;
        let start: [usize; 3] = std::array::from_fn(|a| lo[a].saturating_sub(1));
        let end: [usize; 3] = std::array::from_fn(|a| (hi[a] + 2).min(grid[a]));
        Some(Self {
            start,
            dims: std::array::from_fn(|a| end[a] - start[a]),
            grid,
        })
    }

    /// The voxels above ½ of `v` (on the whole grid) in the box, x fastest.
    fn cut(&self, v: &[f64]) -> Vec<bool> {
        let [nx, ny, _] = self.grid;
        let [cx, cy, cz] = self.dims;
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

/// The distances (mm, ascending) of the voxels in `a` and not in `b` to the nearest voxel of
/// `b` (∞ for an empty `b`), and the index of the farthest (the first of equals).
fn distances(
    a: &[bool],
    b: &[bool],
    dims: [usize; 3],
    spacing: [f64; 3],
) -> Result<(Vec<f64>, Option<usize>)> {
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
    let mut d: Vec<f64> = apart.into_iter().map(|(_, d)| d).collect();
    d.sort_by(f64::total_cmp);
    Ok((d, farthest))
}

/// The count of `sorted` above `reach`, over `of`.
fn share(sorted: &[f64], reach: f64, of: usize) -> f64 {
    let beyond = sorted.len() - sorted.partition_point(|&d| d <= reach);
    match of {
        0 => 0.0,
        _ => beyond as f64 / of as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::rasterize::voxel_dice;
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
            prop_assert_eq!(d.voxel_dice(), voxel_dice(&mesh, &target).unwrap());
            for r in [0.0, 0.2, 0.3, d.reach(0.1), 0.8] {
                prop_assert!((d.missed_beyond(r) - beyond(&missed, r) / count as f64).abs() < 1e-12);
                prop_assert!((d.added_beyond(r) - beyond(&added, r) / count as f64).abs() < 1e-12);
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
                    prop_assert_eq!(brute_distances(&far, &model, &target), vec![farthest]);
                }
                None => prop_assert!(share <= MAX_MISSED_SHARE),
            }
        }
    }

    /// A model of nothing misses all of its target; a target of nothing is never missed.
    #[test]
    fn an_empty_model_or_target_is_measured_without_a_panic() {
        let mesh = octahedron_at(1.0, Vec3::zeros());
        let (dims, grid) = crate::image::rasterize::grid_around(&mesh, 0.2, 0.4).unwrap();
        let empty = Volume::new(dims, vec![0.0; dims.iter().product()], grid).unwrap();
        let d = Disagreement::new(&mesh, &empty).unwrap();
        assert_eq!((d.voxel_dice(), d.missed_beyond(0.0)), (0.0, 0.0));
        assert!(d.miss(0.1).is_none());
        let far = octahedron_at(1.0, Vec3::new(100.0, 0.0, 0.0));
        let target = rasterize(&mesh, dims, grid).unwrap();
        let d = Disagreement::new(&far, &target).unwrap();
        let miss = d.miss(0.1).expect("nothing of the target is in the model");
        assert_eq!((d.voxel_dice(), miss.share), (0.0, 1.0));
        assert_eq!(miss.distance, f64::INFINITY);
    }
}
