//! Initial alignment: a similarity `p ↦ s R p + t` that carries a template's interior onto a
//! segmentation's foreground, found from their moments and chosen by voxel overlap. It starts a
//! fit where the flow has only the shape differences left to follow (the paper initialises by
//! an affine SSD stage).
//!
//! With `V`, `c` and `Σ` the volume (mm³), centroid and covariance of each binary shape (voxel
//! centres in world mm, each voxel weighing its volume; the template rasterized on a grid of the
//! image's smallest voxel size):
//! - `s = (V_img / V_tmpl)^{1/3}`,
//! - `R` is the identity, or `E_img D E_tmplᵀ` for the proper eigenvector frames `E` of the two
//!   covariances (eigenvalues in increasing order) and each of the four sign matrices
//!   `D = diag(±1, ±1, ±1)` with `det D = 1` (the principal axes fix `R` up to these signs),
//! - `t = c_img − s R c_tmpl`,
//!
//! and the candidate whose moved boundary overlaps the foreground best (voxel Dice on the
//! image's grid) wins. Against corresponding points, [`similarity_between`] is the least-squares
//! similarity (Umeyama 1991). A similarity keeps a medial model medial, so the template can
//! follow it exactly.

use crate::image::rasterize::{grid_around, rasterize, voxel_dice};
use crate::image::Volume;
use crate::mesh::{centroid_and_covariance, TriMesh};
use crate::{Error, Result, Vec3};
use nalgebra::{Matrix3, Matrix4, SymmetricEigen};

/// Volume, centroid and covariance of the foreground (values > ½) of a binary volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Moments {
    /// Foreground volume, mm³.
    pub volume: f64,
    /// Centroid, world mm.
    pub centroid: Vec3,
    /// Covariance of the foreground's points, mm².
    pub covariance: Matrix3<f64>,
}

impl Moments {
    /// The moments of `mask`'s foreground; an error when it has none.
    pub fn of(mask: &Volume) -> Result<Self> {
        let [nx, ny, _] = mask.dims();
        let points: Vec<Vec3> = mask
            .data()
            .iter()
            .enumerate()
            .filter(|(_, &v)| v > 0.5)
            .map(|(i, _)| mask.voxel_centre([i % nx, (i / nx) % ny, i / (nx * ny)]))
            .collect();
        if points.is_empty() {
            return Err(Error::InvalidVolume(
                "the image has no foreground to align to".into(),
            ));
        }
        let (centroid, covariance) = centroid_and_covariance(&points);
        Ok(Self {
            volume: points.len() as f64 * mask.voxel_volume(),
            centroid,
            covariance,
        })
    }

    /// The eigenvectors of the covariance as the columns of a rotation (eigenvalues in
    /// increasing order; the last column flipped if needed so that the determinant is +1).
    fn frame(&self) -> Matrix3<f64> {
        let eigen = SymmetricEigen::new(self.covariance);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let mut frame =
            Matrix3::from_columns(&order.map(|k| eigen.eigenvectors.column(k).into_owned()));
        if frame.determinant() < 0.0 {
            frame.column_mut(2).neg_mut();
        }
        frame
    }
}

/// The chosen similarity and how much it helps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// The similarity as a 4×4 world matrix (mm).
    pub matrix: Matrix4<f64>,
    /// Its scale `s`.
    pub scale: f64,
    /// Voxel Dice of the template boundary against the foreground before alignment.
    pub voxel_dice_before: f64,
    /// Voxel Dice after.
    pub voxel_dice: f64,
}

/// The similarity that best carries the closed template boundary `boundary` onto the
/// foreground of the binary `mask` (see the module doc).
pub fn align_similarity(boundary: &TriMesh, mask: &Volume) -> Result<Alignment> {
    let image = Moments::of(mask)?;
    let spacing = mask.spacing().min();
    let (dims, grid) = grid_around(boundary, spacing, 2.0 * spacing)?;
    let template = Moments::of(&rasterize(boundary, dims, grid)?)?;
    let scale = (image.volume / template.volume).cbrt();
    let (e_img, e_tmpl) = (image.frame(), template.frame());
    let signs = [
        [1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ];
    let rotations = std::iter::once(Matrix3::identity()).chain(
        signs
            .iter()
            .map(|d| e_img * Matrix3::from_diagonal(&Vec3::from(*d)) * e_tmpl.transpose()),
    );
    let voxel_dice_before = voxel_dice(boundary, mask)?;
    let mut best: Option<(Matrix4<f64>, f64)> = None;
    for r in rotations {
        let linear = r * scale;
        let mut matrix = linear.to_homogeneous();
        let shift = image.centroid - linear * template.centroid;
        matrix.fixed_view_mut::<3, 1>(0, 3).copy_from(&shift);
        let moved: Vec<Vec3> = boundary
            .points()
            .iter()
            .map(|p| linear * p + shift)
            .collect();
        let dice = voxel_dice(&TriMesh::new(moved, boundary.triangles().to_vec())?, mask)?;
        if best.map_or(true, |(_, d)| dice > d) {
            best = Some((matrix, dice));
        }
    }
    let (matrix, voxel_dice) = best.expect("the identity is a candidate");
    Ok(Alignment {
        matrix,
        scale,
        voxel_dice_before,
        voxel_dice,
    })
}

/// The similarity `p ↦ s R p + t` minimising `Σ |s R p_i + t − q_i|²` over corresponding
/// points (Umeyama 1991): with centred points `p̃`, `q̃` and `H = Σ q̃ p̃ᵀ = U S Vᵀ`,
/// `R = U diag(1, 1, det(U Vᵀ)) Vᵀ`, `s = tr(S D) / Σ |p̃|²`, `t = q̄ − s R p̄`.
pub fn similarity_between(p: &[Vec3], q: &[Vec3]) -> Result<Matrix4<f64>> {
    if p.len() != q.len() || p.len() < 3 {
        return Err(Error::ShapeMismatch {
            what: "corresponding points of a similarity (at least 3)".into(),
            expected: p.len().max(3),
            found: q.len(),
        });
    }
    let n = p.len() as f64;
    let (pc, qc) = (p.iter().sum::<Vec3>() / n, q.iter().sum::<Vec3>() / n);
    let h: Matrix3<f64> = p
        .iter()
        .zip(q)
        .map(|(a, b)| (b - qc) * (a - pc).transpose())
        .sum();
    let spread: f64 = p.iter().map(|a| (a - pc).norm_squared()).sum();
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    let d = Vec3::new(1.0, 1.0, (u * v_t).determinant().signum());
    let r = u * Matrix3::from_diagonal(&d) * v_t;
    let scale = svd.singular_values.dot(&d) / spread;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::InvalidParameter(format!(
            "no similarity between the points (scale {scale})"
        )));
    }
    let mut m = (r * scale).to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&(qc - r * scale * pc));
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::octahedron;

    /// An octahedron stretched along x, z and y (distinct axes), as a mesh.
    fn stretched(centre: Vec3, scale: f64) -> TriMesh {
        let (points, triangles) = octahedron();
        let stretch = Vec3::new(6.0, 3.0, 4.0) * scale;
        let points = points
            .iter()
            .map(|p| centre + p.component_mul(&stretch))
            .collect();
        TriMesh::new(points, triangles).unwrap()
    }

    #[test]
    fn a_shifted_scaled_shape_is_found_again() {
        let target = stretched(Vec3::new(3.0, -2.0, 1.0), 1.2);
        let (dims, grid) = grid_around(&target, 0.25, 2.0).unwrap();
        let mask = rasterize(&target, dims, grid).unwrap();
        let template = stretched(Vec3::zeros(), 1.0);
        let a = align_similarity(&template, &mask).unwrap();
        assert!(a.voxel_dice_before < 0.6, "{a:?}");
        assert!(a.voxel_dice > 0.95, "{a:?}");
        assert!((a.scale - 1.2).abs() < 0.02, "{a:?}");
        let moved = a.matrix.transform_point(&nalgebra::Point3::origin());
        assert!(
            (moved.coords - Vec3::new(3.0, -2.0, 1.0)).norm() < 0.1,
            "{a:?}"
        );
    }

    #[test]
    fn the_similarity_between_corresponding_points_is_exact() {
        let (p, _) = octahedron();
        let p: Vec<Vec3> = p
            .iter()
            .map(|a| a.component_mul(&Vec3::new(1.0, 2.0, 3.0)))
            .collect();
        let r = nalgebra::Rotation3::from_euler_angles(0.4, -0.3, 1.1);
        let t = Vec3::new(1.0, -2.0, 0.5);
        let q: Vec<Vec3> = p.iter().map(|a| r * a * 1.7 + t).collect();
        let m = similarity_between(&p, &q).unwrap();
        for (a, b) in p.iter().zip(&q) {
            let moved = m.transform_point(&(*a).into()).coords;
            assert!((moved - b).norm() < 1e-12, "{moved} vs {b}");
        }
        assert!(similarity_between(&p[..2], &q[..2]).is_err());
    }

    #[test]
    fn an_empty_image_is_an_error() {
        let target = stretched(Vec3::zeros(), 1.0);
        let (dims, grid) = grid_around(&target, 0.5, 1.0).unwrap();
        let empty = Volume::new(dims, vec![0.0; dims.iter().product()], grid).unwrap();
        assert!(align_similarity(&target, &empty).is_err());
    }
}
