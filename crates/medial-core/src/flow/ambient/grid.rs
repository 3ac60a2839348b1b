//! Whole images through a fitted flow: the displacement `d(y) = φ(y) − y` (`φ = φ₁` or `φ₁⁻¹`,
//! docs/method.md §3.6) on every voxel of a grid, from its values on a coarser control grid.
//!
//! **The control grid.** Nodes every `s` voxels along each axis of the voxel grid (`s` the
//! *stride*, by default `⌊0.75 σ / h_max⌋`, at least 1, `h_max` the largest voxel spacing: the
//! velocity of each step is a sum of Gaussians of width σ, smooth well below σ), two nodes
//! beyond the grid on each side. The nodes are mapped with the kernel truncated at the ε whose
//! bound ([`AmbientFlow::truncation_bound`]) is a tenth of the tolerance ([`TRUNCATION_SHARE`]),
//! in blocks of nearby nodes, each step skipping the landmarks beyond the cutoff radius
//! `σ √(2 ln(1/ε))` of the block ([`AmbientFlow::map_truncated`]).
//!
//! **Interpolation.** A voxel in the control cell `[c, c+1]³` (in nodes) takes the tensor
//! product of 4-point Lagrange cubics through the nodes `c−1 … c+2` of each axis. Along one
//! axis the error at `t ∈ [0, 1]` of the cell is `f⁗(ξ) h⁴ (t+1) t (t−1) (t−2) / 24`, at most
//! `(9/16)/24 · h⁴ |f⁗|`; the tensor product adds the errors of the three axes, each after
//! the first multiplied by the Lebesgue constant `5/4` of the cubic (`Σ |w| ≤ 5/4`):
//!
//! `|d̃(y) − d(y)| ≤ (9/384) (D_z + 5/4 D_y + 25/16 D_x) + (5/4)³ δ_ε`,
//!
//! with `D_a = h_a⁴ max |∂⁴_a d|` over the cell and `δ_ε` the truncation bound of the nodes.
//! `D_a` is estimated by the fourth differences `|d_{m−2} − 4 d_{m−1} + 6 d_m − 4 d_{m+1} +
//! d_{m+2}|` of the nodes along axis `a` (each is `h⁴ ∂⁴_a d` somewhere within two nodes) at
//! the cell's eight corners, times [`INTERPOLATION_SAFETY`]. A cell whose estimate exceeds the
//! tolerance is not interpolated: its voxels are mapped one by one (truncated at the same ε,
//! within `δ_ε`). A cell whose 64 nodes do not move (no landmark within the cutoff at any step)
//! does not move. So every voxel is within the tolerance of the exact map wherever the fourth
//! differences tell the fourth derivatives within the safety factor — which the tests check
//! against the exact map, voxel by voxel.
//!
//! The displacements come out slab by slab ([`GridMap::displacements`]), so that an image of
//! any size is carried holding only the control grid and one slab; each voxel is computed by
//! the same operations whatever the thread count (the same bits).

use super::AmbientFlow;
use crate::{Error, Result, Vec3};
use nalgebra::{Matrix4, Vector4};
use rayon::prelude::*;
use std::ops::Range;

/// The share of the tolerance given to the truncation of the kernel.
pub const TRUNCATION_SHARE: f64 = 0.1;

/// The factor on the interpolation error estimated from fourth differences.
pub const INTERPOLATION_SAFETY: f64 = 2.0;

/// The default control spacing in kernel widths σ (rounded down to whole voxels).
pub const STRIDE_PER_SIGMA: f64 = 0.75;

/// The largest stride, voxels.
pub const MAX_STRIDE: usize = 16;

/// Points per block of a truncated map (nodes: 8 × 8 × 8).
const BLOCK: usize = 8;

/// Most voxels of mapped cells per block.
const MAPPED_BLOCK: usize = 128;

/// `max_{t∈[0,1]} |(t+1) t (t−1) (t−2)| / 24`.
const LAGRANGE_ERROR: f64 = 0.5625 / 24.0;

/// The Lebesgue constant of the 4-point cubic on its middle interval.
const LEBESGUE: f64 = 1.25;

/// A voxel grid: its size and its voxel → world (RAS mm) matrix, as a NIfTI image has.
#[derive(Clone, Debug, PartialEq)]
pub struct Lattice {
    /// Voxels along `x`, `y`, `z`.
    pub dims: [usize; 3],
    /// Voxel index (homogeneous) → world mm.
    pub voxel_to_world: Matrix4<f64>,
}

impl Lattice {
    /// The world point of the (possibly fractional, possibly outside) voxel index `index`.
    pub fn point(&self, index: [f64; 3]) -> Vec3 {
        let p = self.voxel_to_world * Vector4::new(index[0], index[1], index[2], 1.0);
        Vec3::new(p.x, p.y, p.z)
    }

    /// The voxel centres, `x` fastest, of the slices `z`.
    pub fn centres(&self, z: Range<usize>) -> Vec<Vec3> {
        let [nx, ny, _] = self.dims;
        z.flat_map(|k| (0..ny).flat_map(move |j| (0..nx).map(move |i| [i, j, k])))
            .map(|[i, j, k]| self.point([i as f64, j as f64, k as f64]))
            .collect()
    }

    /// The spacing along each axis, mm.
    pub fn spacing(&self) -> [f64; 3] {
        std::array::from_fn(|a| self.voxel_to_world.fixed_view::<3, 1>(0, a).norm())
    }
}

/// How finely [`GridMap`] works.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridOptions {
    /// The largest distance (mm) allowed between a voxel's displacement and the exact map's.
    pub tolerance_mm: f64,
    /// Voxels between control nodes (default: [`STRIDE_PER_SIGMA`] σ in voxels).
    pub stride: Option<usize>,
}

impl GridOptions {
    /// A tolerance in voxels of the lattice (its smallest spacing), the default stride.
    pub fn voxels(lattice: &Lattice, voxels: f64) -> Self {
        let h = lattice.spacing().into_iter().fold(f64::INFINITY, f64::min);
        Self {
            tolerance_mm: voxels * h,
            stride: None,
        }
    }
}

/// What a control cell does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cell {
    /// Its 64 nodes do not move: nor do its voxels.
    Still,
    /// Interpolated from its nodes.
    Interpolated,
    /// Its voxels mapped one by one.
    Mapped,
}

/// The displacement of a map of a fitted flow on a voxel grid, from a control grid (module
/// documentation).
///
/// ```
/// use medial_core::flow::ambient::grid::{GridMap, GridOptions, Lattice};
/// use medial_core::flow::ambient::AmbientFlow;
/// use medial_core::flow::{Flow, FlowParams};
/// use medial_core::Vec3;
/// use nalgebra::Matrix4;
/// let params = FlowParams { sigma: 2.0, time_steps: 4, kinetic_weight: 0.0 };
/// let flow = Flow::new(params, 2).unwrap();
/// let q0 = [Vec3::new(4.0, 4.0, 4.0), Vec3::new(6.0, 4.0, 4.0)];
/// let u = vec![0.3; flow.momenta_len()];
/// let ambient = AmbientFlow::new(&flow, &flow.shoot(&q0, &u).unwrap(), &u).unwrap();
/// let lattice = Lattice { dims: [20, 16, 16], voxel_to_world: Matrix4::new_scaling(0.5) };
/// let options = GridOptions { tolerance_mm: 1e-3, stride: None };
/// let map = GridMap::new(&ambient, &lattice, true, &options).unwrap();
/// let d = map.displacements(0..16).unwrap();
/// let centres = lattice.centres(0..16);
/// let exact = ambient.inverse(&centres).unwrap();
/// for ((d, y), x) in d.iter().zip(&centres).zip(&exact) {
///     assert!((y + d - x).norm() <= 1e-3);
/// }
/// ```
pub struct GridMap<'a> {
    flow: &'a AmbientFlow,
    lattice: Lattice,
    inverse: bool,
    stride: usize,
    epsilon: f64,
    /// Nodes along each axis: `(n − 1)/s + 6`, node `a` at voxel `(a − 2) s`.
    node_dims: [usize; 3],
    /// The displacement at each node, `x` fastest.
    nodes: Vec<Vec3>,
    /// Cells along each axis: `(n − 1)/s + 1`.
    cell_dims: [usize; 3],
    cells: Vec<Cell>,
    /// The largest error estimate of an interpolated cell, mm.
    estimate: f64,
}

impl<'a> GridMap<'a> {
    /// The control grid of `φ₁` (`φ₁⁻¹` with `inverse`) of `flow` on `lattice`.
    ///
    /// Errors: [`Error::InvalidParameter`] for a tolerance that is not a positive number, a
    /// stride of 0, an empty lattice; those of [`AmbientFlow::map_truncated`].
    pub fn new(
        flow: &'a AmbientFlow,
        lattice: &Lattice,
        inverse: bool,
        options: &GridOptions,
    ) -> Result<Self> {
        let tolerance = options.tolerance_mm;
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(Error::InvalidParameter(format!(
                "the tolerance of a control grid must be a positive number of mm, got {tolerance}"
            )));
        }
        if lattice.dims.contains(&0) {
            return Err(Error::InvalidParameter("the voxel grid is empty".into()));
        }
        let h_max = lattice.spacing().into_iter().fold(0.0, f64::max);
        if !(h_max.is_finite() && h_max > 0.0) {
            return Err(Error::InvalidParameter(
                "the voxel grid's spacing is not a positive number".into(),
            ));
        }
        let stride = match options.stride {
            Some(0) => {
                return Err(Error::InvalidParameter(
                    "the stride of a control grid must be at least 1".into(),
                ))
            }
            Some(s) => s,
            None => {
                ((STRIDE_PER_SIGMA * flow.sigma() / h_max).floor() as usize).clamp(1, MAX_STRIDE)
            }
        };
        let epsilon = flow.truncation_for(TRUNCATION_SHARE * tolerance);
        let cell_dims = lattice.dims.map(|n| (n - 1) / stride + 1);
        let node_dims = cell_dims.map(|c| c + 5);
        let mut map = Self {
            flow,
            lattice: lattice.clone(),
            inverse,
            stride,
            epsilon,
            node_dims,
            nodes: Vec::new(),
            cell_dims,
            cells: Vec::new(),
            estimate: 0.0,
        };
        map.nodes = map.map_nodes()?;
        let budget = tolerance - LEBESGUE.powi(3) * flow.truncation_bound(epsilon);
        map.judge_cells(budget);
        Ok(map)
    }

    /// Voxels between nodes.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The kernel tolerance ε of the truncated maps.
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// The control nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The fraction of the control cells whose voxels are mapped one by one.
    pub fn mapped_fraction(&self) -> f64 {
        let mapped = self.cells.iter().filter(|&&c| c == Cell::Mapped).count();
        mapped as f64 / self.cells.len() as f64
    }

    /// The largest estimated error of an interpolated cell (module documentation), mm.
    pub fn interpolation_estimate(&self) -> f64 {
        self.estimate
    }

    /// The displacements `φ(y) − y` of the voxel centres `y` of the slices `z` (`x` fastest).
    ///
    /// Errors: [`Error::InvalidParameter`] for slices beyond the grid; those of
    /// [`AmbientFlow::map_truncated`].
    pub fn displacements(&self, z: Range<usize>) -> Result<Vec<Vec3>> {
        let [nx, ny, nz] = self.lattice.dims;
        if z.start > z.end || z.end > nz {
            return Err(Error::InvalidParameter(format!(
                "slices {}..{} of a grid of {nz}",
                z.start, z.end
            )));
        }
        let s = self.stride;
        let rows: Vec<Vec<Vec3>> = z
            .clone()
            .flat_map(|k| (0..ny).map(move |j| (j, k)))
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(j, k)| {
                (0..nx)
                    .map(|i| match self.cell_of([i, j, k]) {
                        (_, Cell::Still | Cell::Mapped) => Vec3::zeros(),
                        (c, Cell::Interpolated) => self.interpolate(c, [i % s, j % s, k % s]),
                    })
                    .collect()
            })
            .collect();
        let mut out: Vec<Vec3> = rows.into_iter().flatten().collect();
        // The voxels of mapped cells, cell by cell, each cell's voxels in one block.
        let [cx, cy, _] = self.cell_dims;
        let first = z.start / s;
        let last = if z.is_empty() {
            first
        } else {
            (z.end - 1) / s + 1
        };
        let mut index = Vec::new();
        let mut blocks: Vec<Vec<Vec3>> = Vec::new();
        for c in first..last {
            for b in 0..cy {
                // Cells next to each other along x share a block, up to MAPPED_BLOCK voxels.
                let mut previous = None;
                for a in 0..cx {
                    if self.cells[(c * cy + b) * cx + a] != Cell::Mapped {
                        continue;
                    }
                    let adjacent = previous == Some(a.wrapping_sub(1));
                    previous = Some(a);
                    let mut block = match blocks.last() {
                        Some(last) if adjacent && last.len() < MAPPED_BLOCK => {
                            blocks.pop().unwrap_or_default()
                        }
                        _ => Vec::new(),
                    };
                    for k in (c * s..(c + 1) * s).filter(|k| z.contains(k)) {
                        for j in b * s..((b + 1) * s).min(ny) {
                            for i in a * s..((a + 1) * s).min(nx) {
                                index.push(((k - z.start) * ny + j) * nx + i);
                                block.push(self.lattice.point([i as f64, j as f64, k as f64]));
                            }
                        }
                    }
                    blocks.push(block);
                }
            }
        }
        let mapped = self.flow.map_blocks(&blocks, self.inverse, self.epsilon)?;
        let points = blocks.iter().flatten();
        for ((i, y), x) in index.into_iter().zip(points).zip(mapped) {
            out[i] = x - y;
        }
        Ok(out)
    }

    /// The cell of voxel `v` (its index into the cells) and what it does.
    fn cell_of(&self, v: [usize; 3]) -> (usize, Cell) {
        let [cx, cy, _] = self.cell_dims;
        let [a, b, c] = v.map(|i| i / self.stride);
        let index = (c * cy + b) * cx + a;
        (index, self.cells[index])
    }

    /// Node `[a, b, c]`'s index.
    fn node(&self, n: [usize; 3]) -> usize {
        let [nx, ny, _] = self.node_dims;
        (n[2] * ny + n[1]) * nx + n[0]
    }

    /// The displacement interpolated in cell `cell` at the voxel offset `r` (voxels from its
    /// first corner).
    fn interpolate(&self, cell: usize, r: [usize; 3]) -> Vec3 {
        let [cx, cy, _] = self.cell_dims;
        let corner = [cell % cx, (cell / cx) % cy, cell / (cx * cy)];
        let w = r.map(|r| lagrange(r as f64 / self.stride as f64));
        let mut sum = Vec3::zeros();
        for (dc, wz) in w[2].iter().enumerate() {
            let mut plane = Vec3::zeros();
            for (db, wy) in w[1].iter().enumerate() {
                let mut line = Vec3::zeros();
                for (da, wx) in w[0].iter().enumerate() {
                    // Nodes c − 1 … c + 2 of the cell: array indices c + 1 … c + 4.
                    let n = self.node([corner[0] + 1 + da, corner[1] + 1 + db, corner[2] + 1 + dc]);
                    line += *wx * self.nodes[n];
                }
                plane += *wy * line;
            }
            sum += *wz * plane;
        }
        sum
    }

    /// The displacements of all nodes, in blocks of 8³ nodes.
    fn map_nodes(&self) -> Result<Vec<Vec3>> {
        let s = self.stride as f64;
        let dims = self.node_dims;
        let block_dims = dims.map(|n| n.div_ceil(BLOCK));
        let mut blocks = Vec::new();
        let mut index = Vec::new();
        for bc in 0..block_dims[2] {
            for bb in 0..block_dims[1] {
                for ba in 0..block_dims[0] {
                    let mut block = Vec::new();
                    for c in bc * BLOCK..((bc + 1) * BLOCK).min(dims[2]) {
                        for b in bb * BLOCK..((bb + 1) * BLOCK).min(dims[1]) {
                            for a in ba * BLOCK..((ba + 1) * BLOCK).min(dims[0]) {
                                index.push(self.node([a, b, c]));
                                let v = [a, b, c].map(|n| (n as f64 - 2.0) * s);
                                block.push(self.lattice.point(v));
                            }
                        }
                    }
                    blocks.push(block);
                }
            }
        }
        let mapped = self.flow.map_blocks(&blocks, self.inverse, self.epsilon)?;
        let mut nodes = vec![Vec3::zeros(); dims.iter().product()];
        for ((i, y), x) in index.into_iter().zip(blocks.iter().flatten()).zip(mapped) {
            nodes[i] = x - y;
        }
        Ok(nodes)
    }

    /// Marks each cell still, interpolated (estimate within `budget` mm) or mapped.
    fn judge_cells(&mut self, budget: f64) {
        let [cx, cy, cz] = self.cell_dims;
        let judged: Vec<(Cell, f64)> = (0..cx * cy * cz)
            .into_par_iter()
            .map(|cell| {
                let corner = [cell % cx, (cell / cx) % cy, cell / (cx * cy)];
                let mut still = true;
                for dc in 1..5 {
                    for db in 1..5 {
                        for da in 1..5 {
                            let n = [corner[0] + da, corner[1] + db, corner[2] + dc];
                            still &= self.nodes[self.node(n)] == Vec3::zeros();
                        }
                    }
                }
                if still {
                    return (Cell::Still, 0.0);
                }
                // D_a at the eight corners (array indices c + 2, c + 3).
                let mut d = [0.0f64; 3];
                for dc in 2..4 {
                    for db in 2..4 {
                        for da in 2..4 {
                            let n = [corner[0] + da, corner[1] + db, corner[2] + dc];
                            for (axis, d) in d.iter_mut().enumerate() {
                                *d = d.max(self.fourth_difference(n, axis));
                            }
                        }
                    }
                }
                let estimate = INTERPOLATION_SAFETY
                    * LAGRANGE_ERROR
                    * (d[2] + LEBESGUE * d[1] + LEBESGUE * LEBESGUE * d[0]);
                if estimate <= budget {
                    (Cell::Interpolated, estimate)
                } else {
                    (Cell::Mapped, 0.0)
                }
            })
            .collect();
        self.estimate = judged.iter().map(|j| j.1).fold(0.0, f64::max);
        self.cells = judged.into_iter().map(|j| j.0).collect();
    }

    /// `|d_{m−2} − 4 d_{m−1} + 6 d_m − 4 d_{m+1} + d_{m+2}|` along `axis` at node `n`.
    fn fourth_difference(&self, n: [usize; 3], axis: usize) -> f64 {
        let at = |offset: isize| {
            let mut m = n;
            m[axis] = (n[axis] as isize + offset) as usize;
            self.nodes[self.node(m)]
        };
        (at(-2) - 4.0 * at(-1) + 6.0 * at(0) - 4.0 * at(1) + at(2)).norm()
    }
}

/// The weights of the 4-point Lagrange cubic through the nodes −1, 0, 1, 2 at `t`.
fn lagrange(t: f64) -> [f64; 4] {
    [
        -t * (t - 1.0) * (t - 2.0) / 6.0,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
        -(t + 1.0) * t * (t - 2.0) / 2.0,
        (t + 1.0) * t * (t - 1.0) / 6.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::{Flow, FlowParams};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A flow of `k` landmarks on a wavy sheet in a 12 mm box, pushed by smooth momenta of
    /// size `strength` (a fitted flow's kind: coherent momenta), σ = 1.4 mm, 10 steps.
    fn flow(seed: u64, k: usize, strength: f64) -> AmbientFlow {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let q0: Vec<Vec3> = (0..k)
            .map(|_| {
                let (x, y): (f64, f64) = (rng.gen_range(2.0..10.0), rng.gen_range(2.0..10.0));
                Vec3::new(x, y, 6.0 + (0.5 * x).sin())
            })
            .collect();
        let steps = 10;
        let u: Vec<f64> = (0..steps)
            .flat_map(|_| q0.iter())
            .flat_map(|q| {
                let d = strength * Vec3::new((0.3 * q.y).cos(), 0.5, (0.4 * q.x).sin());
                [d.x, d.y, d.z]
            })
            .collect();
        let params = FlowParams {
            sigma: 1.4,
            time_steps: steps,
            kinetic_weight: 0.0,
        };
        let flow = Flow::new(params, k).unwrap();
        let trajectory = flow.shoot(&q0, &u).unwrap();
        AmbientFlow::new(&flow, &trajectory, &u).unwrap()
    }

    fn lattice() -> Lattice {
        let mut m = Matrix4::new_scaling(0.5);
        m[(3, 3)] = 1.0;
        // Oblique, so that the grid's axes are not the world's.
        let r = nalgebra::Rotation3::from_euler_angles(0.2, -0.1, 0.3).to_homogeneous();
        Lattice {
            dims: [26, 24, 25],
            voxel_to_world: r * m,
        }
    }

    /// The largest distance between the grid's and the exact map's images of every voxel.
    fn worst<'a>(
        flow: &'a AmbientFlow,
        inverse: bool,
        options: &GridOptions,
    ) -> (f64, GridMap<'a>) {
        let lattice = lattice();
        let map = GridMap::new(flow, &lattice, inverse, options).unwrap();
        let nz = lattice.dims[2];
        // In slabs of 7 slices (not a multiple of the stride) and whole.
        let mut d = Vec::new();
        for z in (0..nz).step_by(7) {
            d.extend(map.displacements(z..(z + 7).min(nz)).unwrap());
        }
        // The voxels of mapped cells share their blocks (and so the landmarks kept) differently
        // in other slabs: the same within twice the truncation's bound.
        let whole = map.displacements(0..nz).unwrap();
        let apart = d
            .iter()
            .zip(&whole)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            apart <= 2.0 * TRUNCATION_SHARE * options.tolerance_mm,
            "{apart}"
        );
        let y = lattice.centres(0..nz);
        let exact = if inverse {
            flow.inverse(&y).unwrap()
        } else {
            flow.forward(&y).unwrap()
        };
        let error = (y.iter().zip(&d).zip(&exact))
            .map(|((y, d), x)| (y + d - x).norm())
            .fold(0.0, f64::max);
        (error, map)
    }

    #[test]
    fn voxels_are_within_the_tolerance_of_the_exact_map_both_ways() {
        let flow = flow(3, 150, 0.6);
        for inverse in [false, true] {
            for tolerance in [1e-2, 1e-3] {
                let options = GridOptions {
                    tolerance_mm: tolerance,
                    stride: Some(2),
                };
                let (error, map) = worst(&flow, inverse, &options);
                println!(
                    "inverse {inverse}, tolerance {tolerance}: error {error:.2e} mm, estimate \
                     {:.2e}, mapped {:.2}",
                    map.interpolation_estimate(),
                    map.mapped_fraction()
                );
                assert!(error <= tolerance, "{error} mm");
                assert!(map.interpolation_estimate() <= tolerance);
                // Some cells are interpolated: the grid does work.
                assert!(map.mapped_fraction() < 1.0);
            }
        }
    }

    #[test]
    fn a_coarse_stride_still_keeps_the_tolerance_by_mapping_voxels() {
        let flow = flow(5, 120, 0.8);
        let options = GridOptions {
            tolerance_mm: 1e-3,
            stride: Some(5),
        };
        let (error, map) = worst(&flow, true, &options);
        assert!(error <= 1e-3, "{error} mm");
        assert!(map.mapped_fraction() > 0.0);
    }

    #[test]
    fn displacements_are_the_same_bits_whatever_the_thread_count() {
        let flow = flow(7, 100, 0.6);
        let lattice = lattice();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let options = GridOptions::voxels(&lattice, 0.01);
                let map = GridMap::new(&flow, &lattice, true, &options).unwrap();
                map.displacements(0..lattice.dims[2]).unwrap()
            })
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
    }

    #[test]
    fn bad_options_are_refused() {
        let flow = flow(1, 10, 0.1);
        let lattice = lattice();
        for (tolerance, stride) in [(0.0, None), (f64::NAN, None), (-1.0, None), (1e-3, Some(0))] {
            let options = GridOptions {
                tolerance_mm: tolerance,
                stride,
            };
            let err = GridMap::new(&flow, &lattice, false, &options)
                .err()
                .unwrap();
            assert!(matches!(err, Error::InvalidParameter(_)), "{err}");
        }
        let empty = Lattice {
            dims: [0, 3, 3],
            ..lattice.clone()
        };
        let options = GridOptions::voxels(&lattice, 0.01);
        assert!(GridMap::new(&flow, &empty, false, &options).is_err());
        let map = GridMap::new(&flow, &lattice, false, &options).unwrap();
        assert!(map.displacements(0..99).is_err());
    }

    #[test]
    fn lagrange_weights_reproduce_cubics() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = lagrange(t);
            let f = |x: f64| 1.0 - 2.0 * x + 0.5 * x * x - 0.3 * x * x * x;
            let p: f64 = (-1..=2).zip(w).map(|(n, w)| w * f(n as f64)).sum();
            assert!((p - f(t)).abs() < 1e-12);
            assert!(w.iter().map(|w| w.abs()).sum::<f64>() <= LEBESGUE + 1e-12);
        }
    }
}
