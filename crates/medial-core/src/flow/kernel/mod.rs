//! The Gaussian kernel `η(r) = exp(−r² / (2σ²))` and its sums over pairs of landmarks.
//!
//! `PairSweep` computes sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over all pairs, with
//! `K_ij = η(|q_i − q_j|)`, for pair terms `t_c` supplied by the caller (`PairTerms`). The
//! index range is cut into blocks; every tile (I, J), I ≤ J, of blocks evaluates the kernel once
//! per unordered pair {i, j} and accumulates both the terms of its rows i ∈ I and those of its
//! columns j ∈ J in a buffer of its own. Tiles run in parallel (rayon); the buffers are then
//! reduced in a fixed order. Every number is thus computed by the same operations in the same
//! order whatever the thread count, and results are bit-identical.
//!
//! The inner loops handle `LANES` pairs at once, with the exponential written out as a
//! polynomial so that it runs in SIMD registers too. They are compiled twice, for any CPU and
//! for AVX2 with fused multiply-adds, chosen at run time once per tile. The two give results
//! that differ in the last bits (fused or separate roundings), so results may differ between
//! CPUs, but never between thread counts on one machine.
//!
//! Cost (AMD EPYC at 2.45 GHz, AVX2, one thread, 500 – 2,000 points): about 2.2 ns per pair
//! for the velocity terms of the flow and 3.4 ns for the adjoint terms.

use crate::{Error, Result};
use rayon::prelude::*;
use std::ops::Range;

/// Pairs handled together by the inner loops: one AVX2 register of `f64`.
pub(crate) const LANES: usize = 4;

pub(crate) use lanes::{F64x4, Real};

/// Where the padding points of a [`PairSweep`] sit: far enough for the kernel to be exactly 0
/// for any width up to 1e40, near enough for `|d|²` and its products with the terms to be
/// finite.
const PADDING_DISTANCE: f64 = 1e100;

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
        exp_neg_scaled(r2, self.half_inv_sigma2)
    }
}

/// `exp(x)` for `x ≤ 0`, branch-free so that it runs lane by lane in SIMD registers too.
///
/// No maintained crate offers a vectorisable f64 exponential of this accuracy, so it is written
/// here: Cody–Waite reduction `x = k·ln2 + r`, `|r| ≤ ln2/2`, a degree-11 polynomial for
/// `e^r` (error below 2e-17 relative), and `2^k` built from the exponent bits. The result
/// agrees with `f64::exp` to a few ulp (tested) down to the smallest normal number; below
/// `x ≈ −708.7` (results under `2^−1022.5`) it is 0, and NaN stays NaN.
#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    exp_neg_scaled(-x, 1.0)
}

/// `e^−sy` for `y ≥ 0` and a scale `s > 0`, lane by lane, with the accuracy of
/// [`exp_nonpositive`]: `sy` is rounded once, as the argument of the exponential.
///
/// `sy` is needed only for the reduced argument `r`, while `k` comes from `y` times the merged
/// constant `−s/ln2`: the scaling is off the chain of dependent operations.
#[inline(always)]
pub(crate) fn exp_neg_scaled<V: Real>(y: V, scale: f64) -> V {
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const INV_LN2: f64 = std::f64::consts::LOG2_E;
    // −709 = −1022.88·ln2 rounds to k = −1023, for which the scale built below is exactly 0:
    // clamping there makes every smaller exponent give 0 without a data-dependent branch or
    // select on the result (which the compiler would turn into a branch around the polynomial).
    const MAX_SY: f64 = 709.0;
    // Adding 1.5·2⁵² rounds to the nearest integer and leaves it in the low mantissa bits,
    // without a rounding instruction or a float-to-int conversion (both block vectorisation).
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let c = V::splat;
    let yc = y.at_most(MAX_SY / scale);
    // k = round(−sy / ln2) (to within one at a tie, which |r| ≤ ln2/2 + ε tolerates),
    // r = −sy − k·ln2.
    let shifted = yc.mul_add(c(-scale * INV_LN2), c(SHIFTER));
    let kf = shifted - c(SHIFTER);
    let r = kf.neg_mul_add(c(LN2_LO), kf.neg_mul_sub(c(LN2_HI), yc * c(scale)));
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

/// The terms `t_c(i, j)`, `c < C`, of pair sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over points
/// that carry `F` numbers each, the first three being the coordinates of the point.
pub(crate) trait PairTerms<const F: usize, const C: usize>: Sync {
    /// For the pairs (i, j) with `j` the [`LANES`] points of `chunk` (number `f` of the point
    /// in lane `l` at `chunk[LANES·f + l]`), given the numbers of point `i` (`row`), `K_ij`
    /// (`kernel`) and `d = q_i − q_j`: adds `K_ij t_c(i, j)` to `row_sums[c]` and
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
/// (number `f` of point `i` at `⌊i/LANES⌋·LANES·F + LANES·f + i mod LANES`), so that the inner
/// loops read and write whole registers from contiguous memory. The point count is padded to
/// a multiple of [`LANES`] with points [`PADDING_DISTANCE`] away, whose kernel values with the
/// others are exactly 0, and whose other numbers are 0.
#[derive(Clone, Debug)]
pub(crate) struct PairSweep<const F: usize, const C: usize> {
    tiling: Tiling,
    /// `1/(2σ²)`.
    scale: f64,
    points: Vec<f64>,
    /// Per tile, the partial sums of its rows, then those of its columns (`C·block` each).
    partials: Vec<f64>,
    sums: Vec<f64>,
}

impl<const F: usize, const C: usize> PairSweep<F, C> {
    /// A sweep of `kernel` over `landmarks` points, all at the origin with zero numbers.
    pub(crate) fn new(kernel: &GaussianKernel, landmarks: usize) -> Self {
        let tiling = Tiling::new(landmarks);
        let mut points = vec![0.0; tiling.padded * F];
        for i in landmarks..tiling.padded {
            points[chunked(i, F)] = PADDING_DISTANCE;
        }
        Self {
            scale: kernel.half_inv_sigma2,
            points,
            partials: vec![0.0; tiling.tiles.len() * 2 * C * tiling.block],
            sums: vec![0.0; tiling.padded * C],
            tiling,
        }
    }

    /// Sets the numbers of point `i`: its coordinates, then `F − 3` numbers for the terms.
    #[inline]
    pub(crate) fn set_point(&mut self, i: usize, numbers: [f64; F]) {
        let base = chunked(i, F);
        for (f, x) in numbers.into_iter().enumerate() {
            self.points[base + LANES * f] = x;
        }
    }

    /// `[S_0(i), …, S_{C−1}(i)]` as of the last [`PairSweep::run`].
    #[inline]
    pub(crate) fn sums(&self, i: usize) -> [f64; C] {
        let base = chunked(i, C);
        std::array::from_fn(|c| self.sums[base + LANES * c])
    }

    /// Computes the sums for the current points: the tiles in parallel, then for each block of
    /// rows the partial sums of its tiles in a fixed order.
    pub(crate) fn run<T: PairTerms<F, C>>(&mut self, terms: &T) {
        self.run_with(terms, Isa::best());
    }

    /// [`PairSweep::run`] with the inner loops `isa` (or portable ones if the CPU lacks it).
    fn run_with<T: PairTerms<F, C>>(&mut self, terms: &T, isa: Isa) {
        self.sweep_tiles(terms, isa);
        self.reduce();
    }

    /// The partial sums of every tile, in parallel.
    fn sweep_tiles<T: PairTerms<F, C>>(&mut self, terms: &T, isa: Isa) {
        let Self {
            tiling,
            scale,
            points,
            partials,
            ..
        } = self;
        let (points, scale) = (&points[..], *scale);
        partials
            .par_chunks_mut(2 * C * tiling.block)
            .zip(&tiling.tiles)
            .for_each(|(buf, &(bi, bj))| {
                let tile = Tile {
                    rows: tiling.range(bi),
                    cols: tiling.range(bj),
                    scale,
                };
                sweep_tile(isa, points, terms, &tile, buf);
            });
    }

    /// `S(i)` for the rows of each block: the partial sums from the blocks `J = 0, 1, …` in
    /// that order (row sums of tile (I, J) for J > I, column sums of tile (J, I) for J < I,
    /// both for J = I), in parallel over blocks when there is enough work.
    fn reduce(&mut self) {
        let Self {
            tiling,
            partials,
            sums,
            ..
        } = self;
        let part_len = C * tiling.block;
        // Blocks per task: enough additions to be worth a task of its own.
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

/// Where number 0 of point `i` sits in an array of points carrying `fields` numbers each,
/// stored in chunks of [`LANES`] points field after field; number `f` is `LANES·f` further.
#[inline(always)]
fn chunked(i: usize, fields: usize) -> usize {
    i / LANES * LANES * fields + i % LANES
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

/// One tile: rows I and columns J, both starting at a multiple of [`LANES`], and the kernel's
/// `1/(2σ²)`.
struct Tile {
    rows: Range<usize>,
    cols: Range<usize>,
    scale: f64,
}

/// The implementations of the inner loops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    /// Plain Rust on arrays of lanes, for any CPU.
    Portable,
    /// AVX2 registers and fused multiply-adds.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    Avx2Fma,
}

impl Isa {
    /// The fastest implementation the running CPU supports.
    fn best() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Isa::Avx2Fma;
        }
        Isa::Portable
    }
}

/// The partial sums of one tile into `buf` (see [`PairSweep::partials`]) with the inner loops
/// `isa`, or portable ones if the CPU lacks it.
fn sweep_tile<const F: usize, const C: usize, T: PairTerms<F, C>>(
    isa: Isa,
    points: &[f64],
    terms: &T,
    tile: &Tile,
    buf: &mut [f64],
) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2Fma if Isa::best() == Isa::Avx2Fma => {
            // SAFETY: the running CPU supports AVX2 and FMA, checked just above.
            unsafe { sweep_tile_avx2_fma(points, terms, tile, buf) }
        }
        _ => sweep_tile_with::<F, C, T, lanes::Portable>(points, terms, tile, buf),
    }
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
        let base = chunked(i, F);
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
            let r2 = d[2].mul_add(d[2], d[1].mul_add(d[1], d[0] * d[0]));
            let mut kij = exp_neg_scaled(r2, tile.scale);
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
            row_sums[chunked(r, C) + LANES * c] = a.sum();
        }
    }
}

/// SIMD lanes: lane-wise IEEE arithmetic on [`LANES`] numbers at once, portable or on AVX2.
mod lanes {
    use std::ops::{Mul, Sub};

    /// Lane-wise IEEE arithmetic on `f64`: a scalar or a SIMD vector. The multiply-adds are
    /// rounded once by implementations with fused multiply-adds and twice by the others; each
    /// implementation always gives the same bits for the same operands.
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
            self.zip3(other, other, |x, y, _| f(x, y))
        }

        /// `f` lane by lane on three operands.
        #[inline(always)]
        fn zip3(self, a: Self, b: Self, f: impl Fn(f64, f64, f64) -> f64) -> Self {
            let mut out = self.0;
            for (l, x) in out.iter_mut().enumerate() {
                *x = f(*x, a.0[l], b.0[l]);
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
            self.zip3(a, b, <f64 as Real>::mul_add)
        }

        #[inline(always)]
        fn neg_mul_add(self, a: Self, b: Self) -> Self {
            self.zip3(a, b, <f64 as Real>::neg_mul_add)
        }

        #[inline(always)]
        fn neg_mul_sub(self, a: Self, b: Self) -> Self {
            self.zip3(a, b, <f64 as Real>::neg_mul_sub)
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
        /// creates them only in code reached through `sweep_tile_avx2_fma` (and in tests),
        /// after the run-time feature check; every `unsafe` block below relies on this.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;
    use proptest::prelude::*;

    fn ulps(a: f64, b: f64) -> f64 {
        ((a - b) / b.abs().max(f64::MIN_POSITIVE)).abs() / f64::EPSILON
    }

    /// Arguments `0 … −700`, denser near 0.
    fn exponents() -> impl Iterator<Item = f64> {
        (0..200_000).map(|i| -700.0 * (i as f64 / 200_000.0).powi(2))
    }

    #[test]
    fn exp_agrees_with_std_to_a_few_ulp() {
        let worst = exponents().fold(0.0f64, |w, x| w.max(ulps(exp_nonpositive(x), x.exp())));
        assert!(worst < 4.0, "worst error {worst} ulp");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-800.0), 0.0);
        assert_eq!(exp_nonpositive(f64::NEG_INFINITY), 0.0);
        assert!(exp_nonpositive(f64::NAN).is_nan());
        // Down to the smallest normal number: a few ulp (or units of the subnormals)…
        for i in 0..=700 {
            let x = -708.0 - i as f64 * 1e-3;
            let (e, exact) = (exp_nonpositive(x), x.exp());
            let tol = 4.0 * f64::EPSILON * exact + 4.0 * f64::from_bits(1);
            assert!((e - exact).abs() <= tol, "exp({x}) = {e}, not {exact}");
        }
        // … then exactly 0.
        for x in [-708.8, -709.0, -745.2, -1e300] {
            assert_eq!(exp_nonpositive(x), 0.0);
        }
    }

    /// The worst error in ulp of [`exp_neg_scaled`] on the lanes `V` over [`exponents`].
    fn worst_lane_error<V: F64x4>() -> f64 {
        exponents().fold(0.0f64, |w, x| {
            let e = exp_neg_scaled(V::splat(-x), 1.0).to_array();
            e.iter().fold(w, |w, &e| w.max(ulps(e, x.exp())))
        })
    }

    #[test]
    fn exp_lanes_agree_with_std_to_a_few_ulp() {
        let worst = worst_lane_error::<lanes::Portable>();
        assert!(worst < 4.0, "portable: worst error {worst} ulp");
        #[cfg(target_arch = "x86_64")]
        if Isa::best() == Isa::Avx2Fma {
            // The CPU has AVX2 and FMA, as `Avx2Fma` values require.
            let worst = worst_lane_error::<lanes::Avx2Fma>();
            assert!(worst < 4.0, "AVX2: worst error {worst} ulp");
        }
    }

    /// Test terms on points `(q, w)`: `t_0(i, j) = w_j` and `t_1(i, j) = e·(q_i − q_j)`,
    /// `e = (1, 2, −½)`: a weighted and an antisymmetric sum.
    struct TestTerms;

    impl TestTerms {
        /// `e·d` in every lane.
        fn e_dot<V: F64x4>(d: &[V; 3]) -> V {
            d[2].mul_add(V::splat(-0.5), d[1].mul_add(V::splat(2.0), d[0]))
        }
    }

    impl PairTerms<4, 2> for TestTerms {
        fn accumulate<V: F64x4>(
            &self,
            row: &[f64; 4],
            chunk: &[f64],
            kernel: V,
            d: &[V; 3],
            row_sums: &mut [V; 2],
            col_sums: &mut [f64],
        ) {
            row_sums[0] = kernel.mul_add(V::load(&chunk[3 * LANES..]), row_sums[0]);
            kernel.mul_add_to(V::splat(row[3]), col_sums);
            let e_dot_d = Self::e_dot(d);
            row_sums[1] = kernel.mul_add(e_dot_d, row_sums[1]);
            kernel.neg_mul_add_to(e_dot_d, &mut col_sums[LANES..]);
        }
    }

    /// Per point, `S` computed pair by pair with `f64::exp`, and the error allowed for it:
    /// `Σ_j (4|x_ij| + 32) ε |K_ij t(i, j)|` with `x_ij = −r²/(2σ²)`, as the exponential
    /// amplifies the rounding of its argument to a relative error of about `|x| ε`.
    fn direct_sums(points: &[(Vec3, f64)], sigma: f64) -> Vec<[(f64, f64); 2]> {
        let e = Vec3::new(1.0, 2.0, -0.5);
        let mut out = vec![[(0.0, 0.0); 2]; points.len()];
        for (i, (qi, _)) in points.iter().enumerate() {
            for (_, (qj, wj)) in points.iter().enumerate().filter(|&(j, _)| j != i) {
                let x = -(qi - qj).norm_squared() / (2.0 * sigma * sigma);
                let k = x.exp();
                for (s, t) in out[i].iter_mut().zip([*wj, e.dot(&(qi - qj))]) {
                    let tol = (4.0 * x.abs() + 32.0) * f64::EPSILON * (k * t).abs();
                    *s = (s.0 + k * t, s.1 + tol);
                }
            }
        }
        out
    }

    /// The sums of a sweep over `points` with the inner loops `isa`.
    fn swept_sums(points: &[(Vec3, f64)], sigma: f64, isa: Isa) -> Vec<[f64; 2]> {
        let kernel = GaussianKernel::new(sigma).unwrap();
        let mut sweep = PairSweep::<4, 2>::new(&kernel, points.len());
        for (i, (q, w)) in points.iter().enumerate() {
            sweep.set_point(i, [q.x, q.y, q.z, *w]);
        }
        sweep.run_with(&TestTerms, isa);
        (0..points.len()).map(|i| sweep.sums(i)).collect()
    }

    fn random_points(seed: u64, k: usize) -> Vec<(Vec3, f64)> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut c = || rng.gen_range(-5.0..5.0);
        (0..k)
            .map(|_| (Vec3::new(c(), c(), c()), c() / 2.0))
            .collect()
    }

    #[test]
    fn kernel_rejects_bad_width() {
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(GaussianKernel::new(s).is_err());
        }
    }

    #[test]
    fn sums_are_the_same_bits_whatever_the_thread_count() {
        // 2,100 points: blocks of 256, a short last block and padding.
        let points = random_points(3, 2_100);
        let with_threads = |n| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| swept_sums(&points, 1.5, Isa::best()))
        };
        let one = with_threads(1);
        assert_eq!(one, with_threads(2));
        assert_eq!(one, with_threads(3));
    }

    proptest! {
        #[test]
        fn sums_match_direct_pair_sums(seed in 0u64..1000, k in 1usize..300, sigma in 0.3f64..4.0) {
            let points = random_points(seed, k);
            let direct = direct_sums(&points, sigma);
            for isa in [Isa::Portable, Isa::best()] {
                for (i, (s, d)) in swept_sums(&points, sigma, isa).iter().zip(&direct).enumerate() {
                    for c in 0..2 {
                        let (exact, tol) = d[c];
                        prop_assert!(
                            (s[c] - exact).abs() <= tol + 1e-300,
                            "{isa:?}, point {i}, sum {c}: {} vs {exact}", s[c]
                        );
                    }
                }
            }
        }
    }
}
