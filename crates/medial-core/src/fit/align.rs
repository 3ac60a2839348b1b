//! Initial alignment: a similarity `p ↦ s R p + t` that carries a template's interior onto a
//! segmentation's foreground, found from their moments and chosen by voxel overlap. It starts a
//! fit where the flow has only the shape differences left to follow (the paper initialises by
//! an affine SSD stage).
//!
//! With `V`, `c` and `Σ` the volume (mm³), centroid and covariance of each binary shape (voxel
//! centres in world mm, each voxel weighing its volume; the template rasterized on a grid of the
//! image's smallest voxel size):
//! - `s = (tr Σ_img / tr Σ_tmpl)^{1/2}`, the ratio of the shapes' root-mean-square extents: a
//!   subject's size, not its volume, which a thicker wall inflates (a sheet twice as thick at
//!   the same extent has twice the volume: a volume scale of 1.26 would then have to be undone
//!   by an anisotropic affine map and a projection, and the flow would start from a template
//!   crushed along its long axes). The wall's thickness is left to the flow: its ratio after the
//!   similarity, `V_img / (s³ V_tmpl)`, is reported ([`Alignment::thickness_ratio`]),
//! - `R` is the identity, or `E_img D E_tmplᵀ` for the proper eigenvector frames `E` of the two
//!   covariances (eigenvalues in increasing order) and each of the four sign matrices
//!   `D = diag(±1, ±1, ±1)` with `det D = 1` (the principal axes fix `R` up to these signs);
//!   where two variances of either shape are within [`FREE_PLANE`] of each other the axes in
//!   their plane are not fixed, and each of these is also tried after turning the template
//!   about its third axis in steps of [`TURN_STEP_DEG`],
//! - `t = c_img − s R c_tmpl`,
//!
//! and the candidate whose moved boundary overlaps the foreground best (voxel Dice on the
//! image's grid) wins; no move at all is a candidate too. Against corresponding points, [`similarity_between`] is the least-squares
//! similarity (Umeyama 1991). A similarity keeps a medial model medial, so the template can
//! follow it exactly.
//!
//! **Affine after the similarity.** An affine map that is not a similarity does not keep a
//! model medial (spokes stop being normal to the boundary), so it is not for the flow to follow:
//! it is applied to the template, which is then projected back onto its constraints
//! ([`crate::construction::project()`]). [`align_affine`] starts from moments: with the
//! covariances `Σ_t` of the similarity-aligned template and `Σ_i` of the foreground,
//! `A = Σ_i^{1/2} Σ_t^{-1/2}` (the symmetric map that carries one covariance onto the other),
//! `t = c_i − A c_t`, where it raises the voxel Dice (else the identity); from there a compass
//! search of the 12 parameters raises the voxel Dice as far as it goes (the moments of a thin
//! wall barely tell a stretch from a turn) where the foreground is about as thick as the
//! template, and the map is kept only when it raises the voxel Dice. [`affine_between`] is the
//! least-squares affine between corresponding points. [`anisotropy`] says how far an affine is
//! from a similarity.

use crate::fit::initial::THICKEN_AT_LEAST;
use crate::image::rasterize::{grid_around, rasterize, voxel_dice};
use crate::image::Volume;
use crate::mesh::carry_points;
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

/// Two principal variances closer than this fraction of the larger leave the principal axes
/// in their plane undetermined: a shape with a rotational or threefold symmetry about an axis
/// (a cup, the toy's three sheets at 120°) has equal ones, and sampling on voxels moves them by
/// a few per cent, so the eigenvectors there point anywhere in the plane.
pub const FREE_PLANE: f64 = 0.1;

/// Step of the turns about the third axis tried where the principal plane is free
/// ([`FREE_PLANE`]), degrees: a wrong turn of half a step leaves a sheet of width `w` at
/// most `w·sin 7.5° ≈ 0.13 w` off, which the overlap still tells from a right one.
pub const TURN_STEP_DEG: f64 = 15.0;

/// The index (in the frame's increasing order) of the distinct principal axis where the other
/// two variances are within [`FREE_PLANE`] of each other; none where all three differ.
fn free_plane(m: &Moments) -> Option<usize> {
    let mut v: Vec<f64> = SymmetricEigen::new(m.covariance)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    v.sort_by(f64::total_cmp);
    let close = |a: f64, b: f64| b > 0.0 && (b - a) / b < FREE_PLANE;
    if close(v[0], v[1]) {
        Some(2)
    } else if close(v[1], v[2]) {
        Some(0)
    } else {
        None
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
    /// How much thicker the foreground is than the moved template, `V_img / (s³ V_tmpl)`
    /// (about the ratio of wall thicknesses for a sheet; 1 for an affine map, which matches
    /// volumes by its moments).
    pub thickness_ratio: f64,
}

impl Alignment {
    /// The mean scale of the linear part of `m`, `det(A)^{1/3}`.
    pub fn scale_of(m: &Matrix4<f64>) -> f64 {
        m.fixed_view::<3, 3>(0, 0).determinant().cbrt()
    }
}

/// The moments of `mask`'s foreground and of `boundary`'s interior (rasterized at the image's
/// smallest voxel size), and the voxel Dice of `boundary` against `mask`.
fn moments_and_dice(boundary: &TriMesh, mask: &Volume) -> Result<(Moments, Moments, f64)> {
    let image = Moments::of(mask)?;
    let spacing = mask.spacing().min();
    let (dims, grid) = grid_around(boundary, spacing, 2.0 * spacing)?;
    let template = Moments::of(&rasterize(boundary, dims, grid)?)?;
    Ok((image, template, voxel_dice(boundary, mask)?))
}

/// The map `p ↦ linear · p + t` that carries the template centroid onto the image centroid,
/// with the voxel Dice of `boundary` moved by it against `mask`.
fn candidate(
    boundary: &TriMesh,
    mask: &Volume,
    linear: Matrix3<f64>,
    image: &Moments,
    template: &Moments,
) -> Result<(Matrix4<f64>, f64)> {
    let mut matrix = linear.to_homogeneous();
    let shift = image.centroid - linear * template.centroid;
    matrix.fixed_view_mut::<3, 1>(0, 3).copy_from(&shift);
    let moved: Vec<Vec3> = boundary
        .points()
        .iter()
        .map(|p| linear * p + shift)
        .collect();
    let dice = voxel_dice(&TriMesh::new(moved, boundary.triangles().to_vec())?, mask)?;
    Ok((matrix, dice))
}

/// The similarity that best carries the closed template boundary `boundary` onto the
/// foreground of the binary `mask` (see the module doc).
pub fn align_similarity(boundary: &TriMesh, mask: &Volume) -> Result<Alignment> {
    let (image, template, voxel_dice_before) = moments_and_dice(boundary, mask)?;
    let scale = (image.covariance.trace() / template.covariance.trace()).sqrt();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(AlignmentFailure::Scale { scale }.into());
    }
    let (e_img, e_tmpl) = (image.frame(), template.frame());
    let signs = [
        [1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ];
    let by_axes: Vec<Matrix3<f64>> = signs
        .iter()
        .map(|d| e_img * Matrix3::from_diagonal(&Vec3::from(*d)) * e_tmpl.transpose())
        .collect();
    // Where two principal variances (of either shape) are nearly equal, the axes in their
    // plane are not fixed by the moments: turn the template about its third axis too.
    let turns: Vec<Matrix3<f64>> = match free_plane(&image).or(free_plane(&template)) {
        None => Vec::new(),
        Some(axis) => {
            let axis = nalgebra::Unit::new_normalize(e_tmpl.column(axis).into_owned());
            let steps = (360.0 / TURN_STEP_DEG).round() as usize;
            (1..steps)
                .map(|k| {
                    let angle = (k as f64 * TURN_STEP_DEG).to_radians();
                    *nalgebra::Rotation3::from_axis_angle(&axis, angle).matrix()
                })
                .collect()
        }
    };
    let rotations = std::iter::once(Matrix3::identity())
        .chain(by_axes.iter().copied())
        .chain(
            by_axes
                .iter()
                .flat_map(|r| turns.iter().map(move |t| r * t)),
        );
    // No move at all is a candidate too: moments can mislead on a thin or partial shape.
    let mut best = (Matrix4::identity(), voxel_dice_before);
    for r in rotations {
        let (matrix, dice) = candidate(boundary, mask, r * scale, &image, &template)?;
        if dice > best.1 {
            best = (matrix, dice);
        }
    }
    let (matrix, voxel_dice) = best;
    let scale = matrix.fixed_view::<3, 3>(0, 0).determinant().cbrt();
    Ok(Alignment {
        matrix,
        scale,
        voxel_dice_before,
        voxel_dice,
        thickness_ratio: image.volume / (scale.powi(3) * template.volume),
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
        return Err(AlignmentFailure::Scale { scale }.into());
    }
    let mut m = (r * scale).to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&(qc - r * scale * pc));
    Ok(m)
}

/// The affine `p ↦ A p + t` that, after the similarity already applied to `boundary`, overlaps
/// `mask`'s foreground most: from the map of the interiors' covariances, by compass search of
/// the voxel Dice (see the module doc), with the voxel Dice before and after. The search runs
/// only where the foreground is about as thick as the template (within [`THICKEN_AT_LEAST`]
/// either way): across a wall of another thickness the overlap rewards a stretch of the wall
/// rather than of the shape (decision 0202). When it does not raise the voxel Dice, the
/// identity (and equal figures) is returned.
pub fn align_affine(boundary: &TriMesh, mask: &Volume) -> Result<Alignment> {
    let (image, template, voxel_dice_before) = moments_and_dice(boundary, mask)?;
    let identity = Alignment {
        matrix: Matrix4::identity(),
        scale: 1.0,
        voxel_dice_before,
        voxel_dice: voxel_dice_before,
        thickness_ratio: image.volume / template.volume,
    };
    let (Some(root_image), Some(inverse_root_template)) = (
        symmetric_power(&image.covariance, 0.5),
        symmetric_power(&template.covariance, -0.5),
    ) else {
        return Ok(identity);
    };
    let linear = root_image * inverse_root_template;
    let (moments, moments_dice) = candidate(boundary, mask, linear, &image, &template)?;
    let (start, start_dice) = if moments_dice > voxel_dice_before {
        (moments, moments_dice)
    } else {
        (Matrix4::identity(), voxel_dice_before)
    };
    let thickness = image.volume / template.volume;
    let (matrix, dice) = if thickness.max(1.0 / thickness) < THICKEN_AT_LEAST {
        most_overlap(boundary, mask, start, start_dice)?
    } else {
        (start, start_dice)
    };
    if dice <= voxel_dice_before {
        return Ok(identity);
    }
    let scale = matrix.fixed_view::<3, 3>(0, 0).determinant().cbrt();
    Ok(Alignment {
        matrix,
        scale,
        voxel_dice_before,
        voxel_dice: dice,
        thickness_ratio: image.volume / (scale.powi(3) * template.volume),
    })
}

/// The first step of [`most_overlap`]'s search: each entry of the linear part by 0.08 (a point
/// at the template's largest radius `ρ` moves by up to 8 % of `ρ`), the shift by `0.08 ρ`.
const OVERLAP_FIRST_STEP: f64 = 0.08;

/// The affine map `m · start` that overlaps `mask`'s foreground most (voxel Dice of `boundary`
/// carried by it), found by compass search (Kolda, Lewis & Torczon 2003) from `start` (whose
/// overlap is `start_dice`): `m` is `x ↦ c + (I + L)(x − c) + ρ s` about the boundary's
/// centroid `c` (`ρ` its largest radius) with the 12 parameters of `L` and `s`; each parameter
/// is moved by `± step` in turn, the first move that raises the overlap taken, and the step
/// halved after a sweep that raises nothing, from [`OVERLAP_FIRST_STEP`] until it moves a point
/// by less than a quarter of a voxel. The overlap itself is judged, not moments: a thin wall's
/// covariance barely tells a stretch from a turn, and on a heart 10 % out of proportion the
/// moments' map is 10° off (decision 0202). Maps that would reflect are skipped.
fn most_overlap(
    boundary: &TriMesh,
    mask: &Volume,
    start: Matrix4<f64>,
    start_dice: f64,
) -> Result<(Matrix4<f64>, f64)> {
    let points = carry_points(boundary.points(), &start);
    let centre = points.iter().sum::<Vec3>() / points.len() as f64;
    let radius = (points.iter())
        .map(|p| (p - centre).norm())
        .fold(0.0, f64::max);
    let last_step = 0.25 * mask.spacing().min() / radius;
    let map = |theta: &[f64; 12]| {
        let linear = Matrix3::identity() + Matrix3::from_row_slice(&theta[..9]);
        let shift = Vec3::new(theta[9], theta[10], theta[11]) * radius;
        let mut m = linear.to_homogeneous();
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&(centre + shift - linear * centre));
        m * start
    };
    let (mut theta, mut best) = ([0.0; 12], start_dice);
    let mut step = OVERLAP_FIRST_STEP;
    while radius > 0.0 && step >= last_step {
        let mut raised = false;
        for (a, sign) in (0..12).flat_map(|a| [(a, 1.0), (a, -1.0)]) {
            let mut trial = theta;
            trial[a] += sign * step;
            let m = map(&trial);
            if m.fixed_view::<3, 3>(0, 0).determinant() <= 0.0 {
                continue;
            }
            let dice = voxel_dice(&boundary.carried(&m), mask)?;
            if dice > best {
                (theta, best, raised) = (trial, dice, true);
                break;
            }
        }
        if !raised {
            step /= 2.0;
        }
    }
    Ok((map(&theta), best))
}

/// `S^a` of a symmetric positive definite matrix (`V diag(λ^a) Vᵀ`); none when an eigenvalue
/// is not positive.
fn symmetric_power(s: &Matrix3<f64>, a: f64) -> Option<Matrix3<f64>> {
    let eigen = SymmetricEigen::new(*s);
    if eigen
        .eigenvalues
        .iter()
        .any(|&l| !(l > 0.0 && l.is_finite()))
    {
        return None;
    }
    let v = eigen.eigenvectors;
    Some(v * Matrix3::from_diagonal(&eigen.eigenvalues.map(|l| l.powf(a))) * v.transpose())
}

/// The affine `p ↦ A p + t` minimising `Σ |A p_i + t − q_i|²` over corresponding points:
/// with centred points, `A = (Σ q̃ p̃ᵀ)(Σ p̃ p̃ᵀ)⁻¹`, `t = q̄ − A p̄`. An error
/// ([`AlignmentFailure`]) when the points `p` are (nearly) coplanar, or the map would reflect.
pub fn affine_between(p: &[Vec3], q: &[Vec3]) -> Result<Matrix4<f64>> {
    if p.len() != q.len() || p.len() < 4 {
        return Err(Error::ShapeMismatch {
            what: "corresponding points of an affine map (at least 4)".into(),
            expected: p.len().max(4),
            found: q.len(),
        });
    }
    let n = p.len() as f64;
    let (pc, qc) = (p.iter().sum::<Vec3>() / n, q.iter().sum::<Vec3>() / n);
    let cross: Matrix3<f64> = p
        .iter()
        .zip(q)
        .map(|(a, b)| (b - qc) * (a - pc).transpose())
        .sum();
    let spread: Matrix3<f64> = p.iter().map(|a| (a - pc) * (a - pc).transpose()).sum();
    let inverse = spread
        .try_inverse()
        .filter(|_| spread.determinant().abs() > 1e-12 * spread.norm().powi(3))
        .ok_or(AlignmentFailure::Coplanar)?;
    let linear = cross * inverse;
    let determinant = linear.determinant();
    if !(determinant > 0.0 && linear.iter().all(|x| x.is_finite())) {
        return Err(AlignmentFailure::Reflection { determinant }.into());
    }
    let mut m = linear.to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&(qc - linear * pc));
    Ok(m)
}

/// The fraction of the spread of the points `q` about their centroid `q̄` that the points
/// `moved` (a map of points corresponding to `q`, one for one) account for:
/// `1 − Σ |moved_i − q_i|² / Σ |q_i − q̄|²` (1 for a perfect match, about 0 or below for points
/// that do not correspond; NaN for coincident `q`).
pub fn explained_spread(moved: &[Vec3], q: &[Vec3]) -> f64 {
    let n = q.len() as f64;
    let qc = q.iter().sum::<Vec3>() / n;
    let residual: f64 = moved
        .iter()
        .zip(q)
        .map(|(m, b)| (m - b).norm_squared())
        .sum();
    let spread: f64 = q.iter().map(|b| (b - qc).norm_squared()).sum();
    1.0 - residual / spread
}

/// Why no map between two sets of corresponding points was found.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum AlignmentFailure {
    /// The points to be mapped lie (nearly) in a plane: their covariance is singular and no
    /// affine map is determined.
    #[error("the points to be mapped are (nearly) coplanar: no affine map between the point sets")]
    Coplanar,
    /// The least-squares affine map turns space inside out (`det A ≤ 0`), which happens when
    /// the points do not correspond in order: pairs of unrelated points pull `A` towards 0.
    #[error(
        "the least-squares affine map between the points reflects (determinant {determinant:.3}): \
         the two point sets do not seem to correspond, point for point"
    )]
    Reflection {
        /// `det A`.
        determinant: f64,
    },
    /// The least-squares scale is not positive: the points do not correspond at all.
    #[error("no similarity between the points (least-squares scale {scale})")]
    Scale {
        /// `s`.
        scale: f64,
    },
}

/// How far the linear part of `m` is from a similarity: `σ_max / σ_min − 1` of its singular
/// values (0 for a similarity, 0.1 for a 10 % stretch along one axis).
pub fn anisotropy(m: &Matrix4<f64>) -> f64 {
    let singular = m.fixed_view::<3, 3>(0, 0).into_owned().singular_values();
    singular.max() / singular.min() - 1.0
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

    /// A flat octahedron of semi-axes 10, 6 and `thickness`, as a mesh.
    fn slab(thickness: f64) -> TriMesh {
        let (points, triangles) = octahedron();
        let stretch = Vec3::new(10.0, 6.0, thickness);
        let points = points.iter().map(|p| p.component_mul(&stretch)).collect();
        TriMesh::new(points, triangles).unwrap()
    }

    /// A wall twice as thick at the same extent is not a larger shape: the similarity keeps
    /// the size (the volume ratio would scale by 2^{1/3} = 1.26) and reports the thickness.
    #[test]
    fn a_thicker_wall_is_not_a_larger_shape() {
        let target = slab(2.0);
        let (dims, grid) = grid_around(&target, 0.1, 1.0).unwrap();
        let mask = rasterize(&target, dims, grid).unwrap();
        let a = align_similarity(&slab(1.0), &mask).unwrap();
        assert!((a.scale - 1.0).abs() < 0.03, "{a:?}");
        assert!((a.thickness_ratio - 2.0).abs() < 0.15, "{a:?}");
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

    /// The toy's three sheets at 120° have two equal principal variances: its moments fix no
    /// axis in their plane, and only the turns about the seam find a rotated copy.
    #[test]
    fn a_turned_shape_with_a_free_principal_plane_is_found_by_the_turns() {
        let case = crate::synth::SyntheticCase::build(crate::synth::Shape::Toy).unwrap();
        let boundary = case.boundary().unwrap();
        let r = nalgebra::Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vec3::new(0.3, -0.5, 0.8)),
            33f64.to_radians(),
        );
        let shift = Vec3::new(4.0, -3.0, 2.0);
        let moved: Vec<Vec3> = boundary.points().iter().map(|p| r * p + shift).collect();
        let target = TriMesh::new(moved, boundary.triangles().to_vec()).unwrap();
        let (dims, grid) = grid_around(&target, 0.5, 2.0).unwrap();
        let mask = rasterize(&target, dims, grid).unwrap();
        let image = Moments::of(&mask).unwrap();
        assert!(free_plane(&image).is_some(), "{:?}", image.covariance);
        let a = align_similarity(&boundary, &mask).unwrap();
        assert!(a.voxel_dice > 0.85, "{a:?}");
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
    fn an_unequal_scaling_is_found_after_the_similarity() {
        let target = stretched(Vec3::new(1.0, 2.0, -1.0), 1.0);
        let stretch = Matrix3::from_diagonal(&Vec3::new(1.25, 0.9, 1.0));
        let target = target.carried(&stretch.to_homogeneous());
        let (dims, grid) = grid_around(&target, 0.2, 2.0).unwrap();
        let mask = rasterize(&target, dims, grid).unwrap();
        let template = stretched(Vec3::zeros(), 1.0);
        let s = align_similarity(&template, &mask).unwrap();
        let carried = TriMesh::new(
            template
                .points()
                .iter()
                .map(|p| s.matrix.transform_point(&(*p).into()).coords)
                .collect(),
            template.triangles().to_vec(),
        )
        .unwrap();
        let a = align_affine(&carried, &mask).unwrap();
        assert!(a.voxel_dice > s.voxel_dice + 0.02, "{s:?} then {a:?}");
        assert!(a.voxel_dice > 0.97, "{a:?}");
        let total = a.matrix * s.matrix;
        let expected = Vec3::new(1.25, 0.9, 1.0);
        let found = total.fixed_view::<3, 3>(0, 0).diagonal();
        assert!((found - expected).amax() < 0.03, "{found} vs {expected}");
        assert!((anisotropy(&total) - 1.25 / 0.9 + 1.0).abs() < 0.05);
        assert!(anisotropy(&s.matrix) < 1e-9);
    }

    /// A thin wall turned and stretched along axes that are not its own: the moments' affine
    /// map (the symmetric root of the covariances) is off by a turn, and the overlap search
    /// from it finds the map (decision 0202: on a heart 10 % out of proportion the moments'
    /// map overlaps 0.71, the search 0.94).
    #[test]
    fn a_turned_and_stretched_thin_wall_is_found_by_its_overlap_not_its_moments() {
        let turn = nalgebra::Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vec3::new(0.3, 0.5, 0.8)),
            15f64.to_radians(),
        );
        let map = Matrix3::from_diagonal(&Vec3::new(0.95, 0.85, 1.05)) * turn.matrix();
        let wall = slab(1.5);
        let target = wall.carried(&map.to_homogeneous());
        let (dims, grid) = grid_around(&target, 0.1, 1.0).unwrap();
        let mask = rasterize(&target, dims, grid).unwrap();
        let s = align_similarity(&wall, &mask).unwrap();
        let carried = wall.carried(&s.matrix);
        let (image, template, _) = moments_and_dice(&carried, &mask).unwrap();
        let linear = symmetric_power(&image.covariance, 0.5).unwrap()
            * symmetric_power(&template.covariance, -0.5).unwrap();
        let (_, moments) = candidate(&carried, &mask, linear, &image, &template).unwrap();
        let a = align_affine(&carried, &mask).unwrap();
        // Measured: the similarity 0.940, the moments' map 0.981, the search 0.996.
        assert!(a.voxel_dice > 0.99, "{s:?}, moments {moments}, then {a:?}");
        assert!(moments < 0.985, "the moments alone are off: {moments}");
    }

    #[test]
    fn the_affine_between_corresponding_points_is_exact() {
        let (p, _) = octahedron();
        let m = Matrix4::new(
            1.2, 0.1, 0.0, 1.0, //
            -0.2, 0.8, 0.3, -2.0, //
            0.0, 0.1, 1.1, 0.5, //
            0.0, 0.0, 0.0, 1.0,
        );
        let q: Vec<Vec3> = p
            .iter()
            .map(|a| m.transform_point(&(*a).into()).coords)
            .collect();
        let found = affine_between(&p, &q).unwrap();
        assert!((found - m).amax() < 1e-12, "{found}");
        let flat: Vec<Vec3> = p.iter().map(|a| Vec3::new(a.x, a.y, 0.0)).collect();
        assert!(matches!(
            affine_between(&flat, &q),
            Err(Error::Alignment(AlignmentFailure::Coplanar))
        ));
        let mirrored: Vec<Vec3> = p.iter().map(|a| Vec3::new(-a.x, a.y, a.z)).collect();
        let reflection = affine_between(&p, &mirrored).unwrap_err();
        assert!(
            matches!(reflection, Error::Alignment(AlignmentFailure::Reflection { determinant }) if (determinant + 1.0).abs() < 1e-12),
            "{reflection}"
        );
        assert!(reflection.to_string().contains("do not seem to correspond"));
    }

    #[test]
    fn the_explained_spread_tells_corresponding_points_from_scrambled_ones() {
        let (p, _) = stretched(Vec3::new(1.0, 2.0, 3.0), 1.0).into_parts();
        assert_eq!(explained_spread(&p, &p), 1.0);
        // A rotation of the octahedron's vertices: the same shape, no correspondence.
        let n = p.len();
        let scrambled: Vec<Vec3> = (0..n).map(|i| p[(i + 1) % n]).collect();
        let m = similarity_between(&p, &scrambled).unwrap();
        let moved: Vec<Vec3> = p
            .iter()
            .map(|a| m.transform_point(&(*a).into()).coords)
            .collect();
        let explained = explained_spread(&moved, &scrambled);
        assert!(explained < 0.5, "{explained}");
        let near: Vec<Vec3> = p.iter().map(|a| a + Vec3::new(0.1, 0.0, 0.0)).collect();
        assert!((explained_spread(&near, &p) - 1.0).abs() < 0.01);
    }

    #[test]
    fn an_empty_image_is_an_error() {
        let target = stretched(Vec3::zeros(), 1.0);
        let (dims, grid) = grid_around(&target, 0.5, 1.0).unwrap();
        let empty = Volume::new(dims, vec![0.0; dims.iter().product()], grid).unwrap();
        assert!(align_similarity(&target, &empty).is_err());
    }
}
