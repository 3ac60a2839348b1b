//! The exact Euclidean distance transform of a binary mask with its feature transform: for
//! every voxel, the nearest background voxel and the squared distance to it (mm²), on a grid of
//! anisotropic spacing.
//!
//! Separable, after Felzenszwalb & Huttenlocher ("Distance transforms of sampled functions",
//! 2012): along axis `a` the squared distance is the lower envelope
//! `D_a(i) = min_q D_{a−1}(q) + (s_a (i − q))²` of parabolas rooted at the previous pass's
//! values, computed in linear time per grid line; the feature (the background voxel that
//! attains the minimum) is carried along with the minimising `q`. The result is exact: the
//! minimum over the background of `Σ_a (s_a Δ_a)²` splits into three nested one-dimensional
//! minima. Hand-written because no maintained pure-Rust crate computes a 3-D anisotropic
//! distance transform with its feature transform (the `distance-transform` crate is 2-D and
//! isotropic and gives no features).

use rayon::prelude::*;

use crate::{Error, Result};

/// No background voxel on the grid (every voxel inside).
pub const NO_FEATURE: u32 = u32::MAX;

/// The distance and feature transform of a mask (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureTransform {
    dims: [usize; 3],
    squared: Vec<f64>,
    feature: Vec<u32>,
}

impl FeatureTransform {
    /// The transform of `inside` (x fastest, `dims` voxels of `spacing` mm along i, j, k):
    /// every voxel's nearest voxel with `inside == false` (itself when it is background).
    ///
    /// Errors: `ShapeMismatch` when `inside` is not `nx·ny·nz` long; `InvalidParameter` for a
    /// non-positive spacing or a grid of 2³² voxels or more (features are 32-bit).
    pub fn new(inside: &[bool], dims: [usize; 3], spacing: [f64; 3]) -> Result<Self> {
        let count = dims.iter().product::<usize>();
        if inside.len() != count {
            return Err(Error::ShapeMismatch {
                what: "mask voxels of a distance transform".into(),
                expected: count,
                found: inside.len(),
            });
        }
        if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::InvalidParameter(format!(
                "voxel spacing must be positive, got {spacing:?} mm"
            )));
        }
        if count >= NO_FEATURE as usize {
            return Err(Error::InvalidParameter(format!(
                "a distance transform of {count} voxels is too large (at most 2³² − 1)"
            )));
        }
        let mut squared: Vec<f64> = inside
            .iter()
            .map(|&v| if v { f64::INFINITY } else { 0.0 })
            .collect();
        let mut feature: Vec<u32> = (0..count as u32)
            .map(|n| if inside[n as usize] { NO_FEATURE } else { n })
            .collect();
        for (axis, &s) in spacing.iter().enumerate() {
            envelope_pass(&mut squared, &mut feature, dims, axis, s);
        }
        Ok(Self {
            dims,
            squared,
            feature,
        })
    }

    /// The grid size.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Squared distance (mm²) from voxel `n` to its nearest background voxel; `∞` without one.
    pub fn squared_distance(&self, n: usize) -> f64 {
        self.squared[n]
    }

    /// The linear index of the nearest background voxel of voxel `n`, [`NO_FEATURE`] without
    /// one.
    pub fn feature(&self, n: usize) -> u32 {
        self.feature[n]
    }
}

/// The linear indices of the grid line along `axis` through the line number `line` (lines
/// numbered over the two other axes, the lower one fastest).
fn line_indices(dims: [usize; 3], axis: usize, line: usize) -> impl Iterator<Item = usize> {
    let stride = [1, dims[0], dims[0] * dims[1]];
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let start = (line % dims[a]) * stride[a] + (line / dims[a]) * stride[b];
    (0..dims[axis]).map(move |i| start + i * stride[axis])
}

/// One separable pass along `axis`: every grid line replaced by the lower envelope of its
/// parabolas. Lines in parallel; each line's result depends on that line only.
fn envelope_pass(squared: &mut [f64], feature: &mut [u32], dims: [usize; 3], axis: usize, s: f64) {
    let lines = dims.iter().product::<usize>() / dims[axis];
    let results: Vec<Vec<(f64, u32)>> = (0..lines)
        .into_par_iter()
        .map(|line| {
            let values: Vec<(f64, u32)> = line_indices(dims, axis, line)
                .map(|n| (squared[n], feature[n]))
                .collect();
            lower_envelope(&values, s)
        })
        .collect();
    for (line, result) in results.into_iter().enumerate() {
        for (n, (d, f)) in line_indices(dims, axis, line).zip(result) {
            squared[n] = d;
            feature[n] = f;
        }
    }
}

/// `out(i) = min_q g(q) + (s (i − q))²` with the feature of the minimising `q` (the first on
/// ties), over the finite `g(q)`; `(∞, NO_FEATURE)` where none is finite. Linear time.
fn lower_envelope(values: &[(f64, u32)], s: f64) -> Vec<(f64, u32)> {
    let n = values.len();
    let s2 = s * s;
    // Roots of the parabolas in the envelope and the boundaries between them (in index units).
    let mut roots: Vec<usize> = Vec::with_capacity(n);
    let mut starts: Vec<f64> = Vec::with_capacity(n);
    let intersection = |p: usize, q: usize| {
        let (gp, gq) = (values[p].0, values[q].0);
        ((gq + s2 * (q * q) as f64) - (gp + s2 * (p * p) as f64)) / (2.0 * s2 * (q - p) as f64)
    };
    for q in (0..n).filter(|&q| values[q].0.is_finite()) {
        while let Some(&p) = roots.last() {
            let x = intersection(p, q);
            if x <= *starts.last().expect("one start per root") {
                roots.pop();
                starts.pop();
            } else {
                starts.push(x);
                break;
            }
        }
        if roots.is_empty() {
            starts.clear();
            starts.push(f64::NEG_INFINITY);
        }
        roots.push(q);
    }
    if roots.is_empty() {
        return vec![(f64::INFINITY, NO_FEATURE); n];
    }
    let mut k = 0;
    (0..n)
        .map(|i| {
            while k + 1 < roots.len() && starts[k + 1] < i as f64 {
                k += 1;
            }
            let q = roots[k];
            let d = i as f64 - q as f64;
            (values[q].0 + s2 * d * d, values[q].1)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The transform by brute force: every voxel against every background voxel.
    fn brute_force(inside: &[bool], dims: [usize; 3], spacing: [f64; 3]) -> Vec<f64> {
        let coords = |n: usize| {
            [
                (n % dims[0]) as f64 * spacing[0],
                ((n / dims[0]) % dims[1]) as f64 * spacing[1],
                (n / (dims[0] * dims[1])) as f64 * spacing[2],
            ]
        };
        (0..inside.len())
            .map(|n| {
                let p = coords(n);
                (0..inside.len())
                    .filter(|&m| !inside[m])
                    .map(|m| {
                        let q = coords(m);
                        (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Distances equal the brute-force minimum and every feature attains it.
        #[test]
        fn matches_brute_force(
            dims in prop::array::uniform3(1usize..7),
            spacing in prop::array::uniform3(0.3f64..2.0),
            bits in prop::collection::vec(prop::bool::weighted(0.7), 216),
        ) {
            let count = dims.iter().product::<usize>();
            let inside = &bits[..count];
            let ft = FeatureTransform::new(inside, dims, spacing).unwrap();
            let expected = brute_force(inside, dims, spacing);
            for (n, &want) in expected.iter().enumerate() {
                let d = ft.squared_distance(n);
                prop_assert!(d == want || (d - want).abs() < 1e-9 * (1.0 + d));
                let f = ft.feature(n);
                if want.is_finite() {
                    prop_assert!(!inside[f as usize]);
                    let mut only = vec![true; count];
                    only[f as usize] = false;
                    let via_feature = brute_force(&only, dims, spacing)[n];
                    prop_assert!((via_feature - d).abs() < 1e-9 * (1.0 + d));
                } else {
                    prop_assert_eq!(f, NO_FEATURE);
                }
            }
        }
    }

    #[test]
    fn refuses_a_wrong_length_and_bad_spacing() {
        assert!(FeatureTransform::new(&[true; 5], [2, 2, 1], [1.0; 3]).is_err());
        assert!(FeatureTransform::new(&[true; 4], [2, 2, 1], [1.0, 0.0, 1.0]).is_err());
    }
}
