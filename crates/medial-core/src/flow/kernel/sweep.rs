//! Sums over pairs of landmarks of the kernel times terms supplied by the caller.
//!
//! [`PairSweep`] computes sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over all pairs, with
//! `K_ij = η(|q_i − q_j|)`, for pair terms `t_c` supplied by the caller ([`PairTerms`]). The
//! points are laid out in slots cut into blocks; every tile (I, J), I ≤ J, of blocks evaluates
//! the kernel once per unordered pair {i, j} and accumulates both the terms of its rows i ∈ I
//! and those of its columns j ∈ J in a buffer of its own. Tiles run in parallel (rayon); the
//! buffers are then reduced in a fixed order (per block, the tiles in their order). Every
//! number is thus computed by the same operations in the same order whatever the thread
//! count, and results are bit-identical.
//!
//! **Exact** (the kernel's tolerance ε = 0): the slots are the points in their order and every
//! tile is swept. **Truncated** (ε > 0): at every run the points are sorted along a Z-order
//! curve of a cell grid of side `r/256`, `r = σ √(2 ln(1/ε))` the kernel's cutoff radius
//! ([`GaussianKernel::cutoff_radius`]), so that the chunks of [`LANES`] consecutive slots are
//! small clusters; a tile carries a mask of its chunk pairs whose bounding boxes are at most
//! `r` apart, only those are swept (tiles with none are left out), and of a masked chunk pair a
//! row whose [`LANES`] squared distances all exceed `r²` skips the exponential and the terms.
//! Every pair skipped is thus more than `r` apart and has `K_ij < ε`, so that
//!
//! `|S_c(i) − S^ε_c(i)| ≤ ε Σ_{j skipped} |t_c(i, j)| ≤ ε Σ_{j ≠ i} |t_c(i, j)|`,
//!
//! and, for terms `t_c(i, j) = s_ij (q_i − q_j)_c` (the adjoint's), `≤ ε r Σ_j |s_ij|`, as
//! `x e^{−x²/(2σ²)}` decreases for `x > σ` and `r > σ` (ε < e^{−1/2}). The grid and the
//! order depend on the positions only, so truncated sums are as deterministic as exact ones,
//! and two runs on the same positions skip the same pairs.
//!
//! The inner loops handle [`LANES`] pairs at once. They are compiled for any CPU, for AVX2
//! with fused multiply-adds and for AVX-512 ([`Isa`]), chosen at run time once per tile. The
//! SIMD versions give the same bits; the portable one differs from them in the last bits
//! (separate roundings), so results may differ between CPUs with and without FMA, but never
//! between thread counts on one machine.

use super::lanes::{self, F64Lanes, Isa};
use super::{exp_neg_scaled, GaussianKernel, LANES};
use rayon::prelude::*;
use std::ops::Range;

/// Where the padding points of a [`PairSweep`] sit: far enough for the kernel to be exactly 0
/// for any width up to 1e40, near enough for `|d|²` and its products with the terms to be
/// finite.
pub(super) const PADDING_DISTANCE: f64 = 1e100;

/// Smallest and largest number of rows (and columns) of a block of a pair sweep, exact or
/// truncated. Small blocks give a problem of a few hundred landmarks tens of tiles to share
/// between threads; large blocks make fewer partial sums to store and reduce when there are
/// thousands. A truncated sweep prunes its pairs chunk pair by chunk pair, so its blocks can be
/// large while the pairs swept stay near; with 256-row blocks the truncated automatic fits of
/// t001-bent (k = 503: 2 blocks) and of the anterior mitral leaflet (k = 1,433: 6 blocks) left
/// a thread idle, and took 1.09× and 1.04× the wall time of 64 and 128 rows (paired runs).
const BLOCK_RANGE: (usize, usize) = (64, 256);

/// Chunks of [`LANES`] slots per block of a truncated sweep at most: the 32 bits of a mask
/// (and the stride of [`Layout::masks`]).
const CHUNKS_PER_BLOCK: usize = BLOCK_RANGE.1 / LANES;
const _: () = assert!(CHUNKS_PER_BLOCK <= 32 && BLOCK_RANGE.0 % LANES == 0);

/// Cells of the grid of a truncated sweep per cutoff radius: a fine curve, whose chunks of
/// [`LANES`] consecutive points are tight clusters.
const CELLS_PER_CUTOFF: f64 = 256.0;

/// The terms `t_c(i, j)`, `c < C`, of pair sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over points
/// that carry `F` numbers each, the first three being the coordinates of the point.
pub(crate) trait PairTerms<const F: usize, const C: usize>: Sync {
    /// For the pairs (i, j) with `j` the [`LANES`] points of `chunk` (number `f` of the point
    /// in lane `l` at `chunk[LANES·f + l]`), given the numbers of point `i` (`row`), `K_ij`
    /// (`kernel`) and `d = q_i − q_j`: adds `K_ij t_c(i, j)` to `row_sums[c]` and
    /// `K_ij t_c(j, i)` to the sums of the points `j`, `col_sums[LANES·c + l]`.
    fn accumulate<V: F64Lanes>(
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
/// each, with one kernel evaluation per unordered pair, exact or truncated (see the module
/// documentation).
///
/// Points, partial sums and sums are stored by slot in chunks of [`LANES`] slots, field after
/// field (number `f` of slot `s` at `⌊s/LANES⌋·LANES·F + LANES·f + s mod LANES`), so that the
/// inner loops read and write whole registers from contiguous memory. The slot count is padded
/// to a multiple of [`LANES`] with points [`PADDING_DISTANCE`] away, whose kernel values with
/// the others are exactly 0, and whose other numbers are 0.
#[derive(Clone, Debug)]
pub(crate) struct PairSweep<const F: usize, const C: usize> {
    /// `1/(2σ²)`.
    scale: f64,
    /// The kernel's cutoff radius: ∞ for an exact sweep.
    cutoff: f64,
    /// The numbers of every point, as set.
    staged: Vec<[f64; F]>,
    /// A truncated sweep's order of the points along the curve, as of the last run: the
    /// next run's sort starts from it (the order it ends with does not depend on it).
    order: Vec<usize>,
    layout: Layout,
    points: Vec<f64>,
    /// Per tile, the partial sums of its rows, then those of its columns (`C·block` each).
    partials: Vec<f64>,
    sums: Vec<f64>,
}

impl<const F: usize, const C: usize> PairSweep<F, C> {
    /// A sweep of `kernel` (exact or truncated, by its tolerance) over `landmarks` points, all
    /// at the origin with zero numbers.
    pub(crate) fn new(kernel: &GaussianKernel, landmarks: usize) -> Self {
        Self::with_layout(
            kernel.half_inv_sigma2,
            kernel.cutoff_radius(),
            Layout::exact(landmarks),
        )
    }

    /// An exact sweep (whatever `kernel`'s tolerance) over `free + fixed` points that skips the
    /// pairs of two fixed points: points `0..free` are free, `free..free + fixed` fixed, and
    /// `S(i)` sums over the other free points and, for a free `i`, over the fixed ones too
    /// (for a fixed `i`, over the free ones only). For attachments whose target–target sum is
    /// a constant: the free points' slots are padded to a whole number of blocks, and the
    /// tiles of two fixed blocks are left out.
    pub(crate) fn bipartite(kernel: &GaussianKernel, free: usize, fixed: usize) -> Self {
        let layout = Layout::bipartite(free, fixed);
        Self::with_layout(kernel.half_inv_sigma2, f64::INFINITY, layout)
    }

    /// A sweep over the points of `layout`, all at the origin with zero numbers, its other
    /// slots padding.
    fn with_layout(scale: f64, cutoff: f64, layout: Layout) -> Self {
        let landmarks = layout.slot.len();
        let mut points = vec![0.0; layout.padded * F];
        let mut used = vec![false; layout.padded];
        layout.slot.iter().for_each(|&s| used[s] = true);
        for s in (0..layout.padded).filter(|&s| !used[s]) {
            points[chunked(s, F)] = PADDING_DISTANCE;
        }
        Self {
            scale,
            cutoff,
            staged: vec![[0.0; F]; landmarks],
            order: (0..landmarks).collect(),
            sums: vec![0.0; layout.padded * C],
            partials: Vec::new(),
            points,
            layout,
        }
    }

    /// Sets the numbers of point `i`: its coordinates, then `F − 3` numbers for the terms.
    #[inline]
    pub(crate) fn set_point(&mut self, i: usize, numbers: [f64; F]) {
        self.staged[i] = numbers;
    }

    /// `[S_0(i), …, S_{C−1}(i)]` as of the last [`PairSweep::run`].
    #[inline]
    pub(crate) fn sums(&self, i: usize) -> [f64; C] {
        let base = chunked(self.layout.slot[i], C);
        std::array::from_fn(|c| self.sums[base + LANES * c])
    }

    /// Computes the sums for the current points: the layout (a truncated sweep's depends on
    /// the positions), the tiles in parallel, then for each block of slots the partial sums
    /// of its tiles in a fixed order.
    pub(crate) fn run<T: PairTerms<F, C>>(&mut self, terms: &T) {
        self.run_with(terms, Isa::best());
    }

    /// [`PairSweep::run`] in `layout`, the layout of a sweep (of any points' numbers) with the
    /// same kernel over the positions now set ([`PairSweep::layout`]): the same sums, without
    /// sorting the points again. The backward pass's sweep at a time step takes the forward
    /// pass's layout there.
    pub(crate) fn run_laid_out<T: PairTerms<F, C>>(&mut self, terms: &T, layout: &Layout) {
        debug_assert_eq!(layout.slot.len(), self.staged.len());
        self.layout.clone_from(layout);
        self.sweep(terms, Isa::best());
    }

    /// The layout of the last run.
    pub(crate) fn layout(&self) -> &Layout {
        &self.layout
    }

    /// [`PairSweep::run`] with the inner loops `isa` (or portable ones if the CPU lacks it).
    fn run_with<T: PairTerms<F, C>>(&mut self, terms: &T, isa: Isa) {
        if self.cutoff.is_finite() {
            self.layout = Layout::truncated(&self.staged, self.cutoff, &mut self.order);
        }
        self.sweep(terms, isa);
    }

    /// The sums in the present layout.
    fn sweep<T: PairTerms<F, C>>(&mut self, terms: &T, isa: Isa) {
        self.lay_out_points();
        let len = self.layout.tiles.len() * 2 * C * self.layout.block;
        self.partials.resize(len, 0.0);
        self.sweep_tiles(terms, isa);
        self.reduce();
    }

    /// Copies the numbers of every point to its slot.
    fn lay_out_points(&mut self) {
        for (numbers, &s) in self.staged.iter().zip(&self.layout.slot) {
            let base = chunked(s, F);
            for (f, &x) in numbers.iter().enumerate() {
                self.points[base + LANES * f] = x;
            }
        }
    }

    /// The partial sums of every tile, in parallel.
    fn sweep_tiles<T: PairTerms<F, C>>(&mut self, terms: &T, isa: Isa) {
        let Self {
            layout,
            scale,
            cutoff,
            points,
            partials,
            ..
        } = self;
        let (points, scale, cutoff2) = (&points[..], *scale, *cutoff * *cutoff);
        // Every tile a task of its own, so that a thread out of work takes single tiles from
        // the others: split only as far as rayon does by default, into an eighth to a quarter
        // of the tiles on 2 threads, one thread sat idle at the end of a sweep while the other
        // finished its last piece.
        partials
            .par_chunks_mut(2 * C * layout.block)
            .zip(&layout.tiles)
            .enumerate()
            .with_max_len(1)
            .for_each(|(t, (buf, &(bi, bj)))| {
                let rows = layout.range(bi);
                let mask = match layout.masks.is_empty() {
                    true => &[][..],
                    false => &layout.masks[t * CHUNKS_PER_BLOCK..][..rows.len() / LANES],
                };
                let tile = Tile {
                    rows,
                    cols: layout.range(bj),
                    scale,
                    cutoff2,
                    mask,
                };
                sweep_tile(isa, points, terms, &tile, buf);
            });
    }

    /// `S(i)` for the slots of each block: the partial sums of its tiles in their order (the
    /// column sums of tiles (J, I), J < I, the row then the column sums of (I, I), the row sums
    /// of (I, J), J > I), in parallel over blocks, however few: the other threads have just
    /// finished their tiles and would otherwise wait for the next step's sweep.
    fn reduce(&mut self) {
        let Self {
            layout,
            partials,
            sums,
            ..
        } = self;
        let part_len = C * layout.block;
        sums.par_chunks_mut(part_len)
            .zip(&layout.parts)
            .for_each(|(block_sums, parts)| {
                block_sums.fill(0.0);
                for &p in parts {
                    add_assign(block_sums, &partials[p * part_len..(p + 1) * part_len]);
                }
            });
    }
}

/// Where number 0 of slot `s` sits in an array of slots carrying `fields` numbers each,
/// stored in chunks of [`LANES`] slots field after field; number `f` is `LANES·f` further.
#[inline(always)]
pub(super) fn chunked(s: usize, fields: usize) -> usize {
    s / LANES * LANES * fields + s % LANES
}

/// `sums[n] += part[n]` for every `n < sums.len()`.
fn add_assign(sums: &mut [f64], part: &[f64]) {
    sums.iter_mut().zip(part).for_each(|(s, p)| *s += p);
}

/// The slots of the points, their cut into blocks (the last one shorter), the tiles (I, J),
/// I ≤ J, that are swept, in row-major order, and the partial sums each block adds up.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// The slot of every point.
    slot: Vec<usize>,
    padded: usize,
    /// Rows of a block: a multiple of [`LANES`] that depends on the number of points only, so
    /// that the order of the sums does not depend on the number of threads.
    block: usize,
    tiles: Vec<(usize, usize)>,
    /// A truncated sweep's masks of the chunk pairs swept: per tile, [`CHUNKS_PER_BLOCK`]
    /// masks, bit `b` of mask `a` set when the pairs of row chunk `a` and column chunk `b`
    /// are swept; empty for an exact sweep, whose tiles are swept whole.
    masks: Vec<u32>,
    /// Per block, the partial sums to add in this order: `2t` the row sums of tile `t`,
    /// `2t + 1` its column sums.
    parts: Vec<Vec<usize>>,
}

impl Layout {
    /// Every point in its own slot, blocks of about a sixteenth of the points (a power of two
    /// in [`BLOCK_RANGE`]), and every tile.
    fn exact(landmarks: usize) -> Self {
        let padded = landmarks.div_ceil(LANES) * LANES;
        let block = block_rows(padded);
        let slot = (0..landmarks).collect();
        let tiles = upper_tiles(padded.div_ceil(block)).collect();
        Self::with_tiles(slot, padded, block, tiles, Vec::new())
    }

    /// The free points `0..free` in the first slots, padded to a whole number of blocks (the
    /// block as [`Layout::exact`] chooses it for all the points), then the fixed ones; every
    /// tile but those of two fixed blocks.
    fn bipartite(free: usize, fixed: usize) -> Self {
        let block = block_rows((free + fixed).div_ceil(LANES) * LANES);
        let free_blocks = free.div_ceil(block);
        let first_fixed = free_blocks * block;
        let padded = first_fixed + fixed.div_ceil(LANES) * LANES;
        let slot = (0..free).chain(first_fixed..first_fixed + fixed).collect();
        let tiles = upper_tiles(padded.div_ceil(block))
            .filter(|&(bi, _)| bi < free_blocks)
            .collect();
        Self::with_tiles(slot, padded, block, tiles, Vec::new())
    }

    /// The points sorted along the Z-order curve of a grid of cells of side
    /// `cutoff / CELLS_PER_CUTOFF` (ties by index; `order`, the previous order, is sorted
    /// into the new one), blocks of [`block_rows`] slots, and per tile (I, J), I ≤ J, the
    /// chunk pairs (a, b), a ≤ b on a diagonal tile, whose chunks' bounding boxes are at most
    /// `cutoff` apart (or not comparable: non-finite coordinates); the tiles with none are
    /// left out.
    fn truncated<const F: usize>(points: &[[f64; F]], cutoff: f64, order: &mut Vec<usize>) -> Self {
        let position = |i: usize| [points[i][0], points[i][1], points[i][2]];
        let all = Aabb::of((0..points.len()).map(position));
        let cell = cutoff / CELLS_PER_CUTOFF;
        // The codes with the index are distinct: every sort gives the same order whatever the
        // one it starts from, and the stable sort is fast on the nearly sorted order of the
        // previous time step.
        let mut keyed: Vec<(u64, usize)> = (order.iter())
            .map(|&i| (morton_code(position(i), all.lo, cell), i))
            .collect();
        keyed.sort();
        order.clear();
        order.extend(keyed.iter().map(|&(_, i)| i));
        let mut slot = vec![0; points.len()];
        for (s, &i) in order.iter().enumerate() {
            slot[i] = s;
        }
        let padded = points.len().div_ceil(LANES) * LANES;
        let chunk_boxes: Vec<Aabb> = order
            .chunks(LANES)
            .map(|chunk| Aabb::of(chunk.iter().map(|&i| position(i))))
            .collect();
        let block = block_rows(padded);
        let chunks_per_block = block / LANES;
        let block_boxes: Vec<Aabb> = (chunk_boxes.chunks(chunks_per_block))
            .map(|boxes| boxes.iter().fold(Aabb::EMPTY, |b, c| b.union(c)))
            .collect();
        // Kept unless provably far: a NaN gap (non-finite coordinates) keeps the pair.
        let cutoff2 = cutoff * cutoff;
        let near = |a: &Aabb, b: &Aabb| {
            let gap = a.gap_squared(b);
            gap.partial_cmp(&cutoff2) != Some(std::cmp::Ordering::Greater)
        };
        let candidates: Vec<(usize, usize)> = upper_tiles(block_boxes.len())
            .filter(|&(bi, bj)| near(&block_boxes[bi], &block_boxes[bj]))
            .collect();
        let chunks = |b: usize| {
            let end = ((b + 1) * chunks_per_block).min(chunk_boxes.len());
            &chunk_boxes[b * chunks_per_block..end]
        };
        let masks: Vec<[u32; CHUNKS_PER_BLOCK]> = (candidates.par_iter())
            .map(|&(bi, bj)| {
                let mut masks = [0u32; CHUNKS_PER_BLOCK];
                let cols = chunks(bj);
                for (a, row) in chunks(bi).iter().enumerate() {
                    if !near(row, &block_boxes[bj]) {
                        continue;
                    }
                    let first = if bi == bj { a } else { 0 };
                    for (b, col) in cols.iter().enumerate().skip(first) {
                        masks[a] |= u32::from(near(row, col)) << b;
                    }
                }
                masks
            })
            .collect();
        let (tiles, masks): (Vec<_>, Vec<_>) = (candidates.into_iter().zip(masks))
            .filter(|(_, masks)| masks.iter().any(|&m| m != 0))
            .unzip();
        let masks = masks.into_iter().flatten().collect();
        Self::with_tiles(slot, padded, block, tiles, masks)
    }

    /// The layout of `slot` with the `tiles` (I, J), I ≤ J, in row-major order, and their
    /// chunk masks (see [`Layout::masks`]).
    fn with_tiles(
        slot: Vec<usize>,
        padded: usize,
        block: usize,
        tiles: Vec<(usize, usize)>,
        masks: Vec<u32>,
    ) -> Self {
        let mut parts = vec![Vec::new(); padded.div_ceil(block)];
        for (t, &(bi, bj)) in tiles.iter().enumerate() {
            parts[bi].push(2 * t);
            parts[bj].push(2 * t + 1);
        }
        Self {
            slot,
            padded,
            block,
            tiles,
            masks,
            parts,
        }
    }

    /// Slots of block `b`.
    fn range(&self, b: usize) -> Range<usize> {
        b * self.block..((b + 1) * self.block).min(self.padded)
    }
}

/// The rows of a block of a sweep over `padded` slots: about a sixteenth of them, a power of
/// two in [`BLOCK_RANGE`].
fn block_rows(padded: usize) -> usize {
    (padded / 16)
        .next_power_of_two()
        .clamp(BLOCK_RANGE.0, BLOCK_RANGE.1)
}

/// The Z-order (Morton) code of the cell of side `cell` holding `p`, cells counted from `lo`
/// (at most 2²¹ per axis: farther cells share the last one, which changes only the order).
fn morton_code(p: [f64; 3], lo: [f64; 3], cell: f64) -> u64 {
    const MAX_CELL: f64 = ((1u64 << 21) - 1) as f64;
    (0..3).fold(0, |code, axis| {
        // A NaN coordinate goes to cell 0 (`as` saturates and maps NaN to 0).
        let c = ((p[axis] - lo[axis]) / cell).clamp(0.0, MAX_CELL) as u64;
        code | spread_bits(c) << axis
    })
}

/// The 21 low bits of `x` moved to bits 0, 3, 6, … (for interleaving three of them).
fn spread_bits(x: u64) -> u64 {
    (0..21).fold(0, |out, b| out | ((x >> b) & 1) << (3 * b))
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug)]
struct Aabb {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Aabb {
    /// The box of no point.
    const EMPTY: Self = Self {
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
    };

    /// The box of both boxes.
    fn union(&self, other: &Self) -> Self {
        Self {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }

    /// The box of `points` (lo = +∞, hi = −∞ for none; NaN coordinates are left out).
    fn of(points: impl Iterator<Item = [f64; 3]>) -> Self {
        points.fold(Self::EMPTY, |b, p| Self {
            lo: std::array::from_fn(|a| b.lo[a].min(p[a])),
            hi: std::array::from_fn(|a| b.hi[a].max(p[a])),
        })
    }

    /// The squared distance between the nearest points of the two boxes (0 if they meet).
    fn gap_squared(&self, other: &Self) -> f64 {
        (0..3)
            .map(|a| {
                let gap = (self.lo[a] - other.hi[a])
                    .max(other.lo[a] - self.hi[a])
                    .max(0.0);
                gap * gap
            })
            .sum()
    }
}

/// The tiles (I, J), I ≤ J, of `blocks` blocks, in row-major order.
fn upper_tiles(blocks: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..blocks).flat_map(move |bi| (bi..blocks).map(move |bj| (bi, bj)))
}

/// One tile: rows I and columns J, both starting at a multiple of [`LANES`], the kernel's
/// `1/(2σ²)` and, on a truncated sweep, the masks of its chunk pairs (see [`Layout::masks`]),
/// one per row chunk; empty: every pair.
struct Tile<'a> {
    rows: Range<usize>,
    cols: Range<usize>,
    scale: f64,
    /// The square of the cutoff radius (∞ for an exact sweep).
    cutoff2: f64,
    mask: &'a [u32],
}

/// The partial sums of one tile into `buf` (see [`PairSweep::partials`]) with the inner loops
/// `isa`, or portable ones if the CPU lacks it.
fn sweep_tile<const F: usize, const C: usize, T: PairTerms<F, C>>(
    isa: Isa,
    points: &[f64],
    terms: &T,
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 if isa.is_supported() => {
            // SAFETY: the running CPU supports AVX-512F, checked just above.
            unsafe { sweep_tile_avx512(points, terms, tile, buf) }
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2Fma if isa.is_supported() => {
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
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    sweep_tile_with::<F, C, T, lanes::Avx2Fma>(points, terms, tile, buf)
}

/// [`sweep_tile_with`] on AVX-512 registers.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn sweep_tile_avx512<const F: usize, const C: usize, T: PairTerms<F, C>>(
    points: &[f64],
    terms: &T,
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    sweep_tile_with::<F, C, T, lanes::Avx512>(points, terms, tile, buf)
}

/// One tile with the lanes `V`, by the body compiled for its shape: diagonal or not.
#[inline(always)]
fn sweep_tile_with<const F: usize, const C: usize, T: PairTerms<F, C>, V: F64Lanes>(
    points: &[f64],
    terms: &T,
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    match (tile.mask.is_empty(), tile.rows.start == tile.cols.start) {
        (true, true) => sweep_tile_body::<F, C, T, V, true>(points, terms, tile, buf),
        (true, false) => sweep_tile_body::<F, C, T, V, false>(points, terms, tile, buf),
        (false, true) => sweep_masked_tile::<F, C, T, V, true>(points, terms, tile, buf),
        (false, false) => sweep_masked_tile::<F, C, T, V, false>(points, terms, tile, buf),
    }
}

/// The squared distances of point `i` (at `qi`) to the [`LANES`] points of `chunk`, and
/// `d = q_i − q_j`.
#[inline(always)]
fn distances<V: F64Lanes>(qi: &[V; 3], chunk: &[f64]) -> (V, [V; 3]) {
    let qj = [
        V::load(chunk),
        V::load(&chunk[LANES..]),
        V::load(&chunk[2 * LANES..]),
    ];
    let d = [qi[0] - qj[0], qi[1] - qj[1], qi[2] - qj[2]];
    (d[2].mul_add(d[2], d[1].mul_add(d[1], d[0] * d[0])), d)
}

/// The numbers of point `i` (its slot in the chunked layout) and its position in every lane.
#[inline(always)]
fn load_row<const F: usize, V: F64Lanes>(points: &[f64], i: usize) -> ([f64; F], [V; 3]) {
    let base = chunked(i, F);
    let mut row = [0.0; F];
    for (f, x) in row.iter_mut().enumerate() {
        *x = points[base + LANES * f];
    }
    let qi = [V::splat(row[0]), V::splat(row[1]), V::splat(row[2])];
    (row, qi)
}

/// `kernel` with its lanes `l ≤ last` set to 0.
#[inline(always)]
fn zero_lanes_to<V: F64Lanes>(kernel: V, last: usize) -> V {
    let mut k = kernel.to_array();
    for k in &mut k[..=last] {
        *k = 0.0;
    }
    V::from_array(k)
}

/// One tile of a truncated sweep: for each row i of a row chunk `a`, the pairs (i, j) with j in
/// the column chunks `b` of mask `a` (j > i on a `DIAGONAL` tile), LANES at a time. Sums as in
/// [`sweep_tile_body`]; the rows of a chunk with no pair have row sums 0.
#[inline(always)]
fn sweep_masked_tile<
    const F: usize,
    const C: usize,
    T: PairTerms<F, C>,
    V: F64Lanes,
    const DIAGONAL: bool,
>(
    points: &[f64],
    terms: &T,
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    let (row_sums, col_sums) = buf.split_at_mut(buf.len() / 2);
    col_sums.fill(0.0);
    row_sums.fill(0.0);
    let columns = &points[tile.cols.start * F..tile.cols.end * F];
    for (a, &mask) in tile.mask.iter().enumerate() {
        if mask == 0 {
            continue;
        }
        for l in 0..LANES {
            let r = a * LANES + l;
            let (row, qi) = load_row::<F, V>(points, tile.rows.start + r);
            let mut acc = [V::splat(0.0); C];
            // On a diagonal tile, the last row of chunk `a` has no pair in it.
            let mut bits = mask;
            if DIAGONAL && l == LANES - 1 {
                bits &= !(1 << a);
            }
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let chunk = &columns[b * LANES * F..][..LANES * F];
                let sums = &mut col_sums[b * LANES * C..][..LANES * C];
                let (r2, d) = distances(&qi, chunk);
                // All LANES pairs beyond the cutoff: skipped, as the forward and backward
                // passes at these positions both do.
                if r2.all_greater(tile.cutoff2) {
                    continue;
                }
                let mut kij = exp_neg_scaled(r2, tile.scale);
                if DIAGONAL && b == a {
                    kij = zero_lanes_to(kij, l);
                }
                terms.accumulate(&row, chunk, kij, &d, &mut acc, sums);
            }
            for (c, acc) in acc.iter().enumerate() {
                row_sums[chunked(r, C) + LANES * c] = acc.sum();
            }
        }
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
    V: F64Lanes,
    const DIAGONAL: bool,
>(
    points: &[f64],
    terms: &T,
    tile: &Tile<'_>,
    buf: &mut [f64],
) {
    let (row_sums, col_sums) = buf.split_at_mut(buf.len() / 2);
    col_sums.fill(0.0);
    let columns = &points[tile.cols.start * F..tile.cols.end * F];
    for (r, i) in tile.rows.clone().enumerate() {
        let (row, qi) = load_row::<F, V>(points, i);
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
            let (r2, d) = distances(&qi, chunk);
            let mut kij = exp_neg_scaled(r2, tile.scale);
            let j = tile.cols.start + n * LANES;
            if DIAGONAL && j <= i {
                kij = zero_lanes_to(kij, i - j);
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
        fn e_dot<V: F64Lanes>(d: &[V; 3]) -> V {
            d[2].mul_add(V::splat(-0.5), d[1].mul_add(V::splat(2.0), d[0]))
        }
    }

    impl PairTerms<4, 2> for TestTerms {
        fn accumulate<V: F64Lanes>(
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
        direct_sums_but_fixed(points, sigma, points.len())
    }

    /// [`direct_sums`] without the pairs of two points `≥ fixed`.
    fn direct_sums_but_fixed(
        points: &[(Vec3, f64)],
        sigma: f64,
        fixed: usize,
    ) -> Vec<[(f64, f64); 2]> {
        let e = Vec3::new(1.0, 2.0, -0.5);
        let mut out = vec![[(0.0, 0.0); 2]; points.len()];
        for (i, (qi, _)) in points.iter().enumerate() {
            let other = |&(j, _): &(usize, _)| j != i && (i < fixed || j < fixed);
            for (_, (qj, wj)) in points.iter().enumerate().filter(other) {
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

    /// The sums of a sweep over `points` with the kernel tolerance `eps` and the inner loops
    /// `isa`, and the number of tiles swept.
    fn swept_sums(
        points: &[(Vec3, f64)],
        sigma: f64,
        eps: f64,
        isa: Isa,
    ) -> (Vec<[f64; 2]>, usize) {
        let kernel = GaussianKernel::new(sigma).unwrap().truncated(eps).unwrap();
        let mut sweep = PairSweep::<4, 2>::new(&kernel, points.len());
        for (i, (q, w)) in points.iter().enumerate() {
            sweep.set_point(i, [q.x, q.y, q.z, *w]);
        }
        sweep.run_with(&TestTerms, isa);
        let sums = (0..points.len()).map(|i| sweep.sums(i)).collect();
        (sums, sweep.layout.tiles.len())
    }

    /// Per point, `Σ_{j ≠ i} |t_c(i, j)|`: the sum that ε times bounds the truncation error.
    fn term_magnitudes(points: &[(Vec3, f64)]) -> Vec<[f64; 2]> {
        let e = Vec3::new(1.0, 2.0, -0.5);
        (points.iter().enumerate())
            .map(|(i, (qi, _))| {
                (points.iter().enumerate().filter(|&(j, _)| j != i))
                    .fold([0.0; 2], |[a, b], (_, (qj, wj))| {
                        [a + wj.abs(), b + e.dot(&(qi - qj)).abs()]
                    })
            })
            .collect()
    }

    fn random_points(seed: u64, k: usize) -> Vec<(Vec3, f64)> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut c = || rng.gen_range(-5.0..5.0);
        (0..k)
            .map(|_| (Vec3::new(c(), c(), c()), c() / 2.0))
            .collect()
    }

    /// The sums of [`swept_sums`] on 1, 2 and 3 threads, checked equal.
    fn same_on_any_thread_count(points: &[(Vec3, f64)], sigma: f64, eps: f64) {
        let with_threads = |n| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| swept_sums(points, sigma, eps, Isa::best()).0)
        };
        let one = with_threads(1);
        assert_eq!(one, with_threads(2));
        assert_eq!(one, with_threads(3));
    }

    #[test]
    fn sums_are_the_same_bits_whatever_the_thread_count() {
        // 2,100 points: blocks of 256, a short last block and padding.
        same_on_any_thread_count(&random_points(3, 2_100), 1.5, 0.0);
    }

    #[test]
    fn truncated_sums_are_the_same_bits_whatever_the_thread_count() {
        same_on_any_thread_count(&random_points(4, 2_100), 0.5, 1e-6);
    }

    #[test]
    fn simd_implementations_give_the_same_bits() {
        let points = random_points(5, 700);
        for eps in [0.0, 1e-4] {
            let sums: Vec<_> = (Isa::ALL.into_iter().skip(1))
                .filter(|isa| isa.is_supported())
                .map(|isa| swept_sums(&points, 1.0, eps, isa).0)
                .collect();
            assert!(sums.windows(2).all(|w| w[0] == w[1]), "ε = {eps}");
        }
    }

    #[test]
    fn truncation_skips_far_tiles() {
        // Points along a line 1,000 long: with σ = 1, ε = 1e-10 (r ≈ 6.8), most blocks are far.
        let points: Vec<(Vec3, f64)> = (0..4_000)
            .map(|i| (Vec3::new(i as f64 * 0.25, 0.0, 0.0), 1.0))
            .collect();
        let (exact, all) = swept_sums(&points, 1.0, 0.0, Isa::best());
        let (truncated, few) = swept_sums(&points, 1.0, 1e-10, Isa::best());
        let blocks = 4_000usize.div_ceil(block_rows(4_000));
        assert!(few < 3 * blocks, "{few} tiles of {blocks} blocks");
        assert!(all < few * blocks);
        let magnitudes = term_magnitudes(&points);
        for ((t, e), m) in truncated.iter().zip(&exact).zip(&magnitudes) {
            assert!((t[0] - e[0]).abs() <= 1e-10 * m[0] + 1e-13 * m[0]);
        }
    }

    /// Terms that record the pairs swept: a point carries its index + 1 (0 for padding), and
    /// every lane with a kernel value not 0 (masked lanes and padding have 0) is a pair.
    struct PairLog(std::sync::Mutex<Vec<(usize, usize)>>);

    impl PairTerms<4, 1> for PairLog {
        fn accumulate<V: F64Lanes>(
            &self,
            row: &[f64; 4],
            chunk: &[f64],
            kernel: V,
            _d: &[V; 3],
            _row_sums: &mut [V; 1],
            _col_sums: &mut [f64],
        ) {
            let mut log = self.0.lock().unwrap();
            for (l, k) in kernel.to_array().into_iter().enumerate() {
                let (i, j) = (row[3] as usize, chunk[3 * LANES + l] as usize);
                if k != 0.0 && j > 0 {
                    log.push(((i - 1).min(j - 1), (i - 1).max(j - 1)));
                }
            }
        }
    }

    /// The pairs {i, j}, i < j, that a sweep with the tolerance `eps` evaluates, sorted, each
    /// as often as it is evaluated.
    fn swept_pairs(points: &[(Vec3, f64)], sigma: f64, eps: f64) -> Vec<(usize, usize)> {
        let kernel = GaussianKernel::new(sigma).unwrap().truncated(eps).unwrap();
        let mut sweep = PairSweep::<4, 1>::new(&kernel, points.len());
        for (i, (q, _)) in points.iter().enumerate() {
            sweep.set_point(i, [q.x, q.y, q.z, (i + 1) as f64]);
        }
        let log = PairLog(Default::default());
        sweep.run_with(&log, Isa::best());
        let mut pairs = log.0.into_inner().unwrap();
        pairs.sort_unstable();
        pairs
    }

    #[test]
    fn truncation_sweeps_every_near_pair_once() {
        // Clusters and scattered points; σ small enough for most pairs to be far.
        for (seed, k, sigma, eps) in [
            (6, 3_000, 0.3, 1e-10),
            (7, 1_100, 0.1, 1e-3),
            (8, 9, 1.0, 0.1),
        ] {
            let mut points = random_points(seed, k);
            for p in points.iter_mut().step_by(3) {
                p.0 *= 0.1;
            }
            let r = GaussianKernel::new(sigma)
                .unwrap()
                .truncated(eps)
                .unwrap()
                .cutoff_radius();
            let pairs = swept_pairs(&points, sigma, eps);
            assert!(pairs.windows(2).all(|w| w[0] < w[1]), "a pair swept twice");
            let near: Vec<(usize, usize)> = (0..k)
                .flat_map(|i| (i + 1..k).map(move |j| (i, j)))
                .filter(|&(i, j)| (points[i].0 - points[j].0).norm() <= r)
                .collect();
            let swept: std::collections::HashSet<_> = pairs.iter().collect();
            assert!(
                near.iter().all(|p| swept.contains(p)),
                "a near pair skipped"
            );
            assert!(pairs.len() < k * (k - 1) / 2 || k < 100, "no pair skipped");
            // The exact sweep evaluates every pair once (with a σ under which no value is 0).
            let all = swept_pairs(&points, 100.0, 0.0);
            assert_eq!(all.len(), k * (k - 1) / 2);
        }
    }

    proptest! {
        #[test]
        fn sums_match_direct_pair_sums(seed in 0u64..1000, k in 1usize..300, sigma in 0.3f64..4.0) {
            let points = random_points(seed, k);
            let direct = direct_sums(&points, sigma);
            for isa in Isa::ALL.into_iter().filter(|isa| isa.is_supported()) {
                let (sums, _) = swept_sums(&points, sigma, 0.0, isa);
                for (i, (s, d)) in sums.iter().zip(&direct).enumerate() {
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

        /// A bipartite sweep sums over every pair but those of two fixed points, on every ISA.
        #[test]
        fn bipartite_sums_match_direct_sums_without_fixed_pairs(
            seed in 0u64..1000,
            free in 1usize..300,
            fixed in 1usize..300,
        ) {
            let points = random_points(seed, free + fixed);
            let direct = direct_sums_but_fixed(&points, 1.5, free);
            let kernel = GaussianKernel::new(1.5).unwrap();
            for isa in Isa::ALL.into_iter().filter(|isa| isa.is_supported()) {
                let mut sweep = PairSweep::<4, 2>::bipartite(&kernel, free, fixed);
                for (i, (q, w)) in points.iter().enumerate() {
                    sweep.set_point(i, [q.x, q.y, q.z, *w]);
                }
                sweep.run_with(&TestTerms, isa);
                for (i, d) in direct.iter().enumerate() {
                    let s = sweep.sums(i);
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

        /// The truncation bound: `|S^ε − S| ≤ ε Σ_j |t(i, j)|` (plus the rounding of the sums).
        #[test]
        fn truncated_sums_are_within_the_tolerance_bound(
            seed in 0u64..1000,
            k in 1usize..700,
            sigma in 0.2f64..2.0,
            log_eps in -12.0f64..-0.4,
        ) {
            let eps = 10f64.powf(log_eps);
            let points = random_points(seed, k);
            let direct = direct_sums(&points, sigma);
            let magnitudes = term_magnitudes(&points);
            let (sums, _) = swept_sums(&points, sigma, eps, Isa::best());
            for (i, ((s, d), m)) in sums.iter().zip(&direct).zip(&magnitudes).enumerate() {
                for c in 0..2 {
                    let (exact, tol) = d[c];
                    let bound = eps * m[c] + tol + 1e-300;
                    prop_assert!(
                        (s[c] - exact).abs() <= bound,
                        "ε = {eps}, point {i}, sum {c}: {} vs {exact}, bound {bound}", s[c]
                    );
                }
            }
        }
    }
}
