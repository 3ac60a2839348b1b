//! Sums over pairs of landmarks of the kernel times terms supplied by the caller.
//!
//! [`PairSweep`] computes sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over all pairs, with
//! `K_ij = η(|q_i − q_j|)`, for pair terms `t_c` supplied by the caller ([`PairTerms`]). The
//! index range is cut into blocks; every tile (I, J), I ≤ J, of blocks evaluates the kernel once
//! per unordered pair {i, j} and accumulates both the terms of its rows i ∈ I and those of its
//! columns j ∈ J in a buffer of its own. Tiles run in parallel (rayon); the buffers are then
//! reduced in a fixed order. Every number is thus computed by the same operations in the same
//! order whatever the thread count, and results are bit-identical.
//!
//! The inner loops handle [`LANES`] pairs at once. They are compiled twice, for any CPU and
//! for AVX2 with fused multiply-adds ([`Isa`]), chosen at run time once per tile. The two give
//! results that differ in the last bits (fused or separate roundings), so results may differ
//! between CPUs, but never between thread counts on one machine.

use super::lanes::{self, F64x4, Isa};
use super::{exp_neg_scaled, GaussianKernel, LANES};
use rayon::prelude::*;
use std::ops::Range;

/// Where the padding points of a [`PairSweep`] sit: far enough for the kernel to be exactly 0
/// for any width up to 1e40, near enough for `|d|²` and its products with the terms to be
/// finite.
pub(super) const PADDING_DISTANCE: f64 = 1e100;

/// Smallest and largest number of rows (and columns) of a block of the pair sweep. Small
/// blocks give a problem of a few hundred landmarks tens of tiles to share between threads;
/// large blocks make fewer partial sums to store and reduce when there are thousands.
const BLOCK_RANGE: (usize, usize) = (64, 256);

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
pub(super) fn chunked(i: usize, fields: usize) -> usize {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;
    use proptest::prelude::*;

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
