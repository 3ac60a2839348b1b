//! Scalar volumes (images) on a regular grid placed in world space by an affine map.
//!
//! A [`Volume`] holds `nx·ny·nz` values, `x` fastest (index `i + nx·(j + ny·k)`), and the 4×4
//! affine `voxel_to_world` that takes a voxel index `(i, j, k)` to RAS world coordinates in mm.
//! Voxel centres sit at integer indices. Sampling is trilinear in the zero-extended grid, so the
//! sampled function is continuous everywhere, equal to the stored value at voxel centres and 0
//! farther than one voxel outside the grid.

use nalgebra::{Matrix3, Matrix4, Vector4};
use rayon::prelude::*;

use crate::mesh::Bounds;
use crate::{Error, Result, Vec3};

/// Relative size below which `|det|` of the 3×3 part (against the product of its column norms)
/// is taken as a degenerate (flat) grid.
const DEGENERATE_SINE: f64 = 1e-10;

/// Voxel indices `lo ..= hi` of a box in a grid.
type IndexBox = ([usize; 3], [usize; 3]);

/// The grid of the box `lo ..= hi` with every voxel split `factor` times along each axis.
fn refined_dims(lo: [usize; 3], hi: [usize; 3], factor: usize) -> [usize; 3] {
    std::array::from_fn(|a| (hi[a] - lo[a] + 1) * factor)
}

/// A scalar image on a regular grid with an affine voxel-to-world map.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    dims: [usize; 3],
    data: Vec<f64>,
    voxel_to_world: Matrix4<f64>,
    world_to_voxel: Matrix4<f64>,
}

impl Volume {
    /// Builds a volume from its grid size `dims = [nx, ny, nz]`, values `data` (x fastest) and
    /// the affine `voxel_to_world` (voxel index → RAS mm).
    ///
    /// Refuses: a zero dimension, `data.len() != nx·ny·nz`, a non-finite value, a non-finite
    /// matrix, a last row other than `0 0 0 1`, and a singular or nearly flat 3×3 part (a zero
    /// column or `|det| < 1e-10 · Π |column|`).
    pub fn new(dims: [usize; 3], data: Vec<f64>, voxel_to_world: Matrix4<f64>) -> Result<Self> {
        let count = voxel_count(dims)?;
        if data.len() != count {
            return Err(Error::ShapeMismatch {
                what: format!(
                    "voxel values of a {}×{}×{} volume",
                    dims[0], dims[1], dims[2]
                ),
                expected: count,
                found: data.len(),
            });
        }
        if let Some(n) = data.iter().position(|v| !v.is_finite()) {
            let (i, j, k) = (
                n % dims[0],
                (n / dims[0]) % dims[1],
                n / (dims[0] * dims[1]),
            );
            return Err(Error::NonFinite(format!(
                "voxel ({i}, {j}, {k}) has value {}",
                data[n]
            )));
        }
        let world_to_voxel = check_affine(&voxel_to_world)?;
        Ok(Self {
            dims,
            data,
            voxel_to_world,
            world_to_voxel,
        })
    }

    /// The grid size `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The values, `x` fastest: voxel `(i, j, k)` is at `i + nx·(j + ny·k)`.
    pub fn data(&self) -> &[f64] {
        &self.data
    }

    /// The affine map voxel index `(i, j, k, 1)` → world `(x, y, z, 1)` (RAS, mm).
    pub fn voxel_to_world(&self) -> &Matrix4<f64> {
        &self.voxel_to_world
    }

    /// The inverse affine map world (mm) → continuous voxel index.
    pub fn world_to_voxel(&self) -> &Matrix4<f64> {
        &self.world_to_voxel
    }

    /// Volume of one voxel in mm³: `|det A|`, `A` the 3×3 part of `voxel_to_world`.
    pub fn voxel_volume(&self) -> f64 {
        linear_part(&self.voxel_to_world).determinant().abs()
    }

    /// Voxel spacing along each voxel axis in mm: the column norms of the 3×3 part.
    pub fn spacing(&self) -> Vec3 {
        let a = linear_part(&self.voxel_to_world);
        Vec3::new(a.column(0).norm(), a.column(1).norm(), a.column(2).norm())
    }

    /// World position (mm) of the centre of voxel `(i, j, k)`.
    pub fn voxel_centre(&self, index: [usize; 3]) -> Vec3 {
        let v = Vector4::new(index[0] as f64, index[1] as f64, index[2] as f64, 1.0);
        (self.voxel_to_world * v).xyz()
    }

    /// The binary mask of the foreground, same grid: `1` where `v == label` if a label is given,
    /// else where `v > 0`; `0` elsewhere.
    pub fn foreground(&self, label: Option<f64>) -> Self {
        let data = self
            .data
            .iter()
            .map(|&v| {
                let inside = match label {
                    Some(l) => v == l,
                    None => v > 0.0,
                };
                f64::from(u8::from(inside))
            })
            .collect();
        self.with_data(data)
    }

    /// The image convolved with a Gaussian of standard deviation `sigma_mm` (mm).
    ///
    /// Separable along the voxel axes: along axis `a` the kernel is
    /// `w_j ∝ exp(−j² / (2 σ_a²))`, `σ_a = sigma_mm / spacing_a`, `|j| ≤ ⌈4 σ_a⌉`, normalised to
    /// sum 1, with zeros outside the grid (total mass is kept unless it reaches the border).
    /// `sigma_mm = 0` returns a copy. Parallel over lines; the result does not depend on the
    /// thread count. Refuses a negative or non-finite `sigma_mm`, and one wider than the grid's
    /// diagonal (the voxel cells included), whose kernel would outgrow memory to give a flat
    /// image.
    pub fn smoothed(&self, sigma_mm: f64) -> Result<Self> {
        if !(sigma_mm.is_finite() && sigma_mm >= 0.0) {
            return Err(Error::InvalidParameter(format!(
                "Gaussian smoothing sigma must be finite and ≥ 0 mm, got {sigma_mm}"
            )));
        }
        let diagonal =
            (linear_part(&self.voxel_to_world) * Vec3::from(self.dims.map(|n| n as f64))).norm();
        if sigma_mm > diagonal {
            return Err(Error::InvalidParameter(format!(
                "Gaussian smoothing sigma {sigma_mm} mm is wider than the whole image ({diagonal:.1} \
                 mm across): the smoothed image would be flat"
            )));
        }
        let spacing = self.spacing();
        let mut data = self.data.clone();
        if sigma_mm > 0.0 {
            for axis in 0..3 {
                let kernel = gaussian_kernel(sigma_mm / spacing[axis]);
                data = convolve_axis(&data, self.dims, axis, &kernel);
            }
        }
        Ok(self.with_data(data))
    }

    /// The trilinear interpolant at world point `p` (mm), 0 outside (see the module doc).
    /// A non-finite `p` gives NaN.
    pub fn sample(&self, p: &Vec3) -> f64 {
        self.sample_with_gradient(p).0
    }

    /// The value of the voxel nearest to world point `p` (mm) in voxel coordinates (the voxel
    /// whose cell of ±½ voxel holds `p`; halves rounded away from 0), 0 outside the grid: the
    /// sampling of label maps. A non-finite `p` gives NaN.
    pub fn sample_nearest(&self, p: &Vec3) -> f64 {
        if !p.iter().all(|c| c.is_finite()) {
            return f64::NAN;
        }
        let v = (self.world_to_voxel * p.push(1.0)).xyz();
        // Beyond the i64 range `as` saturates, far outside the grid either way.
        let [i, j, k] = [v.x, v.y, v.z].map(|c| c.round() as i64);
        self.at(i, j, k)
    }

    /// The trilinear interpolant at world point `p` and its exact gradient with respect to `p`
    /// (per mm): `∇_p f = Aᵀ ∇_v f`, `A` the 3×3 part of the world-to-voxel map. On a cell face,
    /// where the interpolant has a kink, the gradient is the one of the cell with the larger
    /// index. A non-finite `p` gives NaN for both.
    pub fn sample_with_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        if !p.iter().all(|c| c.is_finite()) {
            return (f64::NAN, Vec3::repeat(f64::NAN));
        }
        let v = (self.world_to_voxel * p.push(1.0)).xyz();
        let (value, grad_voxel) = self.trilinear(&v);
        (
            value,
            linear_part(&self.world_to_voxel).transpose() * grad_voxel,
        )
    }

    /// The world bounding box (mm) of the voxels with a non-zero value, each voxel the cell of
    /// ±½ voxel about its centre along every voxel axis; `None` when every value is 0.
    pub fn support_bounds(&self) -> Option<Bounds> {
        let (lo, hi) = self.index_box(|v| v != 0.0, 0)?;
        let corners: Vec<Vec3> = (0..8)
            .map(|c: usize| {
                let index = Vector4::from_fn(|a, _| match a {
                    3 => 1.0,
                    _ if c >> a & 1 == 0 => lo[a] as f64 - 0.5,
                    _ => hi[a] as f64 + 0.5,
                });
                (self.voxel_to_world * index).xyz()
            })
            .collect();
        Bounds::of(&corners)
    }

    /// The voxel indices `lo ..= hi` of the box around the voxels whose value passes
    /// `inside`, widened by `margin` voxels on every side within the grid; `None` when no
    /// voxel passes.
    fn index_box(&self, inside: impl Fn(f64) -> bool, margin: usize) -> Option<IndexBox> {
        let [nx, ny, _] = self.dims;
        let mut range: Option<IndexBox> = None;
        for (n, _) in self.data.iter().enumerate().filter(|(_, &v)| inside(v)) {
            let index = [n % nx, (n / nx) % ny, n / (nx * ny)];
            let (lo, hi) = range.get_or_insert((index, index));
            for a in 0..3 {
                lo[a] = lo[a].min(index[a]);
                hi[a] = hi[a].max(index[a]);
            }
        }
        let (lo, hi) = range?;
        Some((
            lo.map(|i| i.saturating_sub(margin)),
            std::array::from_fn(|a| (hi[a] + margin).min(self.dims[a] - 1)),
        ))
    }

    /// The grid size of [`Self::refined`] with these arguments (without computing it).
    pub fn refined_dims(&self, factor: usize, margin: usize) -> [usize; 3] {
        match self.index_box(|v| v > 0.0, margin) {
            Some((lo, hi)) => refined_dims(lo, hi, factor.max(1)),
            None => self.dims,
        }
    }

    /// Whether the image is a graded signed image, such as a level set whose foreground is
    /// `v > 0` (cmrep's convention): it has negative and positive values and values strictly
    /// between its least and greatest. The zero crossing of its trilinear interpolant then
    /// places the boundary between voxel centres, which [`Self::refined`] can use.
    pub fn is_graded_signed(&self) -> bool {
        let (min, max) = self
            .data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        min < 0.0 && max > 0.0 && self.data.iter().any(|&v| min < v && v < max)
    }

    /// The trilinear interpolant ([`Self::sample`]) on a grid `factor` times finer along every
    /// axis, over the box of the voxels within `margin` voxels of a positive one: along each
    /// axis, fine voxel `j` sits at index `lo + (j − (f − 1)/2)/f` of this grid, so that every
    /// voxel is split into `f³` and the fine centres are symmetric about the coarse ones. The
    /// foreground `v > 0` of the result follows the zero crossing of a signed image to `1/f`
    /// of a voxel instead of a staircase of whole voxels; outside the box the foreground is
    /// empty, as in this image. A copy when no voxel is positive.
    ///
    /// Errors: `factor = 0` (`InvalidParameter`), and those of [`Volume::new`] for the fine grid.
    pub fn refined(&self, factor: usize, margin: usize) -> Result<Self> {
        if factor == 0 {
            return Err(Error::InvalidParameter(
                "an image refinement factor must be at least 1".into(),
            ));
        }
        let Some((lo, hi)) = self.index_box(|v| v > 0.0, margin) else {
            return Ok(self.clone());
        };
        let f = factor as f64;
        let dims = refined_dims(lo, hi, factor);
        let offset = Vec3::from_fn(|a, _| lo[a] as f64 - (f - 1.0) / (2.0 * f));
        let fine_to_coarse = Matrix4::new_translation(&offset) * Matrix4::new_scaling(1.0 / f);
        self.resampled(dims, self.voxel_to_world * fine_to_coarse)
    }

    /// The image sampled ([`Self::sample`], trilinear) at the voxel centres of the grid `dims`,
    /// `voxel_to_world`. Parallel over `k` slices, deterministic.
    ///
    /// Errors: those of [`Volume::new`] for the new grid.
    pub fn resampled(&self, dims: [usize; 3], voxel_to_world: Matrix4<f64>) -> Result<Self> {
        let [nx, ny, nz] = dims;
        voxel_count(dims)?;
        check_affine(&voxel_to_world)?;
        let data: Vec<f64> = (0..nz)
            .into_par_iter()
            .flat_map_iter(|k| {
                (0..nx * ny).map(move |n| {
                    let v = Vector4::new((n % nx) as f64, (n / nx) as f64, k as f64, 1.0);
                    self.sample(&(voxel_to_world * v).xyz())
                })
            })
            .collect();
        Self::new(dims, data, voxel_to_world)
    }

    /// `∫ f = Σ values × voxel volume` (mm³ for a mask).
    pub fn integral(&self) -> f64 {
        self.data.iter().sum::<f64>() * self.voxel_volume()
    }

    /// The same grid with other values (length already checked by the caller).
    fn with_data(&self, data: Vec<f64>) -> Self {
        debug_assert_eq!(data.len(), self.data.len());
        Self {
            dims: self.dims,
            data,
            voxel_to_world: self.voxel_to_world,
            world_to_voxel: self.world_to_voxel,
        }
    }

    /// Value of voxel `(i, j, k)`, 0 outside the grid.
    fn at(&self, i: i64, j: i64, k: i64) -> f64 {
        let [nx, ny, nz] = self.dims.map(|n| n as i64);
        if (0..nx).contains(&i) && (0..ny).contains(&j) && (0..nz).contains(&k) {
            self.data[(i + nx * (j + ny * k)) as usize]
        } else {
            0.0
        }
    }

    /// The 8 values around cell `base` (lower corner), corner `n` at offset
    /// `(n & 1, (n >> 1) & 1, (n >> 2) & 1)`; zeros outside the grid.
    fn cell(&self, base: [i64; 3]) -> [f64; 8] {
        let [nx, ny, nz] = self.dims.map(|n| n as i64);
        let [i, j, k] = base;
        if i >= 0 && j >= 0 && k >= 0 && i + 1 < nx && j + 1 < ny && k + 1 < nz {
            let (sy, sz) = (nx as usize, (nx * ny) as usize);
            let o = (i + nx * (j + ny * k)) as usize;
            let d = &self.data;
            [
                d[o],
                d[o + 1],
                d[o + sy],
                d[o + sy + 1],
                d[o + sz],
                d[o + sz + 1],
                d[o + sz + sy],
                d[o + sz + sy + 1],
            ]
        } else {
            std::array::from_fn(|n| {
                self.at(
                    i + (n & 1) as i64,
                    j + ((n >> 1) & 1) as i64,
                    k + ((n >> 2) & 1) as i64,
                )
            })
        }
    }

    /// Trilinear value and gradient in voxel coordinates `v`.
    fn trilinear(&self, v: &Vec3) -> (f64, Vec3) {
        let outside = (0..3).any(|a| v[a] <= -1.0 || v[a] >= self.dims[a] as f64);
        if outside {
            return (0.0, Vec3::zeros());
        }
        let base = v.map(f64::floor);
        let t = v - base;
        let c = self.cell([base.x as i64, base.y as i64, base.z as i64]);
        // Interpolate along x, then y, then z; differentiate each stage. (Written out: the
        // `array::map` of these small arrays was once compiled out of line, +5 % of the Dice
        // attachment's instructions.)
        let lerp = |a: f64, b: f64, s: f64| a + s * (b - a);
        let x = [
            lerp(c[0], c[1], t.x),
            lerp(c[2], c[3], t.x),
            lerp(c[4], c[5], t.x),
            lerp(c[6], c[7], t.x),
        ];
        let dx = [c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6]];
        let y = [lerp(x[0], x[1], t.y), lerp(x[2], x[3], t.y)];
        let dxy = [lerp(dx[0], dx[1], t.y), lerp(dx[2], dx[3], t.y)];
        let dy = [x[1] - x[0], x[3] - x[2]];
        let value = y[0] + t.z * (y[1] - y[0]);
        let grad = Vec3::new(
            dxy[0] + t.z * (dxy[1] - dxy[0]),
            dy[0] + t.z * (dy[1] - dy[0]),
            y[1] - y[0],
        );
        (value, grad)
    }
}

/// The 3×3 linear part of an affine 4×4 matrix.
fn linear_part(m: &Matrix4<f64>) -> Matrix3<f64> {
    m.fixed_view::<3, 3>(0, 0).into_owned()
}

/// `nx·ny·nz`, refusing a zero dimension and a count that overflows.
pub(crate) fn voxel_count(dims: [usize; 3]) -> Result<usize> {
    if dims.contains(&0) {
        return Err(Error::InvalidVolume(format!(
            "empty grid: dimensions {dims:?}"
        )));
    }
    dims[0]
        .checked_mul(dims[1])
        .and_then(|n| n.checked_mul(dims[2]))
        .ok_or_else(|| Error::InvalidVolume(format!("grid {dims:?} is too large")))
}

/// Checks that `m` is a finite, non-degenerate affine map and returns its inverse.
pub(crate) fn check_affine(m: &Matrix4<f64>) -> Result<Matrix4<f64>> {
    let text = rows(m);
    if !m.iter().all(|c| c.is_finite()) {
        return Err(Error::NonFinite(format!("voxel-to-world matrix {text}")));
    }
    if m.row(3) != nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0) {
        return Err(Error::InvalidVolume(format!(
            "voxel-to-world matrix {text} is not affine: its last row must be 0 0 0 1"
        )));
    }
    let a = linear_part(m);
    if let Some(c) = (0..3).find(|&c| a.column(c).norm() == 0.0) {
        return Err(Error::InvalidVolume(format!(
            "voxel-to-world matrix has a zero column {c} (voxel axis {c} has no extent): {text}"
        )));
    }
    let scale: f64 = (0..3).map(|c| a.column(c).norm()).product();
    if a.determinant().abs() < DEGENERATE_SINE * scale {
        return Err(Error::InvalidVolume(format!(
            "voxel-to-world matrix is singular (voxel axes are coplanar): {text}"
        )));
    }
    m.try_inverse()
        .ok_or_else(|| Error::InvalidVolume(format!("voxel-to-world matrix {text} has no inverse")))
}

/// `m` on one line, row by row: `[[a, b, c, d], [e, …], …]` (nalgebra's `Display` spans lines).
fn rows(m: &Matrix4<f64>) -> String {
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| {
            let entries: Vec<String> = r.iter().map(|x| x.to_string()).collect();
            format!("[{}]", entries.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

/// Normalised Gaussian weights `w_{−R..=R}`, `R = ⌈4σ⌉`, for a standard deviation in voxels.
fn gaussian_kernel(sigma_voxels: f64) -> Vec<f64> {
    let radius = (4.0 * sigma_voxels).ceil() as i64;
    let weights: Vec<f64> = (-radius..=radius)
        .map(|j| (-((j * j) as f64) / (2.0 * sigma_voxels * sigma_voxels)).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    weights.into_iter().map(|w| w / total).collect()
}

/// `out[i] = Σ_j w_j in[i − j]` along voxel axis `axis`, zeros outside. Each parallel task
/// writes one disjoint block of the output (a row for x, a slice for y and z).
fn convolve_axis(input: &[f64], dims: [usize; 3], axis: usize, kernel: &[f64]) -> Vec<f64> {
    let [nx, ny, nz] = dims;
    let radius = (kernel.len() / 2) as i64;
    let mut out = vec![0.0; input.len()];
    // For each tap in order, `add(range, shift, w)` with the destinations `i` of a line of `len`
    // whose source `i − shift` is on the line: each output sums its taps in the kernel's order
    // on every axis, so the passes give the same bits as one loop per voxel.
    let taps = |len: usize, add: &mut dyn FnMut(std::ops::Range<usize>, i64, f64)| {
        for (tap, &w) in kernel.iter().enumerate() {
            let shift = tap as i64 - radius;
            let lo = shift.max(0) as usize;
            let hi = (len as i64 + shift.min(0)).max(0) as usize;
            if lo < hi {
                add(lo..hi, shift, w);
            }
        }
    };
    // `dst[r] += w · src[r − shift]`, one vectorisable loop over the range.
    fn add_shifted(
        dst: &mut [f64],
        src: &[f64],
        range: std::ops::Range<usize>,
        shift: i64,
        w: f64,
    ) {
        let from = (range.start as i64 - shift) as usize;
        let len = range.len();
        dst[range]
            .iter_mut()
            .zip(&src[from..from + len])
            .for_each(|(d, s)| *d += w * s);
    }
    match axis {
        0 => out
            .par_chunks_mut(nx)
            .zip(input.par_chunks(nx))
            .for_each(|(row, src)| {
                taps(nx, &mut |range, shift, w| {
                    add_shifted(row, src, range, shift, w)
                });
            }),
        1 => out
            .par_chunks_mut(nx * ny)
            .zip(input.par_chunks(nx * ny))
            .for_each(|(dst, src)| {
                taps(ny, &mut |range, shift, w| {
                    add_shifted(
                        dst,
                        src,
                        range.start * nx..range.end * nx,
                        shift * nx as i64,
                        w,
                    )
                });
            }),
        _ => out
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, dst)| {
                for (tap, &w) in kernel.iter().enumerate() {
                    let src = k as i64 - (tap as i64 - radius);
                    if (0..nz as i64).contains(&src) {
                        let s = &input[src as usize * nx * ny..(src as usize + 1) * nx * ny];
                        dst.iter_mut().zip(s).for_each(|(d, s)| *d += w * s);
                    }
                }
            }),
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn oblique() -> Matrix4<f64> {
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.7);
        let a = r.matrix() * Matrix3::from_diagonal(&Vec3::new(0.8, 1.1, 1.5));
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&Vec3::new(-4.0, 2.0, 7.5));
        m
    }

    fn random_volume(dims: [usize; 3], seed: u64) -> Volume {
        let mut state = seed;
        let data = (0..dims.iter().product())
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect();
        Volume::new(dims, data, oblique()).unwrap()
    }

    #[test]
    fn nearest_sampling_takes_the_voxel_whose_cell_holds_the_point() {
        let v = random_volume([4, 3, 5], 9);
        let m = *v.voxel_to_world();
        let at = |i: f64, j: f64, k: f64| (m * Vector4::new(i, j, k, 1.0)).xyz();
        assert_eq!(
            v.sample_nearest(&at(2.0, 1.0, 3.0)),
            v.data()[2 + 4 * (1 + 3 * 3)]
        );
        assert_eq!(
            v.sample_nearest(&at(2.4, 0.6, 2.6)),
            v.data()[2 + 4 * (1 + 3 * 3)]
        );
        assert_eq!(
            v.sample_nearest(&at(-0.4, 2.4, 4.4)),
            v.data()[4 * (2 + 3 * 4)]
        );
        assert_eq!(v.sample_nearest(&at(-0.6, 0.0, 0.0)), 0.0);
        assert_eq!(v.sample_nearest(&at(0.0, 0.0, 4.6)), 0.0);
        assert!(v.sample_nearest(&Vec3::new(f64::NAN, 0.0, 0.0)).is_nan());
    }

    #[test]
    fn refuses_bad_input() {
        let m = Matrix4::identity();
        assert!(Volume::new([2, 2, 0], vec![], m).is_err());
        assert!(Volume::new([2, 2, 2], vec![0.0; 7], m).is_err());
        let mut nan = vec![0.0; 8];
        nan[5] = f64::NAN;
        let err = Volume::new([2, 2, 2], nan, m).unwrap_err().to_string();
        assert!(err.contains("(1, 0, 1)"), "{err}");
        let mut flat = m;
        flat[(1, 1)] = 0.0;
        assert!(Volume::new([2, 2, 2], vec![0.0; 8], flat)
            .unwrap_err()
            .to_string()
            .contains("zero column 1"));
        let mut coplanar = m;
        coplanar
            .fixed_view_mut::<3, 1>(0, 2)
            .copy_from(&Vec3::new(1.0, 1.0, 0.0));
        assert!(Volume::new([2, 2, 2], vec![0.0; 8], coplanar).is_err());
        let mut projective = m;
        projective[(3, 0)] = 0.1;
        assert!(Volume::new([2, 2, 2], vec![0.0; 8], projective)
            .unwrap_err()
            .to_string()
            .contains("last row"));
        let mut nan_matrix = m;
        nan_matrix[(0, 3)] = f64::NAN;
        for bad in [flat, coplanar, projective, nan_matrix] {
            let err = Volume::new([2, 2, 2], vec![0.0; 8], bad)
                .unwrap_err()
                .to_string();
            assert!(!err.contains('\n'), "one line: {err}");
            assert!(err.contains("[[1, 0, "), "the matrix row by row: {err}");
        }
        assert!(random_volume([3, 3, 3], 1).smoothed(-1.0).is_err());
        assert!(random_volume([3, 3, 3], 1).smoothed(f64::NAN).is_err());
        let err = random_volume([3, 3, 3], 1).smoothed(1e9).unwrap_err();
        assert!(
            err.to_string().contains("wider than the whole image"),
            "{err}"
        );
    }

    #[test]
    fn geometry_of_an_oblique_grid() {
        let v = random_volume([4, 5, 6], 2);
        assert!((v.voxel_volume() - 0.8 * 1.1 * 1.5).abs() < 1e-12);
        assert!((v.spacing() - Vec3::new(0.8, 1.1, 1.5)).norm() < 1e-12);
        assert!((v.integral() - v.data().iter().sum::<f64>() * 1.32).abs() < 1e-9);
    }

    #[test]
    fn sampling_interpolates_voxel_centres_and_vanishes_outside() {
        let v = random_volume([4, 5, 6], 3);
        for (n, &value) in v.data().iter().enumerate() {
            let centre = v.voxel_centre([n % 4, (n / 4) % 5, n / 20]);
            assert!((v.sample(&centre) - value).abs() < 1e-12);
        }
        let outside = v.voxel_centre([0, 0, 0]) - 1.0001 * v.voxel_to_world().column(0).xyz();
        assert_eq!(v.sample(&outside), 0.0);
        assert!(v.sample(&Vec3::new(f64::NAN, 0.0, 0.0)).is_nan());
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let v = random_volume([4, 5, 6], 4);
        let mut state = 7u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            // Points inside and just outside the grid (the zero-padded band).
            let idx = Vector4::new(
                next() * 5.0 - 1.0,
                next() * 6.0 - 1.0,
                next() * 7.0 - 1.0,
                1.0,
            );
            let p = (v.voxel_to_world() * idx).xyz();
            let (f, g) = v.sample_with_gradient(&p);
            assert_eq!(f, v.sample(&p));
            let h = 1e-6;
            for a in 0..3 {
                let e = Vec3::ith(a, h);
                let fd = (v.sample(&(p + e)) - v.sample(&(p - e))) / (2.0 * h);
                assert!(
                    (fd - g[a]).abs() < 1e-6 * (1.0 + g.norm()),
                    "axis {a}: {fd} vs {}",
                    g[a]
                );
            }
        }
    }

    #[test]
    fn smoothing_keeps_mass_and_is_symmetric() {
        let dims = [21, 19, 17];
        let mut data = vec![0.0; 21 * 19 * 17];
        data[10 + 21 * (9 + 19 * 8)] = 1.0;
        let v = Volume::new(dims, data, Matrix4::new_scaling(0.5)).unwrap();
        let s = v.smoothed(1.0).unwrap();
        assert!((s.integral() - v.integral()).abs() < 1e-12);
        // Second moment along x: σ² = 1 mm² (a discrete Gaussian truncated at 4σ, within 1 %).
        let var: f64 = s
            .data()
            .iter()
            .enumerate()
            .map(|(n, w)| w * ((n % 21) as f64 * 0.5 - 5.0).powi(2))
            .sum::<f64>()
            / s.data().iter().sum::<f64>();
        assert!((var - 1.0).abs() < 0.01, "variance {var}");
        let at = |i: usize, j: usize, k: usize| s.data()[i + 21 * (j + 19 * k)];
        assert_eq!(at(8, 9, 8), at(12, 9, 8));
        assert!((at(10, 7, 8) - at(8, 9, 8)).abs() < 1e-15);
        assert!((at(10, 9, 6) - at(8, 9, 8)).abs() < 1e-15);
        assert_eq!(v.smoothed(0.0).unwrap(), v);
    }

    /// The separable passes against a plain loop per voxel and axis that sums the taps in the
    /// kernel's order from 0 (the same additions): the same bits, on a grid of unequal sides and
    /// spacings whose kernels reach past the grid's ends.
    #[test]
    fn smoothing_matches_a_loop_per_voxel() {
        let dims = [13, 7, 5];
        let v = Volume::new(
            dims,
            random_volume(dims, 3).data().to_vec(),
            Matrix4::new_nonuniform_scaling(&Vec3::new(0.4, 0.7, 1.1)),
        )
        .unwrap();
        let sigma = 1.5;
        let mut data = v.data().to_vec();
        for axis in 0..3 {
            let kernel = gaussian_kernel(sigma / v.spacing()[axis]);
            let radius = (kernel.len() / 2) as i64;
            let mut out = vec![0.0; data.len()];
            for (n, o) in out.iter_mut().enumerate() {
                let mut index = [
                    n % dims[0],
                    (n / dims[0]) % dims[1],
                    n / (dims[0] * dims[1]),
                ];
                let at = index[axis] as i64;
                for (tap, &w) in kernel.iter().enumerate() {
                    let src = at - (tap as i64 - radius);
                    if (0..dims[axis] as i64).contains(&src) {
                        index[axis] = src as usize;
                        *o += w * data[index[0] + dims[0] * (index[1] + dims[1] * index[2])];
                    }
                }
            }
            data = out;
        }
        assert_eq!(v.smoothed(sigma).unwrap().data(), &data[..]);
    }

    #[test]
    fn smoothing_is_deterministic_across_thread_counts() {
        let v = random_volume([30, 20, 10], 5);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| v.smoothed(1.3).unwrap())
        };
        assert_eq!(run(1).data(), run(2).data());
    }

    #[test]
    fn support_bounds_cover_the_non_zero_voxels() {
        let mut data = vec![0.0; 4 * 3 * 2];
        assert_eq!(
            Volume::new([4, 3, 2], data.clone(), oblique())
                .unwrap()
                .support_bounds(),
            None
        );
        data[1 + 4 * (2 + 3)] = 1.0; // voxel (1, 2, 1)
        data[2] = 0.5;
        let v = Volume::new([4, 3, 2], data, oblique()).unwrap();
        let b = v.support_bounds().unwrap();
        // The voxel cells of indices 1…2 × 0…2 × 0…1 (±½ voxel), mapped to the world.
        let corners: Vec<Vec3> = (0..8usize)
            .map(|c| {
                let index = Vector4::new(
                    [0.5, 2.5][c & 1],
                    [-0.5, 2.5][(c >> 1) & 1],
                    [-0.5, 1.5][(c >> 2) & 1],
                    1.0,
                );
                (v.voxel_to_world() * index).xyz()
            })
            .collect();
        let expected = Bounds::of(&corners).unwrap();
        assert!((b.min - expected.min).norm() < 1e-12 && (b.max - expected.max).norm() < 1e-12);
    }

    #[test]
    fn foreground_by_label_or_positive() {
        let v = Volume::new([3, 1, 1], vec![0.0, 2.0, 3.0], Matrix4::identity()).unwrap();
        assert_eq!(v.foreground(None).data(), &[0.0, 1.0, 1.0]);
        assert_eq!(v.foreground(Some(3.0)).data(), &[0.0, 0.0, 1.0]);
    }
}
