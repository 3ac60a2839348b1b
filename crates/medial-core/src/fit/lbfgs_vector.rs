//! The momenta as L-BFGS sees them: a vector whose algebra (the argmin-math operations that
//! L-BFGS and its More–Thuente line search use) runs on the thread pool, with the same bits
//! for any thread count.
//!
//! An L-BFGS iteration with memory m passes over its vectors about 7m + 10 times (3m + 2 dot
//! products, 2m scaled additions that each make a product and then a sum, the copies argmin
//! makes of the iterate and gradient). With m = 10 and 79,000 momenta (the reduced KeOps
//! hippocampus in 40 steps) those are about 50 MB of memory traffic per iteration.
//! argmin-math's nalgebra and `Vec` backends are sequential, so the operations are written
//! here (no maintained crate offers deterministic parallel argmin-math vectors).
//!
//! **Determinism.** Elementwise operations are the same bits however they are split. Sums
//! (dot products, norms) are split into fixed chunks of [`CHUNK`] entries, independent of
//! the thread count; each chunk is summed in [`ACCUMULATORS`] running terms, and the chunks'
//! sums are added in chunk order. Vectors shorter than [`PARALLEL_FROM`] are computed on the
//! calling thread, in the same chunks.

use argmin_math::{
    ArgminAdd, ArgminDot, ArgminL1Norm, ArgminL2Norm, ArgminMinMax, ArgminMul, ArgminScaledAdd,
    ArgminSignum, ArgminSub, ArgminZeroLike,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::mem::MaybeUninit;

/// Entries per chunk of a sum (and per task of an elementwise operation): 64 KiB of `f64`.
pub const CHUNK: usize = 8192;

/// Running terms of the sum of a chunk: independent additions that the CPU overlaps and the
/// compiler keeps in SIMD registers (a single running sum is a chain of dependent additions).
pub const ACCUMULATORS: usize = 8;

/// Shortest vector whose operations run on the thread pool: below it, handing the work to
/// the pool costs more than it saves.
pub const PARALLEL_FROM: usize = 4 * CHUNK;

/// A vector of `f64` whose argmin-math operations run in parallel, deterministically (see the
/// module documentation).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct LbfgsVector(Vec<f64>);

impl LbfgsVector {
    /// The vector of `values`.
    pub fn from_slice(values: &[f64]) -> Self {
        Self(values.to_vec())
    }

    /// Its entries.
    pub fn as_slice(&self) -> &[f64] {
        &self.0
    }

    /// `f(x_i)` for every entry.
    fn map(&self, f: impl Fn(f64) -> f64 + Sync + Send) -> Self {
        self.zip_map(self, |x, _| f(x))
    }

    /// `f(x_i, y_i)` for every entry of `self` and `other` (of the same length), written chunk
    /// by chunk into the new vector: a plain loop over slices, which the compiler vectorises
    /// (a parallel `collect` stores one checked entry at a time, several instructions each).
    /// Scalars go into `f` by value: one read through a reference is repeated for every entry,
    /// as the stores might change it.
    fn zip_map(&self, other: &Self, f: impl Fn(f64, f64) -> f64 + Sync + Send) -> Self {
        assert_eq!(self.0.len(), other.0.len(), "vectors of different lengths");
        let len = self.0.len();
        let mut out = Vec::with_capacity(len);
        let spare = &mut out.spare_capacity_mut()[..len];
        if len < PARALLEL_FROM {
            fill(spare, &self.0, &other.0, &f);
        } else {
            (spare.par_chunks_mut(CHUNK))
                .zip(self.0.par_chunks(CHUNK))
                .zip(other.0.par_chunks(CHUNK))
                .for_each(|((out, x), y)| fill(out, x, y, &f));
        }
        // SAFETY: all `len` entries were written: `fill` writes every entry of each chunk of
        // `spare`, zipped with the chunks of `self` and `other` of the same length.
        unsafe { out.set_len(len) };
        Self(out)
    }

    /// `Σ_i f(x_i, y_i)`, chunk by chunk (see the module documentation).
    fn sum_of(&self, other: &Self, f: impl Fn(f64, f64) -> f64 + Sync + Send) -> f64 {
        assert_eq!(self.0.len(), other.0.len(), "vectors of different lengths");
        let chunk_sum = |(x, y): (&[f64], &[f64])| {
            let mut acc = [0.0; ACCUMULATORS];
            let (xs, ys) = (x.chunks_exact(ACCUMULATORS), y.chunks_exact(ACCUMULATORS));
            let (x_tail, y_tail) = (xs.remainder(), ys.remainder());
            for (x, y) in xs.zip(ys) {
                for l in 0..ACCUMULATORS {
                    acc[l] += f(x[l], y[l]);
                }
            }
            for (l, (&x, &y)) in x_tail.iter().zip(y_tail).enumerate() {
                acc[l] += f(x, y);
            }
            acc.iter().sum::<f64>()
        };
        if self.0.len() < PARALLEL_FROM {
            return self
                .0
                .chunks(CHUNK)
                .zip(other.0.chunks(CHUNK))
                .map(chunk_sum)
                .sum();
        }
        let sums: Vec<f64> = self
            .0
            .par_chunks(CHUNK)
            .zip(other.0.par_chunks(CHUNK))
            .map(chunk_sum)
            .collect();
        sums.iter().sum()
    }
}

/// `out_i = f(x_i, y_i)` for every entry of `out`, `x` and `y` of its length.
fn fill(out: &mut [MaybeUninit<f64>], x: &[f64], y: &[f64], f: impl Fn(f64, f64) -> f64) {
    for ((o, &x), &y) in out.iter_mut().zip(x).zip(y) {
        o.write(f(x, y));
    }
}

impl ArgminDot<LbfgsVector, f64> for LbfgsVector {
    /// `Σ_i x_i y_i`.
    fn dot(&self, other: &LbfgsVector) -> f64 {
        self.sum_of(other, |x, y| x * y)
    }
}

impl ArgminL2Norm<f64> for LbfgsVector {
    /// `√(Σ_i x_i²)`.
    fn l2_norm(&self) -> f64 {
        self.sum_of(self, |x, _| x * x).sqrt()
    }
}

impl ArgminL1Norm<f64> for LbfgsVector {
    /// `Σ_i |x_i|`.
    fn l1_norm(&self) -> f64 {
        self.sum_of(self, |x, _| x.abs())
    }
}

impl ArgminAdd<LbfgsVector, LbfgsVector> for LbfgsVector {
    fn add(&self, other: &LbfgsVector) -> LbfgsVector {
        self.zip_map(other, |x, y| x + y)
    }
}

impl ArgminAdd<f64, LbfgsVector> for LbfgsVector {
    fn add(&self, other: &f64) -> LbfgsVector {
        let a = *other;
        self.map(move |x| x + a)
    }
}

impl ArgminSub<LbfgsVector, LbfgsVector> for LbfgsVector {
    fn sub(&self, other: &LbfgsVector) -> LbfgsVector {
        self.zip_map(other, |x, y| x - y)
    }
}

impl ArgminSub<f64, LbfgsVector> for LbfgsVector {
    fn sub(&self, other: &f64) -> LbfgsVector {
        let a = *other;
        self.map(move |x| x - a)
    }
}

impl ArgminMul<f64, LbfgsVector> for LbfgsVector {
    fn mul(&self, other: &f64) -> LbfgsVector {
        let a = *other;
        self.map(move |x| x * a)
    }
}

impl ArgminMul<LbfgsVector, LbfgsVector> for LbfgsVector {
    /// The elementwise product.
    fn mul(&self, other: &LbfgsVector) -> LbfgsVector {
        self.zip_map(other, |x, y| x * y)
    }
}

impl ArgminScaledAdd<LbfgsVector, f64, LbfgsVector> for LbfgsVector {
    /// `x + a y`, rounded as `a·y` then the sum (as argmin-math's backends do).
    fn scaled_add(&self, factor: &f64, vec: &LbfgsVector) -> LbfgsVector {
        let a = *factor;
        self.zip_map(vec, move |x, y| x + a * y)
    }
}

impl ArgminSignum for LbfgsVector {
    fn signum(self) -> LbfgsVector {
        self.map(f64::signum)
    }
}

impl ArgminZeroLike for LbfgsVector {
    fn zero_like(&self) -> LbfgsVector {
        Self(vec![0.0; self.0.len()])
    }
}

impl ArgminMinMax for LbfgsVector {
    /// The elementwise minimum.
    fn min(x: &Self, y: &Self) -> Self {
        x.zip_map(y, f64::min)
    }

    /// The elementwise maximum.
    fn max(x: &Self, y: &Self) -> Self {
        x.zip_map(y, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vector(n: usize, seed: f64) -> LbfgsVector {
        LbfgsVector((0..n).map(|i| ((i as f64 + seed) * 0.37).sin()).collect())
    }

    /// The sums as specified, sequentially: chunks of `CHUNK`, `ACCUMULATORS` running terms.
    fn reference_sum(x: &[f64], y: &[f64], f: impl Fn(f64, f64) -> f64) -> f64 {
        x.chunks(CHUNK)
            .zip(y.chunks(CHUNK))
            .map(|(x, y)| {
                let mut acc = [0.0; ACCUMULATORS];
                for (i, (&a, &b)) in x.iter().zip(y).enumerate() {
                    acc[i % ACCUMULATORS] += f(a, b);
                }
                acc.iter().sum::<f64>()
            })
            .sum()
    }

    #[test]
    fn sums_are_the_same_bits_on_any_thread_count_and_close_to_exact() {
        for n in [0, 1, 7, 1000, PARALLEL_FROM - 1, PARALLEL_FROM, 79_443] {
            let (x, y) = (vector(n, 0.0), vector(n, 2.5));
            let on = |threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| (x.dot(&y), x.l2_norm(), x.l1_norm()))
            };
            let one = on(1);
            assert_eq!(one, on(2), "n = {n}");
            assert_eq!(one, on(3), "n = {n}");
            assert_eq!(one.0, reference_sum(&x.0, &y.0, |a, b| a * b), "n = {n}");
            assert_eq!(one.1, reference_sum(&x.0, &x.0, |a, _| a * a).sqrt());
            assert_eq!(one.2, reference_sum(&x.0, &x.0, |a, _| a.abs()));
            let naive: f64 = x.0.iter().zip(&y.0).map(|(a, b)| a * b).sum();
            assert!((one.0 - naive).abs() <= 1e-12 * (1.0 + n as f64), "n = {n}");
        }
    }

    #[test]
    fn elementwise_operations_match_their_definitions() {
        for n in [5, PARALLEL_FROM + 3] {
            let (x, y) = (vector(n, 0.0), vector(n, 1.0));
            let each = |v: &LbfgsVector, f: &dyn Fn(usize) -> f64| {
                v.0.len() == n && v.0.iter().enumerate().all(|(i, &vi)| vi == f(i))
            };
            let (a, b) = (&x.0, &y.0);
            assert!(each(&ArgminAdd::add(&x, &y), &|i| a[i] + b[i]));
            assert!(each(&ArgminAdd::add(&x, &2.0), &|i| a[i] + 2.0));
            assert!(each(&ArgminSub::sub(&x, &y), &|i| a[i] - b[i]));
            assert!(each(&ArgminSub::sub(&x, &2.0), &|i| a[i] - 2.0));
            assert!(each(&ArgminMul::mul(&x, &-3.0), &|i| a[i] * -3.0));
            assert!(each(&ArgminMul::mul(&x, &y), &|i| a[i] * b[i]));
            assert!(each(&x.scaled_add(&0.5, &y), &|i| a[i] + 0.5 * b[i]));
            assert!(each(&x.clone().signum(), &|i| a[i].signum()));
            assert!(each(&x.zero_like(), &|_| 0.0));
            assert!(each(&LbfgsVector::min(&x, &y), &|i| a[i].min(b[i])));
            assert!(each(&LbfgsVector::max(&x, &y), &|i| a[i].max(b[i])));
        }
    }

    #[test]
    fn serialises_as_a_plain_list() {
        let v = LbfgsVector::from_slice(&[1.0, -2.5]);
        let bytes = postcard::to_allocvec(&v).unwrap();
        assert_eq!(bytes, postcard::to_allocvec(&vec![1.0f64, -2.5]).unwrap());
        assert_eq!(postcard::from_bytes::<LbfgsVector>(&bytes).unwrap(), v);
    }
}
