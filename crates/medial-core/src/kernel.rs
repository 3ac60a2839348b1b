//! The Gaussian kernel `η(r) = exp(−r² / (2σ²))` and its sums over pairs of landmarks.
//!
//! [`PairSweep`] computes sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over all pairs, with
//! `K_ij = η(|q_i − q_j|)`, for pair terms `t_c` supplied by the caller ([`PairTerms`]). The
//! index range is cut into blocks; every tile (I, J), I ≤ J, of blocks evaluates the kernel once
//! per unordered pair {i, j} and accumulates both the terms of its rows i ∈ I and those of its
//! columns j ∈ J in a buffer of its own. Tiles run in parallel (rayon); the buffers are then
//! reduced in a fixed order. Every number is thus computed by the same operations in the same
//! order whatever the thread count, and results are bit-identical.
//!
//! The inner loops handle [`LANES`] pairs at once and are compiled twice, for the baseline
//! target and for AVX2, chosen at run time. Neither uses fused multiply-adds, so both give the
//! same bits.

use crate::{Error, Result, Vec3};
use rayon::prelude::*;
use std::ops::Range;

/// Pairs handled together by the inner loops: one AVX2 register of `f64`.
pub(crate) const LANES: usize = 4;

pub(crate) use lanes::{F64x4, Real};

/// Smallest and largest number of rows (and columns) of a block of the pair sweep. Small
/// blocks give a problem of a few hundred landmarks tens of tiles to share between threads;
/// large blocks make fewer partial sums to store and reduce when there are thousands.
const BLOCK_RANGE: (usize, usize) = (64, 256);

/// Gaussian kernel of width `σ` (same unit as the coordinates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianKernel {
    sigma: f64,
    /// `1 / (2σ²)`.
    half_inv_sigma2: f64,
}

impl GaussianKernel {
    /// A kernel of width `sigma > 0`.
    pub fn new(sigma: f64) -> Result<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::InvalidParameter(format!(
                "kernel width sigma must be a positive number, got {sigma}"
            )));
        }
        Ok(Self {
            sigma,
            half_inv_sigma2: 0.5 / (sigma * sigma),
        })
    }

    /// The width `σ`.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// `η` as a function of the squared distance: `exp(−r² / (2σ²))`.
    #[inline(always)]
    pub fn of_squared_distance(&self, r2: f64) -> f64 {
        exp_neg(r2 * self.half_inv_sigma2)
    }

    /// The kernel's length unit `ℓ = σ√2`: `η(r) = exp(−(r/ℓ)²)`.
    pub(crate) fn length_unit(&self) -> f64 {
        self.sigma * std::f64::consts::SQRT_2
    }
}

/// `exp(x)` for `x ≤ 0`, branch-free so that the compiler vectorises the loops that call it.
///
/// No maintained crate offers a vectorisable f64 exponential of this accuracy, so it is written
/// here: Cody–Waite reduction `x = k·ln2 + r`, `|r| ≤ ln2/2`, a degree-11 polynomial for
/// `e^r` (error below 2e-17 relative), and `2^k` built from the exponent bits. The result
/// agrees with `f64::exp` to a few ulp (tested) down to the smallest normal number; below
/// `x ≈ −708.7` (results under `2^−1022.5`) it is 0, and NaN stays NaN.
#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    exp_neg(-x)
}

/// `e^−y` for `y ≥ 0`, lane by lane: [`exp_nonpositive`] of `−y`, with the same bits.
#[inline(always)]
pub(crate) fn exp_neg<V: Real>(y: V) -> V {
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const INV_LN2: f64 = std::f64::consts::LOG2_E;
    // −709 = −1022.88·ln2 rounds to k = −1023, for which the scale built below is exactly 0:
    // clamping there makes every smaller exponent give 0 without a data-dependent branch or
    // select on the result (which the compiler would turn into a branch around the polynomial).
    const MAX_Y: f64 = 709.0;
    // Adding 1.5·2⁵² rounds to the nearest integer and leaves it in the low mantissa bits,
    // without a rounding instruction or a float-to-int conversion (both block vectorisation).
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let c = V::splat;
    let yc = y.at_most(MAX_Y);
    // k = round(−y / ln2), r = −y − k·ln2.
    let shifted = yc.mul_add(c(-INV_LN2), c(SHIFTER));
    let kf = shifted - c(SHIFTER);
    let r = kf.neg_mul_add(c(LN2_LO), kf.neg_mul_sub(c(LN2_HI), yc));
    let p = exp_polynomial(r);
    // The low 12 bits of `shifted`'s representation hold k (mod 2¹²), so those of
    // `bits + 1023` hold the biased exponent k + 1023 of 2^k: in [1, 1023] for k ∈ [−1022, 0],
    // and 0 (the scale is +0) for k = −1023.
    p * shifted.exponent_scale()
}

/// `e^r` for `|r| ≤ ln2/2` by a degree-11 polynomial, fitted to `e^r` on that interval in
/// Chebyshev nodes (near-minimax, computed with 50-digit arithmetic): relative error 1.7e-17
/// with the coefficients rounded to `f64`, below a fifth of an ulp.
///
/// Evaluated by Estrin's scheme: pairs `c_{2m} + c_{2m+1} r`, then pairs of pairs with `r²`,
/// then a polynomial in `r⁴`. The chain of dependent operations is 4 multiply-adds long instead
/// of Horner's 11, so that the CPU does not wait on each one in turn.
#[inline(always)]
fn exp_polynomial<V: Real>(r: V) -> V {
    const C: [f64; 12] = [
        1.0,
        1.0,
        0.500_000_000_000_001_9,
        0.166_666_666_666_666_8,
        0.041_666_666_666_488_1,
        0.008_333_333_333_319_601,
        0.001_388_888_895_231_477_5,
        0.000_198_412_698_900_471_13,
        2.480_148_548_232_849_4e-5,
        2.755_724_091_857_897e-6,
        2.763_263_963_904_103e-7,
        2.511_003_760_596_377_7e-8,
    ];
    let pair = |m: usize| r.mul_add(V::splat(C[2 * m + 1]), V::splat(C[2 * m]));
    let r2 = r * r;
    let r4 = r2 * r2;
    let quad = |m: usize| pair(2 * m + 1).mul_add(r2, pair(2 * m));
    quad(2).mul_add(r4, quad(1)).mul_add(r4, quad(0))
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
        Self {
            x: vec![0.0; n],
            y: vec![0.0; n],
            z: vec![0.0; n],
        }
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

/// The terms `t_c(i, j)`, `c < C`, of pair sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over points
/// that carry `F` numbers each, the first three being the coordinates of the point.
pub(crate) trait PairTerms<const F: usize, const C: usize>: Sync {
    /// For the pairs (i, j) with `j` the [`LANES`] points of `chunk` (number `f` of the point
    /// in lane `l` at `chunk[LANES·f + l]`), given the numbers of point `i` (`row`), `K_ij`
    /// (`kernel`) and `d = (q_i − q_j)/ℓ` (see [`PairSweep::length_unit`]): adds `K_ij t_c(i, j)` to `row_sums[c]` and
    /// `K_ij t_c(j, i)` to the sums of the points `j`, `col_sums[LANES·c + l]`.
    fn accumulate<V: F64x4>(
        &self,
        row: &[f64; F],
        chunk: &[f64],
        kernel: V,
        d: &[V; 3],
        row_sums: &mut [V; C],
        col_sums: &mut [f64],
    );
}

/// Pair sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)`, `c < C`, over points carrying `F` numbers
/// each, with one kernel evaluation per unordered pair (see the module documentation).
///
/// Points, partial sums and sums are stored in chunks of [`LANES`] points, field after field
/// (number `f` of point `i` at `(i / LANES)·LANES·F + LANES·f + i % LANES`), so that the inner
/// loops read and write whole registers from contiguous memory. The point count is padded to
/// a multiple of [`LANES`] with points whose numbers are all 0: the terms must vanish there
/// (they do for zero controls and adjoints).
#[derive(Clone, Debug)]
pub(crate) struct PairSweep<const F: usize, const C: usize> {
    tiling: Tiling,
    /// The kernel's length unit `ℓ`: the sweep works on the coordinates `q/ℓ`.
    unit: f64,
    points: Vec<f64>,
    /// Per tile, the partial sums of its rows, then those of its columns (`C·block` each).
    partials: Vec<f64>,
    sums: Vec<f64>,
}

impl<const F: usize, const C: usize> PairSweep<F, C> {
    /// A sweep of `kernel` over `landmarks` points, all zero.
    pub(crate) fn new(kernel: &GaussianKernel, landmarks: usize) -> Self {
        let tiling = Tiling::new(landmarks);
        Self {
            unit: kernel.length_unit(),
            points: vec![0.0; tiling.padded * F],
            partials: vec![0.0; tiling.tiles.len() * 2 * C * tiling.block],
            sums: vec![0.0; tiling.padded * C],
            tiling,
        }
    }

    /// Sets the numbers of point `i`: its coordinates, then `F − 3` numbers for the terms.
    #[inline]
    pub(crate) fn set_point(&mut self, i: usize, numbers: [f64; F]) {
        let base = i / LANES * LANES * F + i % LANES;
        for (f, x) in numbers.into_iter().enumerate() {
            self.points[base + LANES * f] = if f < 3 { x / self.unit } else { x };
        }
    }

    /// The kernel's length unit `ℓ = σ√2`, in which the differences `d` given to the terms are
    /// expressed.
    pub(crate) fn length_unit(&self) -> f64 {
        self.unit
    }

    /// `[S_0(i), …, S_{C−1}(i)]` as of the last [`PairSweep::run`].
    #[inline]
    pub(crate) fn sums(&self, i: usize) -> [f64; C] {
        let base = i / LANES * LANES * C + i % LANES;
        std::array::from_fn(|c| self.sums[base + LANES * c])
    }

    /// Computes the sums for the current points: the tiles in parallel, then for each block of
    /// rows the partial sums of its tiles in a fixed order.
    pub(crate) fn run<T: PairTerms<F, C>>(&mut self, terms: &T) {
        let Self {
            tiling,
            points,
            partials,
            sums,
            ..
        } = self;
        let points = &points[..];
        let part_len = C * tiling.block;
        partials
            .par_chunks_mut(2 * part_len)
            .zip(&tiling.tiles)
            .for_each(|(buf, &(bi, bj))| {
                let tile = Tile {
                    rows: tiling.range(bi),
                    cols: tiling.range(bj),
                };
                sweep_tile(points, terms, &tile, buf);
            });
        let partials = &partials[..];
        // Blocks per reduction task: enough additions to be worth a task of its own.
        let min_blocks = (1 << 16) / (part_len * tiling.blocks).max(1);
        sums.par_chunks_mut(part_len)
            .enumerate()
            .with_min_len(min_blocks.max(1))
            .for_each(|(bi, block_sums)| {
                block_sums.fill(0.0);
                for bj in 0..tiling.blocks {
                    let t = tiling.tile_index(bi.min(bj), bi.max(bj));
                    let (row_part, col_part) =
                        partials[2 * t * part_len..2 * (t + 1) * part_len].split_at(part_len);
                    if bj >= bi {
                        add_assign(block_sums, row_part);
                    }
                    if bj <= bi {
                        add_assign(block_sums, col_part);
                    }
                }
            });
    }
}

/// `sums[n] += part[n]` for every `n < sums.len()`.
fn add_assign(sums: &mut [f64], part: &[f64]) {
    sums.iter_mut().zip(part).for_each(|(s, p)| *s += p);
}

/// The cut of the padded index range into blocks (the last one shorter), and the tiles (I, J),
/// I ≤ J, row-major.
#[derive(Clone, Debug)]
struct Tiling {
    padded: usize,
    /// Rows of a block: a power of two in [`BLOCK_RANGE`], about a sixteenth of the points. It
    /// depends on the number of points only, so that the order of the sums does not depend on
    /// the number of threads.
    block: usize,
    blocks: usize,
    tiles: Vec<(usize, usize)>,
}

impl Tiling {
    fn new(landmarks: usize) -> Self {
        let padded = landmarks.div_ceil(LANES) * LANES;
        let block = (padded / 16)
            .next_power_of_two()
            .clamp(BLOCK_RANGE.0, BLOCK_RANGE.1);
        let blocks = padded.div_ceil(block);
        let tiles = (0..blocks)
            .flat_map(|bi| (bi..blocks).map(move |bj| (bi, bj)))
            .collect();
        Self {
            padded,
            block,
            blocks,
            tiles,
        }
    }

    /// Indices of block `b`.
    fn range(&self, b: usize) -> Range<usize> {
        b * self.block..((b + 1) * self.block).min(self.padded)
    }

    /// Position of tile (bi, bj), bi ≤ bj, in the row-major list: `bi·blocks − bi(bi+1)/2 + bj`.
    fn tile_index(&self, bi: usize, bj: usize) -> usize {
        bi * self.blocks - bi * (bi + 1) / 2 + bj
    }
}

/// Rows I and columns J of one tile; both start at a multiple of [`LANES`].
struct Tile {
    rows: Range<usize>,
    cols: Range<usize>,
}

/// The partial sums of one tile into `buf` (see [`PairSweep::partials`]), with the fastest
/// code the CPU supports.
fn sweep_tile<const F: usize, const C: usize, T: PairTerms<F, C>>(
    points: &[f64],
    terms: &T,
    tile: &Tile,
    buf: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the running CPU supports AVX2 and FMA, checked just above.
        return unsafe { sweep_tile_avx2_fma(points, terms, tile, buf) };
    }
    sweep_tile_with::<F, C, T, lanes::Portable>(points, terms, tile, buf)
}

/// [`sweep_tile_with`] on AVX2 registers with fused multiply-adds.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sweep_tile_avx2_fma<const F: usize, const C: usize, T: PairTerms<F, C>>(
    points: &[f64],
    terms: &T,
    tile: &Tile,
    buf: &mut [f64],
) {
    sweep_tile_with::<F, C, T, lanes::Avx2Fma>(points, terms, tile, buf)
}

/// One tile with the lanes `V`, by the body compiled for its shape: diagonal or not.
#[inline(always)]
fn sweep_tile_with<const F: usize, const C: usize, T: PairTerms<F, C>, V: F64x4>(
    points: &[f64],
    terms: &T,
    tile: &Tile,
    buf: &mut [f64],
) {
    if tile.rows.start == tile.cols.start {
        sweep_tile_body::<F, C, T, V, true>(points, terms, tile, buf)
    } else {
        sweep_tile_body::<F, C, T, V, false>(points, terms, tile, buf)
    }
}

/// One tile: for each row i, the pairs (i, j) with j ∈ J (j > i on a `DIAGONAL` tile), LANES at
/// a time. Row sums are kept in LANES accumulators per sum and added in a fixed order; column
/// sums are accumulated in `buf` row after row.
#[inline(always)]
fn sweep_tile_body<
    const F: usize,
    const C: usize,
    T: PairTerms<F, C>,
    V: F64x4,
    const DIAGONAL: bool,
>(
    points: &[f64],
    terms: &T,
    tile: &Tile,
    buf: &mut [f64],
) {
    let (row_sums, col_sums) = buf.split_at_mut(buf.len() / 2);
    col_sums.fill(0.0);
    let columns = &points[tile.cols.start * F..tile.cols.end * F];
    for (r, i) in tile.rows.clone().enumerate() {
        let base = i / LANES * LANES * F + i % LANES;
        let mut row = [0.0; F];
        for (f, x) in row.iter_mut().enumerate() {
            *x = points[base + LANES * f];
        }
        let qi = [V::splat(row[0]), V::splat(row[1]), V::splat(row[2])];
        let mut acc = [V::splat(0.0); C];
        // On a diagonal tile, start at the chunk holding i + 1 and mask its lanes j ≤ i.
        let first = if DIAGONAL {
            (i + 1 - tile.cols.start) / LANES
        } else {
            0
        };
        let chunks = columns[first * LANES * F..].chunks_exact(LANES * F);
        let sums = col_sums[first * LANES * C..].chunks_exact_mut(LANES * C);
        for (n, (chunk, sums)) in (first..).zip(chunks.zip(sums)) {
            let qj = [
                V::load(chunk),
                V::load(&chunk[LANES..]),
                V::load(&chunk[2 * LANES..]),
            ];
            let d = [qi[0] - qj[0], qi[1] - qj[1], qi[2] - qj[2]];
            let mut kij = exp_neg(d[2].mul_add(d[2], d[1].mul_add(d[1], d[0] * d[0])));
            let j = tile.cols.start + n * LANES;
            if DIAGONAL && j <= i {
                let mut k = kij.to_array();
                for (l, k) in k.iter_mut().enumerate() {
                    if j + l <= i {
                        *k = 0.0;
                    }
                }
                kij = V::from_array(k);
            }
            terms.accumulate(&row, chunk, kij, &d, &mut acc, sums);
        }
        for (c, a) in acc.iter().enumerate() {
            row_sums[r / LANES * LANES * C + LANES * c + r % LANES] = a.sum();
        }
    }
}

/// SIMD lanes: lane-wise IEEE arithmetic on [`LANES`] numbers at once, portable or on AVX2.
mod lanes {
    use std::ops::{Mul, Sub};

    /// Lane-wise IEEE arithmetic on `f64`: a scalar or a SIMD vector. No implementation uses
    /// fused multiply-adds, so all give the same bits.
    pub(crate) trait Real: Copy + Sub<Output = Self> + Mul<Output = Self> {
        /// `x` in every lane.
        fn splat(x: f64) -> Self;
        /// `hi` in the lanes where `self > hi`, else `self` (NaN stays NaN).
        fn at_most(self, hi: f64) -> Self;
        /// Per lane, with `b` the bits of the lane: `f64::from_bits((b + 1023) << 52)`.
        fn exponent_scale(self) -> Self;
        /// `self·a + b`, rounded once where the implementation has fused multiply-adds.
        fn mul_add(self, a: Self, b: Self) -> Self;
        /// `b − self·a`, rounded once where the implementation has fused multiply-adds.
        fn neg_mul_add(self, a: Self, b: Self) -> Self;
        /// `−self·a − b`, rounded once where the implementation has fused multiply-adds.
        fn neg_mul_sub(self, a: Self, b: Self) -> Self;
    }

    /// [`super::LANES`] lanes of `f64`.
    pub(crate) trait F64x4: Real {
        /// `v[0 … 3]`.
        fn load(v: &[f64]) -> Self;
        /// `v[0 … 3] = self`.
        fn store(self, v: &mut [f64]);

        /// The lanes as an array.
        #[inline(always)]
        fn to_array(self) -> [f64; 4] {
            let mut a = [0.0; 4];
            self.store(&mut a);
            a
        }

        /// Lanes from an array.
        #[inline(always)]
        fn from_array(a: [f64; 4]) -> Self {
            Self::load(&a)
        }

        /// `v[0 … 3] += self·a` (see [`Real::mul_add`]).
        #[inline(always)]
        fn mul_add_to(self, a: Self, v: &mut [f64]) {
            self.mul_add(a, Self::load(v)).store(v);
        }

        /// `v[0 … 3] −= self·a` (see [`Real::neg_mul_add`]).
        #[inline(always)]
        fn neg_mul_add_to(self, a: Self, v: &mut [f64]) {
            self.neg_mul_add(a, Self::load(v)).store(v);
        }

        /// The sum of the lanes in a fixed order: `(l0 + l1) + (l2 + l3)`.
        #[inline(always)]
        fn sum(self) -> f64 {
            let l = self.to_array();
            (l[0] + l[1]) + (l[2] + l[3])
        }
    }

    impl Real for f64 {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            x
        }

        #[inline(always)]
        fn at_most(self, hi: f64) -> Self {
            if self > hi {
                hi
            } else {
                self
            }
        }

        #[inline(always)]
        fn exponent_scale(self) -> Self {
            f64::from_bits(self.to_bits().wrapping_add(1023) << 52)
        }

        /// Two roundings: `f64::mul_add` would call a slow software routine on CPUs without FMA.
        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            self * a + b
        }

        #[inline(always)]
        fn neg_mul_add(self, a: Self, b: Self) -> Self {
            b - self * a
        }

        #[inline(always)]
        fn neg_mul_sub(self, a: Self, b: Self) -> Self {
            -(self * a) - b
        }
    }

    /// Four lanes in an array, for any CPU.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub(crate) struct Portable([f64; 4]);

    impl Portable {
        /// `f` lane by lane.
        #[inline(always)]
        fn map(self, f: impl Fn(f64) -> f64) -> Self {
            Self(self.0.map(f))
        }

        /// `f` lane by lane on two operands.
        #[inline(always)]
        fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
            let mut out = self.0;
            for (x, y) in out.iter_mut().zip(other.0) {
                *x = f(*x, y);
            }
            Self(out)
        }
    }

    impl Sub for Portable {
        type Output = Self;
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            self.zip(other, |x, y| x - y)
        }
    }

    impl Mul for Portable {
        type Output = Self;
        #[inline(always)]
        fn mul(self, other: Self) -> Self {
            self.zip(other, |x, y| x * y)
        }
    }

    impl Real for Portable {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            Self([x; 4])
        }

        #[inline(always)]
        fn at_most(self, hi: f64) -> Self {
            self.map(|x| x.at_most(hi))
        }

        #[inline(always)]
        fn exponent_scale(self) -> Self {
            self.map(f64::exponent_scale)
        }

        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            Self(std::array::from_fn(|l| {
                Real::mul_add(self.0[l], a.0[l], b.0[l])
            }))
        }

        #[inline(always)]
        fn neg_mul_add(self, a: Self, b: Self) -> Self {
            Self(std::array::from_fn(|l| {
                Real::neg_mul_add(self.0[l], a.0[l], b.0[l])
            }))
        }

        #[inline(always)]
        fn neg_mul_sub(self, a: Self, b: Self) -> Self {
            Self(std::array::from_fn(|l| {
                Real::neg_mul_sub(self.0[l], a.0[l], b.0[l])
            }))
        }
    }

    impl F64x4 for Portable {
        #[inline(always)]
        fn load(v: &[f64]) -> Self {
            let mut a = [0.0; 4];
            a.copy_from_slice(&v[..4]);
            Self(a)
        }

        #[inline(always)]
        fn store(self, v: &mut [f64]) {
            v[..4].copy_from_slice(&self.0);
        }
    }

    #[cfg(target_arch = "x86_64")]
    pub(crate) use avx2::Avx2Fma;

    #[cfg(target_arch = "x86_64")]
    mod avx2 {
        use super::{F64x4, Real};
        use std::arch::x86_64::*;
        use std::ops::{Mul, Sub};

        /// Four lanes in an AVX register, with fused multiply-adds.
        ///
        /// Invariant: values of this type exist only on CPUs with AVX2 and FMA. The crate
        /// creates them only in code reached through `sweep_tile_avx2_fma`, after the run-time
        /// feature check; every `unsafe` block below relies on this.
        #[derive(Clone, Copy, Debug)]
        pub(crate) struct Avx2Fma(__m256d);

        impl Sub for Avx2Fma {
            type Output = Self;
            #[inline(always)]
            fn sub(self, other: Self) -> Self {
                // SAFETY: AVX2 is available (type invariant).
                Self(unsafe { _mm256_sub_pd(self.0, other.0) })
            }
        }

        impl Mul for Avx2Fma {
            type Output = Self;
            #[inline(always)]
            fn mul(self, other: Self) -> Self {
                // SAFETY: AVX2 is available (type invariant).
                Self(unsafe { _mm256_mul_pd(self.0, other.0) })
            }
        }

        impl Real for Avx2Fma {
            #[inline(always)]
            fn splat(x: f64) -> Self {
                // SAFETY: AVX2 is available (type invariant).
                Self(unsafe { _mm256_set1_pd(x) })
            }

            #[inline(always)]
            fn at_most(self, hi: f64) -> Self {
                // `min_pd(a, b)` returns b where a < b fails, which includes a NaN b.
                // SAFETY: AVX2 is available (type invariant).
                Self(unsafe { _mm256_min_pd(_mm256_set1_pd(hi), self.0) })
            }

            #[inline(always)]
            fn exponent_scale(self) -> Self {
                // SAFETY: AVX2 is available (type invariant).
                unsafe {
                    let bits =
                        _mm256_add_epi64(_mm256_castpd_si256(self.0), _mm256_set1_epi64x(1023));
                    Self(_mm256_castsi256_pd(_mm256_slli_epi64::<52>(bits)))
                }
            }

            #[inline(always)]
            fn mul_add(self, a: Self, b: Self) -> Self {
                // SAFETY: FMA is available (type invariant).
                Self(unsafe { _mm256_fmadd_pd(self.0, a.0, b.0) })
            }

            #[inline(always)]
            fn neg_mul_add(self, a: Self, b: Self) -> Self {
                // SAFETY: FMA is available (type invariant).
                Self(unsafe { _mm256_fnmadd_pd(self.0, a.0, b.0) })
            }

            #[inline(always)]
            fn neg_mul_sub(self, a: Self, b: Self) -> Self {
                // SAFETY: FMA is available (type invariant).
                Self(unsafe { _mm256_fnmsub_pd(self.0, a.0, b.0) })
            }
        }

        impl F64x4 for Avx2Fma {
            #[inline(always)]
            fn load(v: &[f64]) -> Self {
                let v = &v[..4];
                // SAFETY: `v` holds 4 numbers; AVX2 is available (type invariant).
                Self(unsafe { _mm256_loadu_pd(v.as_ptr()) })
            }

            #[inline(always)]
            fn store(self, v: &mut [f64]) {
                let v = &mut v[..4];
                // SAFETY: `v` holds 4 numbers; AVX2 is available (type invariant).
                unsafe { _mm256_storeu_pd(v.as_mut_ptr(), self.0) }
            }
        }
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
        self.values
            .par_chunks_mut(k.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                row[i] = 1.0;
                let (xi, yi, zi) = (q.x[i], q.y[i], q.z[i]);
                let upper = i + 1..k;
                for (((kij, xj), yj), zj) in row[upper.clone()]
                    .iter_mut()
                    .zip(&q.x[upper.clone()])
                    .zip(&q.y[upper.clone()])
                    .zip(&q.z[upper])
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
