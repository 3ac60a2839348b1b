//! The Gaussian kernel `η(r) = exp(−r² / (2σ²))` and its dense symmetric matrix over landmarks.
//!
//! The matrix `K_ij = η(|q_i − q_j|)` is filled with one exponential per unordered pair: the
//! strict upper triangle is computed row-parallel, then mirrored. Every entry is computed by a
//! fixed formula from its two points only, so the matrix is identical whatever the number of
//! threads.

use crate::{Error, Result, Vec3};
use rayon::prelude::*;

/// Rows handed to one rayon task when filling or reducing over the kernel matrix.
pub(crate) const ROW_CHUNK: usize = 8;

/// Gaussian kernel of width `σ` (same unit as the coordinates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianKernel {
    sigma: f64,
    /// `−1 / (2σ²)`.
    neg_half_inv_sigma2: f64,
}

impl GaussianKernel {
    /// A kernel of width `sigma > 0`.
    pub fn new(sigma: f64) -> Result<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::InvalidParameter(format!(
                "kernel width sigma must be a positive number, got {sigma}"
            )));
        }
        Ok(Self { sigma, neg_half_inv_sigma2: -0.5 / (sigma * sigma) })
    }

    /// The width `σ`.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// `η` as a function of the squared distance: `exp(−r² / (2σ²))`.
    #[inline(always)]
    pub fn of_squared_distance(&self, r2: f64) -> f64 {
        exp_nonpositive(r2 * self.neg_half_inv_sigma2)
    }
}

/// `exp(x)` for `x ≤ 0`, branch-free so that the compiler vectorises the loops that call it.
///
/// No maintained crate offers a vectorisable f64 exponential of this accuracy, so it is written
/// here: Cody–Waite reduction `x = k·ln2 + r`, `|r| ≤ ln2/2`, a degree-13 Taylor polynomial
/// (truncation error below 1e-17 relative), and `2^k` built from the exponent bits. The result
/// agrees with `f64::exp` to a few ulp (tested); inputs below −708 return 0.
#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    const LN2_HI: f64 = 6.931_471_803_691_238_2e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const INV_LN2: f64 = std::f64::consts::LOG2_E;
    const MIN_X: f64 = -708.0;
    // Adding 1.5·2⁵² rounds to the nearest integer and leaves it in the low mantissa bits,
    // without a rounding instruction or a float-to-int conversion (both block vectorisation).
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let underflow = x < MIN_X;
    let xc = if underflow { MIN_X } else { x };
    let shifted = xc * INV_LN2 + SHIFTER;
    let kf = shifted - SHIFTER;
    let r = (xc - kf * LN2_HI) - kf * LN2_LO;
    // Horner evaluation of Σ_{i=0}^{13} r^i / i!.
    let mut p = 1.0 / 6_227_020_800.0;
    p = p * r + 1.0 / 479_001_600.0;
    p = p * r + 1.0 / 39_916_800.0;
    p = p * r + 1.0 / 3_628_800.0;
    p = p * r + 1.0 / 362_880.0;
    p = p * r + 1.0 / 40_320.0;
    p = p * r + 1.0 / 5_040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    // k ∈ [−1022, 0]: 2^k is a normal number whose biased exponent k + 1023 sits in the low
    // 12 bits of `shifted`'s representation plus 1023.
    let scale = f64::from_bits(shifted.to_bits().wrapping_add(1023) << 52);
    if underflow {
        0.0
    } else {
        p * scale
    }
}

/// Landmark coordinates in structure-of-arrays layout: `x[i], y[i], z[i]` of landmark `i`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Soa3 {
    /// First coordinates.
    pub x: Vec<f64>,
    /// Second coordinates.
    pub y: Vec<f64>,
    /// Third coordinates.
    pub z: Vec<f64>,
}

impl Soa3 {
    /// `n` zero vectors.
    pub fn zeros(n: usize) -> Self {
        Self { x: vec![0.0; n], y: vec![0.0; n], z: vec![0.0; n] }
    }

    /// From points.
    pub fn from_points(points: &[Vec3]) -> Self {
        Self {
            x: points.iter().map(|p| p.x).collect(),
            y: points.iter().map(|p| p.y).collect(),
            z: points.iter().map(|p| p.z).collect(),
        }
    }

    /// From a flat array `[x0, y0, z0, x1, …]`.
    pub fn from_flat(flat: &[f64]) -> Self {
        Self {
            x: flat.iter().step_by(3).copied().collect(),
            y: flat.iter().skip(1).step_by(3).copied().collect(),
            z: flat.iter().skip(2).step_by(3).copied().collect(),
        }
    }

    /// Number of vectors.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// No vectors.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Vector `i`.
    #[inline]
    pub fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    /// Sets vector `i`.
    #[inline]
    pub fn set(&mut self, i: usize, v: Vec3) {
        self.x[i] = v.x;
        self.y[i] = v.y;
        self.z[i] = v.z;
    }

    /// As points.
    pub fn to_points(&self) -> Vec<Vec3> {
        (0..self.len()).map(|i| self.get(i)).collect()
    }
}

/// The dense symmetric matrix `K_ij = η(|q_i − q_j|)`, row-major, `k × k`, unit diagonal.
#[derive(Clone, Debug, Default)]
pub struct KernelMatrix {
    k: usize,
    values: Vec<f64>,
}

impl KernelMatrix {
    /// Fills the matrix for the points `q`, reusing the allocation: one exponential per
    /// unordered pair (upper triangle, row-parallel), then a mirror copy.
    pub fn fill(&mut self, kernel: &GaussianKernel, q: &Soa3) {
        let k = q.len();
        self.k = k;
        self.values.resize(k * k, 0.0);
        self.values.par_chunks_mut(k.max(1)).enumerate().for_each(|(i, row)| {
            row[i] = 1.0;
            let (xi, yi, zi) = (q.x[i], q.y[i], q.z[i]);
            let upper = i + 1..k;
            for (((kij, xj), yj), zj) in
                row[upper.clone()].iter_mut().zip(&q.x[upper.clone()]).zip(&q.y[upper.clone()]).zip(&q.z[upper])
            {
                let (dx, dy, dz) = (xi - xj, yi - yj, zi - zj);
                *kij = kernel.of_squared_distance(dx * dx + dy * dy + dz * dz);
            }
        });
        self.mirror_upper_to_lower();
    }

    /// Copies the strict upper triangle onto the strict lower one, in tiles for cache locality.
    fn mirror_upper_to_lower(&mut self) {
        const TILE: usize = 64;
        let k = self.k;
        let ptr = SyncPtr(self.values.as_mut_ptr());
        (0..k.div_ceil(TILE)).into_par_iter().for_each(|bi| {
            let ptr = &ptr;
            for bj in 0..=bi {
                for i in bi * TILE..((bi + 1) * TILE).min(k) {
                    for j in bj * TILE..((bj + 1) * TILE).min(i) {
                        // SAFETY: task `bi` writes only rows of its own tile row (i in tile bi)
                        // below the diagonal and reads only the strict upper triangle, which no
                        // task writes; all indices are < k².
                        unsafe { *ptr.0.add(i * k + j) = *ptr.0.add(j * k + i) };
                    }
                }
            }
        });
    }

    /// Number of landmarks.
    pub fn size(&self) -> usize {
        self.k
    }

    /// Row `i`.
    #[inline]
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.k..(i + 1) * self.k]
    }

    /// Bytes a matrix for `k` landmarks holds.
    pub fn bytes_for(k: usize) -> usize {
        k * k * std::mem::size_of::<f64>()
    }
}

/// A raw pointer that may cross threads; used only for the disjoint writes of the mirror copy.
struct SyncPtr(*mut f64);
// SAFETY: see `KernelMatrix::mirror_upper_to_lower`: writes are disjoint across tasks.
unsafe impl Sync for SyncPtr {}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ulps(a: f64, b: f64) -> f64 {
        ((a - b) / b.abs().max(f64::MIN_POSITIVE)).abs() / f64::EPSILON
    }

    #[test]
    fn exp_agrees_with_std_to_a_few_ulp() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let x = -700.0 * (i as f64 / 200_000.0).powi(2);
            worst = worst.max(ulps(exp_nonpositive(x), x.exp()));
        }
        assert!(worst < 4.0, "worst error {worst} ulp");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-800.0), 0.0);
        assert_eq!(exp_nonpositive(f64::NEG_INFINITY), 0.0);
    }

    #[test]
    fn kernel_rejects_bad_width() {
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(GaussianKernel::new(s).is_err());
        }
    }

    proptest! {
        #[test]
        fn matrix_is_symmetric_with_exact_entries(
            pts in proptest::collection::vec((-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0), 1..150),
            sigma in 0.3f64..4.0,
        ) {
            let q = Soa3::from_points(&pts.iter().map(|&(x, y, z)| Vec3::new(x, y, z)).collect::<Vec<_>>());
            let kernel = GaussianKernel::new(sigma).unwrap();
            let mut m = KernelMatrix::default();
            m.fill(&kernel, &q);
            for i in 0..q.len() {
                prop_assert_eq!(m.row(i)[i], 1.0);
                for j in 0..q.len() {
                    prop_assert_eq!(m.row(i)[j], m.row(j)[i]);
                    let x = -(q.get(i) - q.get(j)).norm_squared() / (2.0 * sigma * sigma);
                    // exp amplifies the rounding of its argument: relative error ≈ |x|·ε.
                    // Below e^−708 the result is flushed to 0 instead of a subnormal.
                    let tol = (4.0 + 4.0 * x.abs()) * f64::EPSILON * x.exp() + 1e-300;
                    prop_assert!((m.row(i)[j] - x.exp()).abs() <= tol);
                }
            }
        }
    }
}
