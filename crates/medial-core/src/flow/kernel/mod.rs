//! The Gaussian kernel `η(r) = exp(−r² / (2σ²))` and its sums over pairs of landmarks.
//!
//! [`GaussianKernel`] and the exponential [`exp_nonpositive`] are here; `sweep` computes the
//! sums `S_c(i) = Σ_{j ≠ i} K_ij t_c(i, j)` over all pairs of landmarks, or only over the
//! pairs nearer than the kernel's cutoff radius when it has a tolerance
//! ([`GaussianKernel::truncated`]), tile by tile in parallel and bit-identical whatever the
//! thread count; `field` the velocity `v(x) = Σ_j K(x, q_j) u_j` of the landmarks at any point
//! of space; `lanes` holds the SIMD arithmetic of its inner loops, which handle `LANES`
//! pairs at once, with the exponential written out as a polynomial so that it runs in SIMD
//! registers too.
//!
//! Arithmetic per pair (from the code; a fused multiply-add counts as 2 flops): the distance
//! 8 flops (3 subtractions, `|d|²` 1 multiplication + 2 multiply-adds), the exponential 33
//! (2 multiply-adds and 3 operations for the reduction, 11 multiply-adds and 2 multiplications
//! for the polynomial, 1 multiplication by `2^k`; plus a minimum and 2 integer operations),
//! then the terms: 12 for the flow's velocity (6 multiply-adds), 36 for its adjoint (2 dot
//! products 11, `K s` 1, 12 multiply-adds 24). So 53 flops per pair and step forward and 77
//! backward, in 31 and 44 SIMD floating-point instructions per `LANES` pairs.

mod field;
mod lanes;
mod sweep;

use crate::{Error, Result};

/// Pairs handled together by the inner loops: one AVX-512 register of `f64`, two AVX2 ones.
pub(crate) const LANES: usize = 8;

pub(crate) use field::{map_points, PointMap, Sources};
pub(crate) use lanes::{F64Lanes, Isa, Real};
pub(crate) use sweep::{Layout, PairSweep, PairTerms};

/// Largest kernel tolerance ε: below `e^{−1/2}` the cutoff radius exceeds σ, which the bound
/// on the adjoint's sums needs (see the `sweep` module).
pub const MAX_TOLERANCE: f64 = 0.5;

/// Most points [`GaussianKernel::near_pair_fraction`] compares pairwise.
pub const NEAR_PAIR_SAMPLE: usize = 4096;

/// Gaussian kernel of width `σ` (same unit as the coordinates), exact or truncated: with a
/// tolerance ε > 0, the sums over pairs skip pairs whose kernel value is below ε.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianKernel {
    sigma: f64,
    /// `1 / (2σ²)`.
    half_inv_sigma2: f64,
    /// ε; 0 for the exact kernel.
    tolerance: f64,
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
            tolerance: 0.0,
        })
    }

    /// The kernel with the tolerance `ε ∈ [0, MAX_TOLERANCE]` (0: exact): sums over pairs
    /// skip only pairs farther apart than [`Self::cutoff_radius`], whose kernel value is below
    /// ε, and the error of a sum `Σ_j K_ij t_ij` is then at most `ε Σ_j |t_ij|`.
    pub fn truncated(self, tolerance: f64) -> Result<Self> {
        if !(0.0..=MAX_TOLERANCE).contains(&tolerance) {
            return Err(Error::InvalidParameter(format!(
                "kernel tolerance must be a number in [0, {MAX_TOLERANCE}], got {tolerance}"
            )));
        }
        Ok(Self { tolerance, ..self })
    }

    /// The width `σ`.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The tolerance ε (0: exact).
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The distance beyond which the kernel is below the tolerance: `r = σ √(2 ln(1/ε))`,
    /// `η(r) = ε`; ∞ for the exact kernel.
    pub fn cutoff_radius(&self) -> f64 {
        if self.tolerance > 0.0 {
            self.sigma * (2.0 * (1.0 / self.tolerance).ln()).sqrt()
        } else {
            f64::INFINITY
        }
    }

    /// The fraction of the unordered pairs of `points` nearer than [`Self::cutoff_radius`]:
    /// what a truncated sweep over them cannot skip (1 for the exact kernel; 1 for fewer than
    /// two points). Of more than [`NEAR_PAIR_SAMPLE`] points an evenly strided subset of about
    /// that many is counted (O(n²) over at most that many).
    pub fn near_pair_fraction(&self, points: &[crate::Vec3]) -> f64 {
        let stride = points.len().div_ceil(NEAR_PAIR_SAMPLE).max(1);
        let sample: Vec<_> = points.iter().step_by(stride).collect();
        let n = sample.len();
        if n < 2 || self.tolerance == 0.0 {
            return 1.0;
        }
        let r2 = self.cutoff_radius().powi(2);
        let near: usize = (0..n)
            .map(|i| {
                (i + 1..n)
                    .filter(|&j| (sample[i] - sample[j]).norm_squared() <= r2)
                    .count()
            })
            .sum();
        near as f64 / (n * (n - 1) / 2) as f64
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
    let r2 = r * r;
    let r4 = r2 * r2;
    exp_quad(r, r2, 2)
        .mul_add(r4, exp_quad(r, r2, 1))
        .mul_add(r4, exp_quad(r, r2, 0))
}

/// The coefficients `c_n` of `e^r ≈ Σ c_n rⁿ` ([`exp_polynomial`]).
const EXP_COEFFICIENTS: [f64; 12] = [
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

/// `(c_{4m} + c_{4m+1} r) + (c_{4m+2} + c_{4m+3} r) r²`. Functions rather than closures, so
/// that they are always inlined into the SIMD tile bodies and the intrinsics under them too
/// (closures are inlined at the compiler's discretion, which varied with unrelated changes).
#[inline(always)]
fn exp_quad<V: Real>(r: V, r2: V, m: usize) -> V {
    exp_pair(r, 2 * m + 1).mul_add(r2, exp_pair(r, 2 * m))
}

/// `c_{2m} + c_{2m+1} r`.
#[inline(always)]
fn exp_pair<V: Real>(r: V, m: usize) -> V {
    r.mul_add(
        V::splat(EXP_COEFFICIENTS[2 * m + 1]),
        V::splat(EXP_COEFFICIENTS[2 * m]),
    )
}

#[cfg(test)]
mod tests {
    use super::lanes::Isa;
    use super::*;

    fn ulps(a: f64, b: f64) -> f64 {
        ((a - b) / b.abs().max(f64::MIN_POSITIVE)).abs() / f64::EPSILON
    }

    /// Arguments `0 … −700`, denser near 0.
    fn exponents() -> impl Iterator<Item = f64> {
        (0..200_000).map(|i| -700.0 * (i as f64 / 200_000.0).powi(2))
    }

    #[test]
    fn near_pair_fraction_counts_the_pairs_within_the_cutoff() {
        // Points 1 mm apart on a line; σ = 1, ε = e^{−3.125}: cutoff 2.5 mm, so pairs up to
        // two apart are near: (n − 1) + (n − 2) of n(n − 1)/2.
        let points: Vec<_> = (0..10)
            .map(|i| crate::Vec3::new(i as f64, 0.0, 0.0))
            .collect();
        let kernel = GaussianKernel::new(1.0).unwrap();
        assert_eq!(kernel.near_pair_fraction(&points), 1.0);
        let truncated = kernel.truncated((-3.125f64).exp()).unwrap();
        assert!((truncated.cutoff_radius() - 2.5).abs() < 1e-12);
        let fraction = truncated.near_pair_fraction(&points);
        assert!((fraction - 17.0 / 45.0).abs() < 1e-12, "{fraction}");
        assert_eq!(truncated.near_pair_fraction(&points[..1]), 1.0);
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
    fn worst_lane_error<V: F64Lanes>() -> f64 {
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
        if Isa::Avx2Fma.is_supported() {
            // The CPU has AVX2 and FMA, as `Avx2Fma` values require.
            let worst = worst_lane_error::<lanes::Avx2Fma>();
            assert!(worst < 4.0, "AVX2: worst error {worst} ulp");
        }
        #[cfg(target_arch = "x86_64")]
        if Isa::Avx512.is_supported() {
            // The CPU has AVX-512F, as `Avx512` values require.
            let worst = worst_lane_error::<lanes::Avx512>();
            assert!(worst < 4.0, "AVX-512: worst error {worst} ulp");
        }
    }

    #[test]
    fn kernel_rejects_bad_width() {
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(GaussianKernel::new(s).is_err());
        }
    }

    #[test]
    fn cutoff_radius_is_where_the_kernel_meets_the_tolerance() {
        let kernel = GaussianKernel::new(4.0).unwrap();
        assert_eq!(kernel.cutoff_radius(), f64::INFINITY);
        for eps in [1e-12, 1e-10, 1e-3, MAX_TOLERANCE] {
            let k = kernel.truncated(eps).unwrap();
            let r = k.cutoff_radius();
            assert!(r > k.sigma());
            let at_r = k.of_squared_distance(r * r);
            assert!(
                (at_r - eps).abs() <= 1e-12 * eps,
                "η(r) = {at_r}, ε = {eps}"
            );
        }
        for eps in [-1e-3, 0.6, f64::NAN, f64::INFINITY] {
            assert!(kernel.truncated(eps).is_err(), "ε = {eps}");
        }
    }
}
