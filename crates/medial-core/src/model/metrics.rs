//! How well a landmark configuration satisfies the medial conditions (docs/method.md §4.4): spoke–normal
//! deviation, spoke-length mismatch, and thickness.
//!
//! A spoke is `s_b = q_b − q_m` (`m = M[b]`), the boundary normal `n̂_b` is the Loop normal
//! `normalize(W¹q × W²q)_b` (docs/method.md §2.4). Degenerate geometry is reported, never hidden: a zero
//! spoke or a degenerate normal gives a NaN angle, an atom of zero mean spoke length a NaN
//! mismatch, and the maxima and means are NaN whenever one of their terms is.

use crate::model::template::MedialTemplate;
use crate::Vec3;

/// Spoke metrics of one landmark configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct SpokeMetrics {
    /// Per boundary point `b`: `acos(ŝ_b · n̂_b)` in degrees (the dot clamped to `[−1, 1]`).
    pub spoke_normal_deg: Vec<f64>,
    /// Per boundary point `b`: the spoke length `|q_b − q_{M[b]}|` (coordinate unit).
    pub spoke_length: Vec<f64>,
    /// Per atom: `(max − min) / mean` of its spoke lengths, a fraction (0 for 1-spoke atoms).
    pub mismatch: Vec<f64>,
    /// Per atom: the local thickness `2 × mean spoke length` (coordinate unit).
    pub thickness: Vec<f64>,
    /// Maximum of [`Self::spoke_normal_deg`], degrees.
    pub max_spoke_normal_deg: f64,
    /// Mean of [`Self::spoke_normal_deg`], degrees.
    pub mean_spoke_normal_deg: f64,
    /// Maximum of [`Self::mismatch`], a fraction (× 100 for %).
    pub max_spoke_mismatch: f64,
}

impl SpokeMetrics {
    /// The metrics of `template`'s structure at landmarks `q` (`k` points, boundary then
    /// medial; pass `template.landmarks()` for the template itself).
    ///
    /// # Panics
    /// If `q.len()` differs from the template's landmark count.
    pub fn compute(template: &MedialTemplate, q: &[Vec3]) -> Self {
        assert_eq!(
            q.len(),
            template.landmark_count(),
            "spoke metrics: one point per landmark"
        );
        let normals = template.tangents().normals(q);
        let spokes: Vec<Vec3> = (0..template.boundary_count())
            .map(|b| q[b] - q[template.atom_landmark(template.medial_index()[b])])
            .collect();
        let spoke_length: Vec<f64> = spokes.iter().map(|s| s.norm()).collect();
        let spoke_normal_deg: Vec<f64> = spokes
            .iter()
            .zip(&spoke_length)
            .zip(&normals)
            .map(|((s, &len), n)| angle_deg(s.dot(n) / len))
            .collect();
        let (mismatch, thickness): (Vec<f64>, Vec<f64>) = (0..template.medial_count())
            .map(|m| atom_mismatch_and_thickness(template.spokes(m), &spoke_length))
            .unzip();
        Self {
            max_spoke_normal_deg: nan_max(&spoke_normal_deg),
            mean_spoke_normal_deg: spoke_normal_deg.iter().sum::<f64>()
                / spoke_normal_deg.len() as f64,
            max_spoke_mismatch: nan_max(&mismatch),
            spoke_normal_deg,
            spoke_length,
            mismatch,
            thickness,
        }
    }
}

/// `acos(cos)` in degrees with `cos` clamped to `[−1, 1]`; NaN stays NaN.
fn angle_deg(cos: f64) -> f64 {
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

/// `((max − min) / mean, 2 mean)` of the spoke lengths of one atom; mismatch 0 for one spoke.
fn atom_mismatch_and_thickness(spokes: &[usize], length: &[f64]) -> (f64, f64) {
    let lengths = spokes.iter().map(|&b| length[b]);
    let mean = lengths.clone().sum::<f64>() / spokes.len() as f64;
    if spokes.len() == 1 {
        return (0.0, 2.0 * mean);
    }
    let max = lengths.clone().fold(f64::NEG_INFINITY, f64::max);
    let min = lengths.fold(f64::INFINITY, f64::min);
    ((max - min) / mean, 2.0 * mean)
}

/// The maximum, NaN if any value is NaN (`f64::max` would skip it); −∞ for no values.
fn nan_max(values: &[f64]) -> f64 {
    values.iter().fold(f64::NEG_INFINITY, |acc, &v| {
        if v.is_nan() || acc.is_nan() {
            f64::NAN
        } else {
            acc.max(v)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::bipyramid;
    use approx::assert_relative_eq;

    #[test]
    fn bipyramid_apexes_and_mismatch() {
        let t = bipyramid(0.5);
        let metrics = SpokeMetrics::compute(&t, t.landmarks());
        // Apex spokes are ±z and the apex normals are ±z.
        assert_relative_eq!(metrics.spoke_normal_deg[0], 0.0, epsilon = 1e-6);
        assert_relative_eq!(metrics.spoke_normal_deg[1], 0.0, epsilon = 1e-6);
        assert_relative_eq!(metrics.thickness[0], 1.0, epsilon = 1e-12);
        assert_eq!(metrics.mismatch[3], 0.0);
        let mut q = t.landmarks().to_vec();
        q[0].z = 0.6;
        let moved = SpokeMetrics::compute(&t, &q);
        assert_relative_eq!(moved.mismatch[0], 0.1 / 0.55, epsilon = 1e-12);
        assert_relative_eq!(moved.max_spoke_mismatch, 0.1 / 0.55, epsilon = 1e-12);
        assert_relative_eq!(moved.thickness[0], 1.1, epsilon = 1e-12);
        // Tilt the top spoke by moving the medial point sideways.
        let tilt = 0.1_f64;
        q[0].z = 0.5;
        q[8].x = -0.5 * tilt.tan();
        let tilted = SpokeMetrics::compute(&t, &q);
        assert_relative_eq!(
            tilted.spoke_normal_deg[0],
            tilt.to_degrees(),
            epsilon = 1e-9
        );
    }

    #[test]
    fn degenerate_spoke_is_reported_as_nan() {
        let t = bipyramid(0.5);
        let mut q = t.landmarks().to_vec();
        q[8] = q[0];
        let metrics = SpokeMetrics::compute(&t, &q);
        assert!(metrics.spoke_normal_deg[0].is_nan());
        assert!(metrics.max_spoke_normal_deg.is_nan() && metrics.mean_spoke_normal_deg.is_nan());
        assert_eq!(nan_max(&[1.0, 3.0, 2.0]), 3.0);
    }
}
