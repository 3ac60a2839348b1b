//! SIMD lanes: lane-wise IEEE arithmetic on [`LANES`] numbers at once, portable, on two AVX2
//! registers with fused multiply-adds or on one AVX-512 register, and the choice between them
//! at run time ([`Isa`]). The two SIMD implementations do the same IEEE operations lane by
//! lane (fused multiply-adds, the same minimum) and so give the same bits.

use super::LANES;
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

/// [`LANES`] lanes of `f64`.
pub(crate) trait F64Lanes: Real {
    /// `v[0 … LANES − 1]`.
    fn load(v: &[f64]) -> Self;
    /// `v[0 … LANES − 1] = self`.
    fn store(self, v: &mut [f64]);
    /// Whether every lane is greater than `x` (false where a lane is NaN).
    fn all_greater(self, x: f64) -> bool;

    /// The lanes as an array.
    #[inline(always)]
    fn to_array(self) -> [f64; LANES] {
        let mut a = [0.0; LANES];
        self.store(&mut a);
        a
    }

    /// Lanes from an array.
    #[inline(always)]
    fn from_array(a: [f64; LANES]) -> Self {
        Self::load(&a)
    }

    /// `v[0 … LANES − 1] += self·a` (see [`Real::mul_add`]).
    #[inline(always)]
    fn mul_add_to(self, a: Self, v: &mut [f64]) {
        self.mul_add(a, Self::load(v)).store(v);
    }

    /// `v[0 … LANES − 1] −= self·a` (see [`Real::neg_mul_add`]).
    #[inline(always)]
    fn neg_mul_add_to(self, a: Self, v: &mut [f64]) {
        self.neg_mul_add(a, Self::load(v)).store(v);
    }

    /// The sum of the lanes in a fixed order: `((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7))`.
    #[inline(always)]
    fn sum(self) -> f64 {
        let l = self.to_array();
        ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]))
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

/// The lanes in an array, for any CPU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Portable([f64; LANES]);

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
        Self([x; LANES])
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

impl F64Lanes for Portable {
    #[inline(always)]
    fn load(v: &[f64]) -> Self {
        let mut a = [0.0; LANES];
        a.copy_from_slice(&v[..LANES]);
        Self(a)
    }

    #[inline(always)]
    fn store(self, v: &mut [f64]) {
        v[..LANES].copy_from_slice(&self.0);
    }

    #[inline(always)]
    fn all_greater(self, x: f64) -> bool {
        self.0.iter().all(|&l| l > x)
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{Avx2Fma, Avx512};

// The AVX-512 intrinsics are stable since Rust 1.89, after the workspace's MSRV: older
// compilers cannot build this module (raising the MSRV would bring newer lints everywhere).
#[cfg(target_arch = "x86_64")]
#[allow(clippy::incompatible_msrv)]
mod x86 {
    use super::{F64Lanes, Real, LANES};
    use std::arch::x86_64::*;
    use std::ops::{Mul, Sub};

    /// The lanes in two AVX registers, with fused multiply-adds.
    ///
    /// Invariant: values of this type exist only on CPUs with AVX2 and FMA. The crate
    /// creates them only in code reached through `sweep_tile_avx2_fma` and
    /// `map_chunk_avx2_fma` (and in tests),
    /// after the run-time feature check; every `unsafe` block below relies on this.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Avx2Fma([__m256d; 2]);

    impl Avx2Fma {
        /// `f` on each of the two registers.
        #[inline(always)]
        fn map(self, f: impl Fn(__m256d) -> __m256d) -> Self {
            // Not `array::map`: it is not always inlined, and then neither are the intrinsics
            // under it (they can only be inlined into code compiled for AVX2 and FMA).
            Self([f(self.0[0]), f(self.0[1])])
        }

        /// `f` on the registers of `self` and `a` pairwise.
        #[inline(always)]
        fn zip(self, a: Self, f: impl Fn(__m256d, __m256d) -> __m256d) -> Self {
            Self([f(self.0[0], a.0[0]), f(self.0[1], a.0[1])])
        }

        /// `f` on the registers of `self`, `a` and `b` by threes.
        #[inline(always)]
        fn zip3(self, a: Self, b: Self, f: impl Fn(__m256d, __m256d, __m256d) -> __m256d) -> Self {
            Self([f(self.0[0], a.0[0], b.0[0]), f(self.0[1], a.0[1], b.0[1])])
        }
    }

    impl Sub for Avx2Fma {
        type Output = Self;
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            // SAFETY: AVX2 is available (type invariant).
            self.zip(other, |a, b| unsafe { _mm256_sub_pd(a, b) })
        }
    }

    impl Mul for Avx2Fma {
        type Output = Self;
        #[inline(always)]
        fn mul(self, other: Self) -> Self {
            // SAFETY: AVX2 is available (type invariant).
            self.zip(other, |a, b| unsafe { _mm256_mul_pd(a, b) })
        }
    }

    impl Real for Avx2Fma {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            // SAFETY: AVX2 is available (type invariant).
            let r = unsafe { _mm256_set1_pd(x) };
            Self([r, r])
        }

        #[inline(always)]
        fn at_most(self, hi: f64) -> Self {
            // `min_pd(a, b)` returns b where a < b fails, which includes a NaN b.
            // SAFETY: AVX2 is available (type invariant).
            self.map(|x| unsafe { _mm256_min_pd(_mm256_set1_pd(hi), x) })
        }

        #[inline(always)]
        fn exponent_scale(self) -> Self {
            // SAFETY: AVX2 is available (type invariant).
            self.map(|x| unsafe {
                let bits = _mm256_add_epi64(_mm256_castpd_si256(x), _mm256_set1_epi64x(1023));
                _mm256_castsi256_pd(_mm256_slli_epi64::<52>(bits))
            })
        }

        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            // SAFETY: FMA is available (type invariant).
            self.zip3(a, b, |x, a, b| unsafe { _mm256_fmadd_pd(x, a, b) })
        }

        #[inline(always)]
        fn neg_mul_add(self, a: Self, b: Self) -> Self {
            // SAFETY: FMA is available (type invariant).
            self.zip3(a, b, |x, a, b| unsafe { _mm256_fnmadd_pd(x, a, b) })
        }

        #[inline(always)]
        fn neg_mul_sub(self, a: Self, b: Self) -> Self {
            // SAFETY: FMA is available (type invariant).
            self.zip3(a, b, |x, a, b| unsafe { _mm256_fnmsub_pd(x, a, b) })
        }
    }

    impl F64Lanes for Avx2Fma {
        #[inline(always)]
        fn load(v: &[f64]) -> Self {
            let v = &v[..LANES];
            // SAFETY: `v` holds 8 numbers; AVX2 is available (type invariant).
            unsafe {
                Self([
                    _mm256_loadu_pd(v.as_ptr()),
                    _mm256_loadu_pd(v[4..].as_ptr()),
                ])
            }
        }

        #[inline(always)]
        fn store(self, v: &mut [f64]) {
            let v = &mut v[..LANES];
            // SAFETY: `v` holds 8 numbers; AVX2 is available (type invariant).
            unsafe {
                _mm256_storeu_pd(v.as_mut_ptr(), self.0[0]);
                _mm256_storeu_pd(v[4..].as_mut_ptr(), self.0[1]);
            }
        }

        #[inline(always)]
        fn all_greater(self, x: f64) -> bool {
            // SAFETY: AVX2 is available (type invariant).
            unsafe {
                let x = _mm256_set1_pd(x);
                let gt = _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_GT_OQ>(self.0[0], x),
                    _mm256_cmp_pd::<_CMP_GT_OQ>(self.0[1], x),
                );
                _mm256_movemask_pd(gt) == 0b1111
            }
        }
    }

    /// The lanes in one AVX-512 register (fused multiply-adds are part of AVX-512F).
    ///
    /// Invariant: values of this type exist only on CPUs with AVX-512F. The crate creates them
    /// only in code reached through `sweep_tile_avx512` (and in tests), after the run-time
    /// feature check; every `unsafe` block below relies on this.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Avx512(__m512d);

    impl Sub for Avx512 {
        type Output = Self;
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_sub_pd(self.0, other.0) })
        }
    }

    impl Mul for Avx512 {
        type Output = Self;
        #[inline(always)]
        fn mul(self, other: Self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_mul_pd(self.0, other.0) })
        }
    }

    impl Real for Avx512 {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_set1_pd(x) })
        }

        #[inline(always)]
        fn at_most(self, hi: f64) -> Self {
            // As `vminpd` on AVX2: the second operand where `a < b` fails (NaN stays NaN).
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_min_pd(_mm512_set1_pd(hi), self.0) })
        }

        #[inline(always)]
        fn exponent_scale(self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            unsafe {
                let bits = _mm512_add_epi64(_mm512_castpd_si512(self.0), _mm512_set1_epi64(1023));
                Self(_mm512_castsi512_pd(_mm512_slli_epi64::<52>(bits)))
            }
        }

        #[inline(always)]
        fn mul_add(self, a: Self, b: Self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_fmadd_pd(self.0, a.0, b.0) })
        }

        #[inline(always)]
        fn neg_mul_add(self, a: Self, b: Self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_fnmadd_pd(self.0, a.0, b.0) })
        }

        #[inline(always)]
        fn neg_mul_sub(self, a: Self, b: Self) -> Self {
            // SAFETY: AVX-512F is available (type invariant).
            Self(unsafe { _mm512_fnmsub_pd(self.0, a.0, b.0) })
        }
    }

    impl F64Lanes for Avx512 {
        #[inline(always)]
        fn load(v: &[f64]) -> Self {
            let v = &v[..LANES];
            // SAFETY: `v` holds 8 numbers; AVX-512F is available (type invariant).
            Self(unsafe { _mm512_loadu_pd(v.as_ptr()) })
        }

        #[inline(always)]
        fn store(self, v: &mut [f64]) {
            let v = &mut v[..LANES];
            // SAFETY: `v` holds 8 numbers; AVX-512F is available (type invariant).
            unsafe { _mm512_storeu_pd(v.as_mut_ptr(), self.0) }
        }

        #[inline(always)]
        fn all_greater(self, x: f64) -> bool {
            // SAFETY: AVX-512F is available (type invariant).
            unsafe { _mm512_cmp_pd_mask::<_CMP_GT_OQ>(self.0, _mm512_set1_pd(x)) == 0xff }
        }
    }
}

/// The implementations of the inner loops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// Plain Rust on arrays of lanes, for any CPU.
    Portable,
    /// Two AVX2 registers and fused multiply-adds.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    Avx2Fma,
    /// One AVX-512 register (AVX-512F, which has fused multiply-adds).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    Avx512,
}

impl Isa {
    /// Every implementation, slowest first.
    pub(crate) const ALL: [Isa; 3] = [Isa::Portable, Isa::Avx2Fma, Isa::Avx512];

    /// The fastest implementation the running CPU supports.
    pub(crate) fn best() -> Self {
        (Self::ALL.into_iter().rev())
            .find(|isa| isa.is_supported())
            .unwrap_or(Isa::Portable)
    }

    /// Whether the running CPU supports `self` (the detection is cached by the standard
    /// library: a load and a test).
    pub(crate) fn is_supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            match self {
                Isa::Portable => true,
                Isa::Avx2Fma => has!("avx2") && has!("fma"),
                Isa::Avx512 => has!("avx512f"),
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Isa::Portable
        }
    }
}
