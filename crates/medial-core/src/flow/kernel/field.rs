//! The velocity field of the landmarks at any point of space,
//! `v(x) = Σ_j η(|x − q_j|) u_j` over all `k` landmarks, and maps of many points evaluated with
//! it in parallel.
//!
//! [`Sources`] holds the landmarks `(q_j, u_j)` of one time step in chunks of [`LANES`] (the
//! layout of [`super::PairSweep`]'s points, padded the same way); [`Sources::velocity`] sums
//! over them in index order, `LANES` landmarks at a time, and adds the lanes in a fixed order.
//! Each point's sum is thus the same sequence of operations whatever the number of threads:
//! [`map_points`] runs a per-point map over chunks of points in parallel and gives the same bits
//! for any thread count. The terms are those of the landmark flow's velocity: at a landmark
//! `x = q_i` the sum is the one [`super::PairSweep`] gives for `i` plus `u_i`, in another order.

use super::lanes::{self, F64Lanes, Isa};
use super::sweep::{chunked, PADDING_DISTANCE};
use super::{exp_neg_scaled, GaussianKernel, LANES};
use crate::{Result, Vec3};
use rayon::prelude::*;

/// Numbers per landmark: the point `q`, then the momentum `u`.
const FIELDS: usize = 6;

/// Points per parallel task of [`map_points`]: the kernel is chosen once per task.
const POINTS_PER_TASK: usize = 64;

/// The landmarks `(q_j, u_j)` of one time step, whose kernel sums give the velocity at any
/// point (see the module documentation).
#[derive(Clone, Debug)]
pub(crate) struct Sources {
    /// `1/(2σ²)`.
    scale: f64,
    /// Chunked as in [`super::PairSweep`]: number `f` of landmark `j` at
    /// `⌊j/LANES⌋·LANES·6 + LANES·f + j mod LANES`.
    points: Vec<f64>,
}

impl Sources {
    /// The landmarks `q` with the momenta `u` (`u[3j + c]`, as long as `3·q.len()`).
    pub(crate) fn new(kernel: &GaussianKernel, q: &[Vec3], u: &[f64]) -> Self {
        let padded = q.len().div_ceil(LANES) * LANES;
        let mut points = vec![0.0; padded * FIELDS];
        for j in q.len()..padded {
            points[chunked(j, FIELDS)] = PADDING_DISTANCE;
        }
        for (j, (qj, uj)) in q.iter().zip(u.chunks_exact(3)).enumerate() {
            let base = chunked(j, FIELDS);
            for (f, x) in [qj.x, qj.y, qj.z, uj[0], uj[1], uj[2]]
                .into_iter()
                .enumerate()
            {
                points[base + LANES * f] = x;
            }
        }
        Self {
            scale: kernel.half_inv_sigma2,
            points,
        }
    }

    /// `v(x) = Σ_j η(|x − q_j|) u_j` with the lanes `V`.
    #[inline(always)]
    pub(crate) fn velocity<V: F64Lanes>(&self, x: &Vec3) -> Vec3 {
        let xs = [V::splat(x.x), V::splat(x.y), V::splat(x.z)];
        let mut sums = [V::splat(0.0); 3];
        for chunk in self.points.chunks_exact(LANES * FIELDS) {
            let d = [
                xs[0] - V::load(chunk),
                xs[1] - V::load(&chunk[LANES..]),
                xs[2] - V::load(&chunk[2 * LANES..]),
            ];
            let r2 = d[2].mul_add(d[2], d[1].mul_add(d[1], d[0] * d[0]));
            let kernel = exp_neg_scaled(r2, self.scale);
            for (c, sum) in sums.iter_mut().enumerate() {
                *sum = kernel.mul_add(V::load(&chunk[LANES * (3 + c)..]), *sum);
            }
        }
        Vec3::new(sums[0].sum(), sums[1].sum(), sums[2].sum())
    }
}

/// A map of points of space computed with kernel sums on the lanes `V` ([`Sources::velocity`]).
pub(crate) trait PointMap: Sync {
    /// The image of `x`, or why there is none. Implementations are `#[inline(always)]`, so
    /// that they are compiled with the instructions of the lanes `V`.
    fn map<V: F64Lanes>(&self, x: &Vec3) -> Result<Vec3>;
}

/// `map` of every point, in parallel over chunks of points, with the fastest lanes the CPU has;
/// the error of the first point (in order) that has one.
pub(crate) fn map_points<M: PointMap>(map: &M, points: &[Vec3]) -> Result<Vec<Vec3>> {
    map_points_with(map, points, Isa::best())
}

/// [`map_points`] with the lanes `isa` (portable ones if the CPU lacks it).
fn map_points_with<M: PointMap>(map: &M, points: &[Vec3], isa: Isa) -> Result<Vec<Vec3>> {
    let chunks: Vec<Result<Vec<Vec3>>> = points
        .par_chunks(POINTS_PER_TASK)
        .map(|chunk| map_chunk(map, chunk, isa))
        .collect();
    let mut out = Vec::with_capacity(points.len());
    for chunk in chunks {
        out.extend(chunk?);
    }
    Ok(out)
}

/// The points of one chunk with the lanes `isa`.
fn map_chunk<M: PointMap>(map: &M, chunk: &[Vec3], isa: Isa) -> Result<Vec<Vec3>> {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 if isa.is_supported() => {
            // SAFETY: the running CPU supports AVX-512F, checked just above.
            unsafe { map_chunk_avx512(map, chunk) }
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2Fma if isa.is_supported() => {
            // SAFETY: the running CPU supports AVX2 and FMA, checked just above.
            unsafe { map_chunk_avx2_fma(map, chunk) }
        }
        _ => map_chunk_with::<M, lanes::Portable>(map, chunk),
    }
}

/// [`map_chunk_with`] on AVX-512 registers.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn map_chunk_avx512<M: PointMap>(map: &M, chunk: &[Vec3]) -> Result<Vec<Vec3>> {
    map_chunk_with::<M, lanes::Avx512>(map, chunk)
}

/// [`map_chunk_with`] on AVX2 registers with fused multiply-adds.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn map_chunk_avx2_fma<M: PointMap>(map: &M, chunk: &[Vec3]) -> Result<Vec<Vec3>> {
    map_chunk_with::<M, lanes::Avx2Fma>(map, chunk)
}

/// A loop rather than an iterator with a closure: the closure would be compiled on its own,
/// without the target features of the caller, and the lanes' intrinsics called out of line
/// (measured: 3× slower).
#[inline(always)]
fn map_chunk_with<M: PointMap, V: F64Lanes>(map: &M, chunk: &[Vec3]) -> Result<Vec<Vec3>> {
    let mut out = Vec::with_capacity(chunk.len());
    for x in chunk {
        out.push(map.map::<V>(x)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The velocity of `sources`, as a map.
    struct Velocity(Sources);

    impl PointMap for Velocity {
        #[inline(always)]
        fn map<V: F64Lanes>(&self, x: &Vec3) -> Result<Vec3> {
            Ok(self.0.velocity::<V>(x))
        }
    }

    fn random(seed: u64, n: usize, scale: f64) -> Vec<Vec3> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut c = || rng.gen_range(-scale..scale);
        (0..n).map(|_| Vec3::new(c(), c(), c())).collect()
    }

    #[test]
    fn velocities_match_direct_sums_with_either_lanes() {
        let sigma = 1.3;
        let kernel = GaussianKernel::new(sigma).unwrap();
        let (q, x) = (random(1, 37, 3.0), random(2, 150, 4.0));
        let u: Vec<f64> = random(3, 37, 1.0)
            .iter()
            .flat_map(|v| [v.x, v.y, v.z])
            .collect();
        let velocity = Velocity(Sources::new(&kernel, &q, &u));
        for isa in [Isa::Portable, Isa::best()] {
            let v = map_points_with(&velocity, &x, isa).unwrap();
            for (xi, vi) in x.iter().zip(&v) {
                let direct: Vec3 = q
                    .iter()
                    .zip(u.chunks_exact(3))
                    .map(|(qj, uj)| {
                        let k = (-(xi - qj).norm_squared() / (2.0 * sigma * sigma)).exp();
                        k * Vec3::from_column_slice(uj)
                    })
                    .sum();
                assert!((vi - direct).norm() < 1e-13, "{isa:?}: {vi} vs {direct}");
            }
        }
    }

    #[test]
    fn velocities_are_the_same_bits_whatever_the_thread_count() {
        let kernel = GaussianKernel::new(0.8).unwrap();
        let q = random(4, 301, 3.0);
        let u: Vec<f64> = random(5, 301, 1.0)
            .iter()
            .flat_map(|v| [v.x, v.y, v.z])
            .collect();
        let (velocity, x) = (Velocity(Sources::new(&kernel, &q, &u)), random(6, 999, 4.0));
        let with_threads = |n| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| map_points(&velocity, &x).unwrap())
        };
        let one = with_threads(1);
        assert_eq!(one, with_threads(2));
        assert_eq!(one, with_threads(3));
    }
}
