//! The initial alignment of an automatic fit (docs/method.md §8.1): where the template starts
//! before the flow moves it.
//!
//! - Against an image (or a closed surface, rasterized): the similarity by moments and overlap
//!   ([`align_similarity`]), then the affine map by moments ([`align_affine`]) when it raises
//!   the overlap and is more than [`AFFINE_ANISOTROPY`] from a similarity.
//! - Against corresponding points: the least-squares similarity, or the least-squares affine
//!   map when it is more than [`AFFINE_ANISOTROPY`] from a similarity; points that the
//!   similarity explains less than [`MIN_EXPLAINED_SPREAD`] of are refused (they do not
//!   correspond).
//! - Against an open surface: none.
//!
//! A similarity keeps a medial template medial. An affine map does not: the carried template is
//! projected back onto its constraints ([`align_template`]); where that projection fails, the
//! similarity alone is taken, since not moving the template further is always sound.
//!
//! ```
//! use medial_core::fit::initial::{align_template, initial_alignment};
//! use medial_core::fit::Target;
//! use medial_core::memory::MemoryLimit;
//! use medial_core::synth::{Shape, SyntheticCase};
//! let case = SyntheticCase::build(Shape::Toy).unwrap();
//! let boundary = case.template().boundary_mesh().unwrap();
//! let target = Target::Points(case.target_boundary().unwrap().points().to_vec());
//! let alignment = initial_alignment(&boundary, &target, 1.0, MemoryLimit::none()).unwrap();
//! let aligned = align_template(case.template(), &alignment).unwrap();
//! assert_eq!(aligned.template.landmark_count(), case.template().landmark_count());
//! ```

#[cfg(doc)]
use crate::construction::inflate::LIMIT_ROUNDS;
use crate::construction::inflate::{halve_at_crossings, self_intersections};
use crate::construction::project::{project, ConstraintFigures, ProjectOptions};
use crate::fit::align::{
    affine_between, align_affine, align_similarity, anisotropy, explained_spread,
    similarity_between,
};
use crate::fit::prepare::Target;
use crate::image::rasterize::{grid_around, rasterize};
use crate::image::volume::Volume;
use crate::memory::{Estimate, MemoryLimit};
use crate::mesh::carry_points;
use crate::mesh::topology::{check_closed_oriented_manifold, check_outward};
use crate::model::constraints::MedialConstraints;
use crate::model::template::MedialTemplate;
use crate::{Error, Result, TriMesh, Vec3};
use nalgebra::Matrix4;

/// An initial map that is at most this far from a similarity ([`anisotropy`]) is taken as its
/// similarity alone: applying and projecting would move the template by less than the
/// projection's own tolerance can tell.
pub const AFFINE_ANISOTROPY: f64 = 0.01;

/// The largest landmark move of the projection that follows an affine map found against filled
/// shapes (an image, a rasterized surface), as a fraction of the template's mean spoke length
/// (its half thickness), beyond which the map is not taken on trust. (A least-squares affine
/// map between corresponding points is the shape's own change and is always followed.) A move
/// of a quarter of the spoke reshapes the boundary–medial prisms by as much, and an anisotropic
/// map that needs it may be fitting the wall's thickness (which the flow follows, thickening
/// the wall along its normals) rather than the shape's extent (which the similarity has
/// matched) — or the shape's own proportions: a heart 10 % out of proportion needs 1.0–1.2 mm
/// at a few atoms of a 3.4 mm mean spoke (decision 0202). So beyond it the similarity alone is
/// a start too ([`AlignedTemplate::similarity`]): an image fit judges the two by a trial of the
/// flow; a fit without a trial takes the similarity.
pub const MAX_PROJECTION_MOVE: f64 = 0.25;

/// The least fraction of the target points' spread ([`explained_spread`]) that the
/// least-squares similarity must account for: below it the points are taken not to correspond
/// to the template boundary's, one for one.
pub const MIN_EXPLAINED_SPREAD: f64 = 0.5;

/// The initial map of a template's boundary onto a target, and what was done, in words.
#[derive(Clone, Debug, PartialEq)]
pub struct InitialAlignment {
    /// The map, a 4×4 world matrix (mm), template → target.
    pub matrix: Matrix4<f64>,
    /// The similarity part of it (the whole map when it is a similarity).
    pub similarity: Matrix4<f64>,
    /// One line per step, with its figures (scale, anisotropy, overlap or distance before and
    /// after).
    pub notes: Vec<String>,
    /// Against an image (or a rasterized surface): how much thicker the foreground is than the
    /// template carried by the similarity
    /// ([`crate::fit::align::Alignment::thickness_ratio`]). Its presence also says that the map
    /// comes from the moments of filled shapes, which confound a wall's thickness with the
    /// shape's extent (corresponding points do not).
    pub thickness_ratio: Option<f64>,
}

impl InitialAlignment {
    /// The similarity `matrix` as the whole map, with `notes`.
    pub(crate) fn similarity(matrix: Matrix4<f64>, notes: Vec<String>) -> Self {
        Self {
            matrix,
            similarity: matrix,
            notes,
            thickness_ratio: None,
        }
    }

    /// Whether the map is more than [`AFFINE_ANISOTROPY`] from a similarity.
    pub fn is_affine(&self) -> bool {
        anisotropy(&self.matrix) > AFFINE_ANISOTROPY
    }
}

/// The initial map of the template boundary `boundary` onto `target` (see the module doc);
/// `spacing` (mm) rasterizes a closed surface. Its grids (the surface rasterized, the template
/// rasterized at an image's smallest voxel for its moments) are refused past `memory`
/// ([`Estimate::grid`]): an image of very anisotropic voxels (0.01 × 10 × 0.5 mm) is small, the
/// template on a grid of its smallest voxel is not.
pub fn initial_alignment(
    boundary: &TriMesh,
    target: &Target,
    spacing: f64,
    memory: MemoryLimit,
) -> Result<InitialAlignment> {
    match target {
        Target::Image { volume, label } => {
            let h = volume.spacing().min();
            check_grid(boundary, h, volume.data().len(), memory)?;
            align_to_image(boundary, &volume.foreground(*label))
        }
        Target::Points(q) => align_to_points(boundary, q),
        Target::Surface(mesh) => align_to_surface(boundary, mesh, spacing, memory),
    }
}

/// Refuses a grid of voxel `h` around `mesh` (as [`grid_around`] makes it, 2 voxels of margin)
/// beside an image of `image_voxels` voxels past `memory` ([`Estimate::alignment`]).
fn check_grid(mesh: &TriMesh, h: f64, image_voxels: usize, memory: MemoryLimit) -> Result<()> {
    let (dims, _) = grid_around(mesh, h, 2.0 * h)?;
    memory.check(&Estimate::alignment(dims, image_voxels), || {
        format!(
            "the initial alignment's grid of {h:.3} mm voxels ({}×{}×{})",
            dims[0], dims[1], dims[2]
        )
    })
}

fn align_to_image(boundary: &TriMesh, mask: &Volume) -> Result<InitialAlignment> {
    let s = align_similarity(boundary, mask)?;
    let mut notes = vec![format!(
        "initial similarity: scale {:.4}, voxel Dice {:.3} → {:.3}, the foreground {:.2}× as \
         thick as the moved template",
        s.scale, s.voxel_dice_before, s.voxel_dice, s.thickness_ratio
    )];
    let carried = boundary.carried(&s.matrix);
    let a = align_affine(&carried, mask)?;
    if anisotropy(&a.matrix) <= AFFINE_ANISOTROPY {
        return Ok(InitialAlignment {
            thickness_ratio: Some(s.thickness_ratio),
            ..InitialAlignment::similarity(s.matrix, notes)
        });
    }
    notes.push(format!(
        "initial affine: anisotropy {:.1} %, voxel Dice {:.3} → {:.3}",
        100.0 * anisotropy(&(a.matrix * s.matrix)),
        a.voxel_dice_before,
        a.voxel_dice
    ));
    Ok(InitialAlignment {
        matrix: a.matrix * s.matrix,
        similarity: s.matrix,
        notes,
        thickness_ratio: Some(s.thickness_ratio),
    })
}

fn align_to_points(boundary: &TriMesh, q: &[Vec3]) -> Result<InitialAlignment> {
    let similarity = similarity_between(boundary.points(), q)?;
    let by_similarity = carry_points(boundary.points(), &similarity);
    let explained = explained_spread(&by_similarity, q);
    if explained.is_nan() || explained < MIN_EXPLAINED_SPREAD {
        return Err(Error::NoCorrespondence {
            explained,
            minimum: MIN_EXPLAINED_SPREAD,
        });
    }
    let rms = |moved: &[Vec3]| {
        let sum: f64 = moved
            .iter()
            .zip(q)
            .map(|(a, b)| (a - b).norm_squared())
            .sum();
        (sum / q.len() as f64).sqrt()
    };
    let rms_similarity = rms(&by_similarity);
    let mut notes = Vec::new();
    let affine = match affine_between(boundary.points(), q) {
        Ok(affine) => Some(affine).filter(|a| anisotropy(a) > AFFINE_ANISOTROPY),
        Err(e) => {
            notes.push(format!("no initial affine map, the similarity alone: {e}"));
            None
        }
    };
    let Some(affine) = affine else {
        notes.push(format!(
            "initial similarity: rms distance {rms_similarity:.3} mm, {:.1} % of the points' \
             spread explained",
            100.0 * explained
        ));
        return Ok(InitialAlignment::similarity(similarity, notes));
    };
    notes.push(format!(
        "initial affine: anisotropy {:.1} %, rms distance {rms_similarity:.3} mm (similarity, \
         {:.1} % of the points' spread explained) → {:.3} mm",
        100.0 * anisotropy(&affine),
        100.0 * explained,
        rms(&carry_points(boundary.points(), &affine))
    ));
    Ok(InitialAlignment {
        matrix: affine,
        similarity,
        notes,
        thickness_ratio: None,
    })
}

fn align_to_surface(
    boundary: &TriMesh,
    mesh: &TriMesh,
    spacing: f64,
    memory: MemoryLimit,
) -> Result<InitialAlignment> {
    if let Err(defect) = check_closed_oriented_manifold(mesh).and_then(|_| check_outward(mesh)) {
        return Ok(InitialAlignment::similarity(
            Matrix4::identity(),
            vec![format!(
                "no initial alignment: the surface is not a closed outward mesh ({defect})"
            )],
        ));
    }
    check_grid(mesh, spacing, 0, memory)?;
    let (dims, grid) = grid_around(mesh, spacing, 2.0 * spacing)?;
    let mask = rasterize(mesh, dims, grid)?;
    check_grid(boundary, spacing, mask.data().len(), memory)?;
    align_to_image(boundary, &mask)
}

/// A template carried by its initial alignment, ready for a fit to start from.
#[derive(Clone, Debug)]
pub struct AlignedTemplate {
    /// The template the fit starts from.
    pub template: MedialTemplate,
    /// The map it was carried by (the alignment's, or its similarity when the affine map could
    /// not be followed by a projection).
    pub matrix: Matrix4<f64>,
    /// One line per step (the projection's figures; a fallback and its reason).
    pub notes: Vec<String>,
    /// Where the affine map needs the projection to move landmarks by more than
    /// [`MAX_PROJECTION_MOVE`]: the template carried by the similarity alone and its map, a
    /// start to judge beside the affine one (by a trial of the flow, where the fit makes one;
    /// [`AlignedTemplate::similarity_alone`] otherwise).
    pub similarity: Option<(MedialTemplate, Matrix4<f64>)>,
}

impl AlignedTemplate {
    /// The similarity alone where the affine map needed large projection moves
    /// ([`AlignedTemplate::similarity`]; noted), else `self`: for a fit that does not judge its
    /// starts by a trial.
    pub fn similarity_alone(self) -> Self {
        match self.similarity {
            Some((template, matrix)) => {
                let mut notes = self.notes;
                notes.push("the similarity alone is taken".into());
                Self {
                    template,
                    matrix,
                    notes,
                    similarity: None,
                }
            }
            None => self,
        }
    }
}

/// Carries `template` by `alignment`. A map that is not a similarity breaks the medial
/// constraints: the carried template is projected back onto them ([`project`]); where that
/// fails, the similarity alone is taken (a similarity keeps a medial template medial); where it
/// moves landmarks by more than [`MAX_PROJECTION_MOVE`], the similarity is offered beside it
/// ([`AlignedTemplate::similarity`]). A template that is not medial as given (an inflated sheet
/// before its projection) is projected too, and taken as it is when that fails (noted).
pub fn align_template(
    template: &MedialTemplate,
    alignment: &InitialAlignment,
) -> Result<AlignedTemplate> {
    let mut notes = Vec::new();
    let mut similarity = None;
    let options = ProjectOptions::default();
    let mut matrix = alignment.matrix;
    let affine = alignment.is_affine();
    let mut carried = template.with_landmarks(&carry_points(template.landmarks(), &matrix))?;
    let medial = ConstraintFigures::of(
        &carried,
        &MedialConstraints::new(&carried),
        carried.landmarks(),
    )
    .meets(&options);
    if affine || !medial {
        let why = if affine {
            "after the affine map"
        } else {
            "as given"
        };
        let spoke = mean_spoke(template) * crate::fit::align::Alignment::scale_of(&matrix);
        match project(&carried, &options) {
            Ok(projection)
                if affine
                    && alignment.thickness_ratio.is_some()
                    && projection.max_displacement > MAX_PROJECTION_MOVE * spoke =>
            {
                notes.push(format!(
                    "the initial affine map (anisotropy {:.1} %) needs the projection to move \
                     landmarks by up to {:.3} mm, more than {MAX_PROJECTION_MOVE} of the mean \
                     spoke ({spoke:.3} mm)",
                    100.0 * anisotropy(&matrix),
                    projection.max_displacement
                ));
                let similar = InitialAlignment::similarity(alignment.similarity, Vec::new());
                let aligned = align_template(template, &similar)?;
                notes.extend(aligned.notes);
                similarity = Some((aligned.template, alignment.similarity));
                carried = projection.template;
            }
            Ok(projection) => {
                notes.push(format!(
                    "template projected onto its constraints {why}: {:.3}° / {:.3} % → {:.3}° / \
                     {:.3} %, landmarks moved ≤ {:.3} mm (rms {:.3} mm)",
                    projection.before.max_spoke_normal_deg,
                    100.0 * projection.before.max_mismatch,
                    projection.after.max_spoke_normal_deg,
                    100.0 * projection.after.max_mismatch,
                    projection.max_displacement,
                    projection.rms_displacement
                ));
                carried = projection.template;
            }
            Err(e) if affine => {
                notes.push(format!(
                    "the initial affine map (anisotropy {:.1} %) cannot be followed by a \
                     projection onto the medial constraints ({e}): the similarity alone is taken",
                    100.0 * anisotropy(&matrix)
                ));
                matrix = alignment.similarity;
                let similar = InitialAlignment::similarity(matrix, Vec::new());
                let aligned = align_template(template, &similar)?;
                notes.extend(aligned.notes);
                carried = aligned.template;
            }
            Err(e) => notes.push(format!(
                "the template is not medial and its projection failed: {e}"
            )),
        }
    }
    Ok(AlignedTemplate {
        template: carried,
        matrix,
        notes,
        similarity,
    })
}

/// The wall-thickness ratio past which a thickened template is tried as a start (either way):
/// below it the flow follows the wall with moves well within a spoke.
pub const THICKEN_AT_LEAST: f64 = 1.15;

/// `template` with every spoke scaled by `factor` about its medial point, projected back onto
/// the constraints: the wall made up to `factor` times as thick at the same medial sheet. Where
/// the sheet cannot hold the whole factor (a curved sheet's offset folds at its focal distance,
/// two sheets at a narrow seam meet sooner), the thickened or projected boundary crosses
/// itself: with `limit_rounds > 0` the change is then halved at the atoms of the crossing
/// triangles and the template thickened and projected again, up to `limit_rounds` times (the
/// limit of a synthetic thickening, [`crate::synth::Thickening::boundary`], whose
/// [`LIMIT_ROUNDS`] a caller may pass), so that a wall is thickened where it can be; with 0 the
/// factor is uniform or nothing. With the number of atoms limited. None where it still crosses
/// itself, or the projection fails or is not a closed, outward surface.
pub fn thickened(
    template: &MedialTemplate,
    factor: f64,
    limit_rounds: u32,
) -> Option<(MedialTemplate, usize)> {
    let q = template.landmarks();
    let atom_of = template.medial_index();
    let mut factors = vec![factor; template.medial_count()];
    for _ in 0..=limit_rounds {
        let moved: Vec<Vec3> = (0..q.len())
            .map(|i| {
                if i < template.boundary_count() {
                    let m = q[template.atom_landmark(atom_of[i])];
                    m + factors[atom_of[i]] * (q[i] - m)
                } else {
                    q[i]
                }
            })
            .collect();
        let carried = template.with_landmarks(&moved).ok()?;
        let thick = carried.boundary_mesh().ok()?;
        let crossing = self_intersections(&thick);
        let (mesh, crossing) = if crossing.is_empty() {
            let projected = project(&carried, &ProjectOptions::default()).ok()?.template;
            let boundary = projected.boundary_mesh().ok()?;
            let crossing = self_intersections(&boundary);
            if crossing.is_empty() {
                let sound = check_closed_oriented_manifold(&boundary).is_ok()
                    && check_outward(&boundary).is_ok();
                let limited = factors.iter().filter(|&&f| f != factor).count();
                return sound.then_some((projected, limited));
            }
            (boundary, crossing)
        } else {
            (thick, crossing)
        };
        halve_at_crossings(&mut factors, &mesh, &crossing, atom_of);
    }
    None
}

/// Mean spoke length `|q_b − q_M[b]|` over the boundary points of `template`, mm.
fn mean_spoke(template: &MedialTemplate) -> f64 {
    let q = template.landmarks();
    let atoms = template.medial_index();
    let n = template.boundary_count();
    (0..n)
        .map(|b| (q[b] - q[template.atom_landmark(atoms[b])]).norm())
        .sum::<f64>()
        / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    /// Past the focal distance of the toy's sheets at its seam (about ×1.4) its wall thickened
    /// uniformly crosses itself: no uniform start, but one limited at a minority of its atoms,
    /// sound after the projection; a factor the sheet holds is uniform, nothing limited.
    #[test]
    fn a_thickened_start_is_uniform_where_the_sheet_holds_it_and_limited_where_not() {
        use crate::construction::inflate::LIMIT_ROUNDS;
        use crate::model::TemplateSummary;
        use crate::synth::{Shape, SyntheticCase};
        let case = SyntheticCase::build(Shape::Toy).unwrap();
        let t = case.template();
        assert!(thickened(t, 1.7, 0).is_none());
        let (thick, limited) = thickened(t, 1.7, LIMIT_ROUNDS).unwrap();
        assert!(limited > 0 && limited < t.medial_count() / 2, "{limited}");
        let boundary = thick.boundary_mesh().unwrap();
        assert!(crate::construction::inflate::self_intersections(&boundary).is_empty());
        assert!(TemplateSummary::of(&thick).volume_mm3 > 1.3 * TemplateSummary::of(t).volume_mm3);
        let (uniform, none) = thickened(t, 1.2, 0).unwrap();
        assert_eq!(none, 0);
        let ratio = TemplateSummary::of(&uniform).volume_mm3 / TemplateSummary::of(t).volume_mm3;
        assert!((ratio - 1.2).abs() < 0.05, "{ratio}");
    }

    /// The alignment's estimate adds the image beside the template's grid: a limit that holds
    /// the grid alone but not both refuses before anything is allocated, naming both parts.
    #[test]
    fn the_alignment_counts_the_image_beside_its_grid() {
        let (points, triangles) = crate::testing::meshes::octahedron();
        let mesh = TriMesh::new(points.iter().map(|p| p * 4.0).collect(), triangles).unwrap();
        // The template's grid at the image's 1 mm voxels.
        let (dims, _) = grid_around(&mesh, 1.0, 2.0).unwrap();
        let grid = Estimate::grid(dims).total();
        let n = 64;
        let image = Volume::new([n, n, n], vec![1.0; n * n * n], Matrix4::identity()).unwrap();
        let target = Target::Image {
            volume: image,
            label: None,
        };
        let limit = MemoryLimit::bytes(grid + 40.0 * (n * n * n) as f64 - 1.0);
        let e = initial_alignment(&mesh, &target, 1.0, limit).unwrap_err();
        let message = e.to_string();
        assert!(message.contains("the image, its foreground"), "{message}");
        assert!(message.contains("the template's grid"), "{message}");
        MemoryLimit::bytes(grid + 40.0 * (n * n * n) as f64)
            .check(&Estimate::alignment(dims, n * n * n), String::new)
            .unwrap();
    }
}
