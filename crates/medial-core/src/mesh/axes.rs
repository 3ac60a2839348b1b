//! Principal axes of a point set: the frame a template's size, thickness and long axis are
//! measured in (the kernel width of a fit, the twist and bend of a synthetic warp).

use crate::mesh::{centroid_and_covariance, Bounds};
use crate::{Error, Result, Vec3};
use nalgebra::{Matrix3, Rotation3};

/// The principal axes of a point set, as [`crate::synth::Warp::bending`] and
/// [`crate::fit::plan`] use them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipalAxes {
    /// Centre of the bounding box of the points in the frame, `mean + F·(lo + hi)/2`, mm.
    pub centre: Vec3,
    /// Right-handed orthonormal frame whose columns are the eigenvectors of the points'
    /// covariance: z of the largest variance (the long axis), x of the smallest (the thickness
    /// direction of a sheet), `y = z × x`. Each of x and z has its largest-magnitude
    /// component positive (a deterministic choice of sign).
    pub frame: Rotation3<f64>,
    /// Extent `hi − lo` of the points along x, y, z of the frame, mm.
    pub extent: Vec3,
    /// Standard deviations of the points along x, y, z of the frame (square roots of the
    /// covariance eigenvalues), mm.
    pub std_dev: Vec3,
}

impl PrincipalAxes {
    /// The principal axes of `points`: covariance `Σ (p − p̄)(p − p̄)ᵀ / n` about the mean `p̄`,
    /// its eigenvectors as the frame, the bounding box in that frame.
    ///
    /// Errors: `NonFinite` for a non-finite coordinate; `InvalidParameter` for no points or
    /// points without extent along their long axis (all equal).
    pub fn of(points: &[Vec3]) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinite(format!(
                "point {i} is {:?}",
                points[i].as_slice()
            )));
        }
        if points.is_empty() {
            return Err(Error::InvalidParameter(
                "principal axes need at least one point".into(),
            ));
        }
        let (mean, covariance) = centroid_and_covariance(points);
        let eigen = covariance.symmetric_eigen();
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let axis = |k: usize| positive_sign(eigen.eigenvectors.column(order[k]).into_owned());
        let (x, z) = (axis(0), axis(2));
        let y = z.cross(&x).normalize();
        let frame = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[y.cross(&z), y, z]));
        let local: Vec<Vec3> = points
            .iter()
            .map(|p| frame.inverse_transform_vector(&(p - mean)))
            .collect();
        let bounds = Bounds::of(&local).unwrap_or(Bounds {
            min: Vec3::zeros(),
            max: Vec3::zeros(),
        });
        let extent = bounds.extent();
        if extent.z <= 0.0 {
            return Err(Error::InvalidParameter(format!(
                "the {} points have no extent along their long axis (all equal)",
                points.len()
            )));
        }
        let variance = Vec3::from_fn(|k, _| eigen.eigenvalues[order[k]].max(0.0));
        Ok(Self {
            centre: mean + frame * bounds.centre(),
            frame,
            extent,
            std_dev: variance.map(f64::sqrt),
        })
    }
}

/// `v` or `−v`, whichever has its largest-magnitude component positive.
fn positive_sign(v: Vec3) -> Vec3 {
    if v[v.iamax()] < 0.0 {
        -v
    } else {
        v
    }
}
