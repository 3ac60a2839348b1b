//! `medial synth --from TEMPLATE.vtk`: turns any cmrep template into a synthetic validation case
//! with a known smooth diffeomorphism, as `medial synth` does for its built-in shapes.
//!
//! The warp is `φ(p) = c + t + A·F·B_κ(T_τ(Fᵀ(p − c)))` ([`medial_core::synth::Warp`]): a twist
//! `T_τ` about and a bend `B_κ` of the template's long principal axis (z of the frame `F`),
//! bending across its thin direction (x of `F`), about the centre `c` of its principal bounding
//! box, followed by an affine map (`--affine`, or a modest similarity about `c`). The case holds
//! the template, the warped boundary points (an SSD target with known correspondence), the
//! rasterized warped shape, the affine part and two configs: `fit_boundary.toml` (constrained
//! SSD to the warped points) and `fit.toml` (the paper's affine SSD → Dice schedule).

use super::{boundary_config, paper_config, BOUNDARY_SSD_NOTE, PAPER_SCHEDULE_NOTE};
use super::{target_image, CaseFiles, SynthArgs};
use crate::error::CliError;
use crate::output::{model_error, print_json, write_text, TemplateSummary};
use medial_core::fit::plan::Geometry;
use medial_core::image::volume::Volume;
use medial_core::mesh::topology::signed_volume;
use medial_core::mesh::PrincipalAxes;
use medial_core::model::template::MedialTemplate;
use medial_core::synth::{
    degrade, seeded_directions, target_boundary, target_surface, Degradation, Degraded, Region,
    Thickened, Thickening, Warp,
};
use medial_core::Vec3;
use nalgebra::{Matrix4, Rotation3, Unit};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Default affine part: rotation about `(1, 1, 1)/√3` through the warp centre, degrees.
const DEFAULT_ROTATION_DEG: f64 = 5.0;
/// Default affine part: isotropic scaling about the warp centre.
const DEFAULT_SCALE: f64 = 1.03;
/// Default affine part: shift along `(1, 1, 1)/√3`, mm.
const DEFAULT_SHIFT_MM: f64 = 1.0;

/// Default bend of the long principal axis from end to end, degrees.
const DEFAULT_BEND_DEG: f64 = 25.0;
/// Default twist about the long principal axis from end to end, degrees.
const DEFAULT_TWIST_DEG: f64 = 10.0;
/// Default voxel size of the target image, mm.
const DEFAULT_SPACING_MM: f64 = 0.5;

/// The warp of `medial synth --from` (each option needs --from).
#[derive(clap::Args, Debug)]
pub struct WarpArgs {
    /// With --from: bend of the template's long principal axis from end to end, degrees
    /// (towards its thinnest principal direction; negative: the other way; less than 360 in
    /// magnitude) [default: 25].
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "from"
    )]
    pub bend: Option<f64>,
    /// With --from: twist of the template about its long principal axis from end to end,
    /// degrees [default: 10].
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "from"
    )]
    pub twist: Option<f64>,
    /// With --from: affine part of the warp, applied after the twist and bend: a text file of
    /// 16 numbers, a 4×4 world matrix (mm) row by row, last row 0 0 0 1, positive determinant
    /// [default: a rotation by 5° about (1, 1, 1)/√3 and a scaling by 1.03, both about the
    /// template's centre, then a shift by 1 mm along (1, 1, 1)/√3].
    #[arg(long, value_name = "FILE", requires = "from")]
    pub affine: Option<PathBuf>,
    /// With --from: rotation of the default affine part, degrees (about (1, 1, 1)/√3, or an
    /// axis drawn from --seed) [default: 5].
    #[arg(long, value_name = "DEG", requires = "from", conflicts_with = "affine")]
    pub rotate: Option<f64>,
    /// With --from: shift of the default affine part, mm (along (1, 1, 1)/√3, or a direction
    /// drawn from --seed) [default: 1].
    #[arg(long, value_name = "MM", requires = "from", conflicts_with = "affine")]
    pub shift: Option<f64>,
    /// With --from: every spoke of the template scaled by this factor about its medial point
    /// before the warp (a thicker or thinner wall, not a larger shape); where the wall would
    /// cross itself the change is halved at the atoms involved until it does not (a warning
    /// says how many; thickening.csv has every atom's factor applied) [default: 1].
    #[arg(long, value_name = "FACTOR", requires = "from")]
    pub thicken: Option<f64>,
    /// With --from: the spokes scaled by this factor at --region-atom, by 1 from
    /// --region-radius on, by a raised cosine between (on top of --thicken); the factor of
    /// every atom goes to thickening.csv.
    #[arg(long, value_name = "FACTOR", requires = "from")]
    pub thicken_region: Option<f64>,
    /// With --thicken-region: the atom at the centre of the region [default: the atom nearest
    /// the centroid of the medial points].
    #[arg(long, value_name = "N", requires = "thicken_region")]
    pub region_atom: Option<usize>,
    /// With --thicken-region: the region's radius, mm (Euclidean, from the centre atom's
    /// medial point) [default: a quarter of the template's longest extent].
    #[arg(long, value_name = "MM", requires = "thicken_region")]
    pub region_radius: Option<f64>,
    /// With --from: probability with which each boundary voxel of the target segmentation
    /// changes label (segmentation noise), 0 to 1 [default: 0].
    #[arg(long, value_name = "FRACTION", requires = "from")]
    pub flip: Option<f64>,
    /// With --from: small holes cut out of the target segmentation (balls of --hole-radius
    /// centred on foreground voxels drawn at random) [default: 0].
    #[arg(long, value_name = "N", requires = "from")]
    pub holes: Option<usize>,
    /// With --holes: the holes' radius, mm [default: the voxel size].
    #[arg(long, value_name = "MM", requires = "holes")]
    pub hole_radius: Option<f64>,
    /// With --from: seed of the random draws (the voxels flipped, the holes' places, and the
    /// axis of --rotate and direction of --shift, which are (1, 1, 1)/√3 without a seed).
    #[arg(long, value_name = "S", requires = "from")]
    pub seed: Option<u64>,
}

/// The options of one case from a template, defaults applied.
struct Options<'a> {
    template: &'a Path,
    out: &'a Path,
    bend: f64,
    twist: f64,
    affine: Option<&'a Path>,
    rotate: f64,
    shift: f64,
    spacing: f64,
    margin: f64,
    stress: &'a WarpArgs,
}

impl<'a> Options<'a> {
    fn of(args: &'a SynthArgs, template: &'a Path) -> Self {
        Self {
            template,
            out: &args.out,
            bend: args.warp.bend.unwrap_or(DEFAULT_BEND_DEG),
            twist: args.warp.twist.unwrap_or(DEFAULT_TWIST_DEG),
            affine: args.warp.affine.as_deref(),
            rotate: args.warp.rotate.unwrap_or(DEFAULT_ROTATION_DEG),
            shift: args.warp.shift.unwrap_or(DEFAULT_SHIFT_MM),
            spacing: args.spacing.unwrap_or(DEFAULT_SPACING_MM),
            margin: args.margin,
            stress: &args.warp,
        }
    }
}

/// What `medial synth --from` prints.
#[derive(Serialize)]
struct WarpSummary {
    template_file: PathBuf,
    out: PathBuf,
    template: TemplateSummary,
    warp: WarpFigures,
    /// The thickening and the degradation of the target, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    stress: Option<StressFigures>,
    /// `|φ(p) − p|` over the template's boundary points, mm.
    displacement_mean_mm: f64,
    displacement_max_mm: f64,
    /// `|φ(p) − affine(p)|` over the boundary points (what twist and bend add), mm.
    beyond_affine_mean_mm: f64,
    beyond_affine_max_mm: f64,
    image_dims: [usize; 3],
    image_spacing_mm: f64,
    /// Foreground volume of the target image, mm³.
    target_volume_mm3: f64,
    /// Volume enclosed by the warped, subdivided boundary, mm³.
    target_surface_volume_mm3: f64,
    /// `det A` times the template's volume (bend and twist keep volume to first order), mm³.
    affine_volume_mm3: f64,
    fit: Geometry,
}

/// What `--thicken`, `--thicken-region`, `--flip` and `--holes` did, as printed.
#[derive(Serialize)]
struct StressFigures {
    thicken: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    region_centre_mm: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    region_radius_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    region_factor: Option<f64>,
    /// Atoms within the region (factor changed by the bump).
    region_atoms: usize,
    /// Atoms whose factor was limited where the wall as asked crossed itself (their factors
    /// in thickening.csv).
    thicken_limited_atoms: usize,
    /// The smallest share of the change asked that a limited atom kept (1: none limited).
    thicken_least_share: f64,
    boundary_voxels: usize,
    flipped_voxels: usize,
    hole_voxels: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    seed: Option<u64>,
}

impl StressFigures {
    fn of(
        args: &Options<'_>,
        thickening: Option<(&Thickening, &Thickened)>,
        template: &MedialTemplate,
        degraded: Option<Degraded>,
    ) -> Option<Self> {
        if thickening.is_none() && degraded.is_none() {
            return None;
        }
        let (thickened, thickening) = (thickening.map(|t| t.1), thickening.map(|t| t.0));
        let region = thickening.and_then(|t| t.region());
        Some(Self {
            thicken: thickening.map_or(1.0, |t| t.global()),
            region_centre_mm: region.map(|r| r.centre.into()),
            region_radius_mm: region.map(|r| r.radius_mm),
            region_factor: region.map(|r| r.factor),
            region_atoms: region.map_or(0, |r| {
                template
                    .medial_points()
                    .iter()
                    .filter(|m| (*m - r.centre).norm() < r.radius_mm)
                    .count()
            }),
            thicken_limited_atoms: thickened.map_or(0, |t| t.limited.len()),
            thicken_least_share: thickened.map_or(1.0, |t| t.least_share),
            boundary_voxels: degraded.as_ref().map_or(0, |d| d.boundary_voxels),
            flipped_voxels: degraded.as_ref().map_or(0, |d| d.flipped),
            hole_voxels: degraded.as_ref().map_or(0, |d| d.cleared),
            seed: args.stress.seed,
        })
    }
}

/// The warp as printed.
#[derive(Serialize)]
struct WarpFigures {
    /// Centre `c`, mm.
    centre_mm: [f64; 3],
    /// Long axis (z of the frame: twisted and bent), unit world vector.
    long_axis: [f64; 3],
    /// Bend direction (x of the frame: the thinnest principal direction), unit world vector.
    bend_direction: [f64; 3],
    /// Extent of the template boundary along x, y, z of the frame, mm.
    extent_mm: [f64; 3],
    bend_deg: f64,
    twist_deg: f64,
    /// `κ`, 1/mm.
    curvature_per_mm: f64,
    /// `τ`, rad/mm.
    twist_rad_per_mm: f64,
    /// `det A`.
    affine_determinant: f64,
    /// Largest `κx` over the boundary (the bend folds the shape at 1).
    max_bend_fraction: f64,
}

/// Reads the template, builds the warp and the targets, writes `template.vtk`,
/// `target_boundary.vtk`, `target.nii.gz`, `affine.txt`, `fit_boundary.toml` and `fit.toml`
/// into the folder and prints a summary.
pub fn run(args: &SynthArgs, template_path: &Path) -> Result<(), CliError> {
    let args = &Options::of(args, template_path);
    let template = medial_io::cmrep::read_template(args.template)?;
    let in_template = |e| model_error(args.template, e);
    let boundary = template.boundary_mesh().map_err(in_template)?;
    let axes = PrincipalAxes::of(boundary.points()).map_err(in_template)?;
    let warp = build_warp(args, &axes)?;
    let thickening = thickening(args, &template, &axes)?;
    let thickened = match &thickening {
        Some(t) => Some(
            t.boundary(&template)
                .map_err(|e| CliError::Input(format!("--thicken / --thicken-region: {e}")))?,
        ),
        None => None,
    };
    let walled = thickened.as_ref().map_or(&boundary, |t| &t.mesh);
    let target = target_boundary(walled, &warp).map_err(in_template)?;
    let surface = target_surface(walled, &warp).map_err(in_template)?;
    let image = target_image(&surface, args.spacing, args.margin)?;
    let (image, degradation) = degraded(args, image)?;
    let geometry = Geometry::of(&template, &boundary, &axes);
    let plan = geometry.plan();
    let header = header(args, &warp, &geometry);
    CaseFiles {
        template: &template,
        target_boundary: &target,
        image: &image,
        affine: warp.affine(),
        configs: &[
            (
                "fit_boundary.toml",
                boundary_config(&plan).to_toml(&format!("{header}{BOUNDARY_SSD_NOTE}"))?,
            ),
            (
                "fit.toml",
                paper_config(&plan).to_toml(&format!("{header}{PAPER_SCHEDULE_NOTE}"))?,
            ),
        ],
    }
    .write(args.out)?;
    if let Some(t) = &thickened {
        write_factors(&args.out.join("thickening.csv"), &t.factors)?;
        if !t.limited.is_empty() {
            tracing::warn!(
                "the thickening was limited at {} atoms (to {:.0} % of the change asked at \
                 least), where the wall as asked crossed itself; thickening.csv has the factors \
                 applied",
                t.limited.len(),
                100.0 * t.least_share
            );
        }
    }
    let affine = nalgebra::Affine3::from_matrix_unchecked(warp.affine());
    let moved = |p: &Vec3| affine.transform_point(&(*p).into()).coords;
    let (displacement_mean_mm, displacement_max_mm) = mean_max(
        boundary
            .points()
            .iter()
            .zip(target.points())
            .map(|(p, q)| (q - p).norm()),
    );
    let (beyond_affine_mean_mm, beyond_affine_max_mm) = mean_max(
        walled
            .points()
            .iter()
            .zip(target.points())
            .map(|(p, q)| (q - moved(p)).norm()),
    );
    let template_summary = TemplateSummary::of(&template);
    print_json(&WarpSummary {
        template_file: args.template.into(),
        out: args.out.into(),
        warp: figures(args, &warp, &axes, walled.points()),
        stress: StressFigures::of(
            args,
            thickening.as_ref().zip(thickened.as_ref()),
            &template,
            degradation,
        ),
        displacement_mean_mm,
        displacement_max_mm,
        beyond_affine_mean_mm,
        beyond_affine_max_mm,
        image_dims: image.dims(),
        image_spacing_mm: args.spacing,
        target_volume_mm3: image.integral(),
        target_surface_volume_mm3: signed_volume(surface.points(), surface.triangles()),
        affine_volume_mm3: warp.linear.determinant() * template_summary.volume_mm3,
        template: template_summary,
        fit: geometry,
    })
}

/// The thickening of the options, if any: `--thicken` everywhere and `--thicken-region`
/// about `--region-atom` (default: the atom nearest the medial points' centroid) within
/// `--region-radius` (default: a quarter of the longest extent).
fn thickening(
    args: &Options<'_>,
    template: &MedialTemplate,
    axes: &PrincipalAxes,
) -> Result<Option<Thickening>, CliError> {
    let stress = args.stress;
    if stress.thicken.is_none() && stress.thicken_region.is_none() {
        return Ok(None);
    }
    let medial = template.medial_points();
    let region = match stress.thicken_region {
        None => None,
        Some(factor) => {
            let atom = match stress.region_atom {
                Some(atom) if atom < medial.len() => atom,
                Some(atom) => {
                    return Err(CliError::Input(format!(
                        "--region-atom {atom}: the template has {} atoms (0 to {})",
                        medial.len(),
                        medial.len() - 1
                    )))
                }
                None => nearest(medial, &(medial.iter().sum::<Vec3>() / medial.len() as f64)),
            };
            Some(Region {
                centre: medial[atom],
                radius_mm: stress.region_radius.unwrap_or(axes.extent.max() / 4.0),
                factor,
            })
        }
    };
    Thickening::new(stress.thicken.unwrap_or(1.0), region)
        .map(Some)
        .map_err(|e| CliError::Input(format!("--thicken / --thicken-region: {e}")))
}

/// The index of the point of `points` nearest `p` (the first of equals).
fn nearest(points: &[Vec3], p: &Vec3) -> usize {
    (0..points.len())
        .min_by(|&a, &b| (points[a] - p).norm().total_cmp(&(points[b] - p).norm()))
        .unwrap_or(0)
}

/// `image` degraded as `--flip`, `--holes` and `--hole-radius` say (unchanged without them).
fn degraded(args: &Options<'_>, image: Volume) -> Result<(Volume, Option<Degraded>), CliError> {
    let stress = args.stress;
    if stress.flip.is_none() && stress.holes.is_none() {
        return Ok((image, None));
    }
    let how = Degradation {
        flip_fraction: stress.flip.unwrap_or(0.0),
        holes: stress.holes.unwrap_or(0),
        hole_radius_mm: stress.hole_radius.unwrap_or(args.spacing),
        seed: stress.seed.unwrap_or(0),
    };
    let out =
        degrade(&image, &how).map_err(|e| CliError::Input(format!("--flip / --holes: {e}")))?;
    Ok((out.image.clone(), Some(out)))
}

/// Writes `atom,factor` rows: the spoke factor of every atom (the truth of a thickening).
fn write_factors(path: &Path, factors: &[f64]) -> Result<(), CliError> {
    let mut text = String::from("atom,factor\n");
    for (atom, f) in factors.iter().enumerate() {
        text.push_str(&format!("{atom},{f}\n"));
    }
    write_text(path, &text)
}

/// The warp of the options: twist and bend along `axes`, then the affine part of `--affine`
/// or the default similarity about the centre.
fn build_warp(args: &Options<'_>, axes: &PrincipalAxes) -> Result<Warp, CliError> {
    let bent = Warp::bending(axes, args.bend, args.twist, &Matrix4::identity()).map_err(|e| {
        CliError::Input(format!("--bend {} --twist {}: {e}", args.bend, args.twist))
    })?;
    match args.affine {
        Some(path) => {
            let affine = medial_io::affine::read_affine(path)?.into_inner();
            bent.with_affine(&affine).map_err(|e| model_error(path, e))
        }
        None => Ok(bent.with_affine(&default_affine(args, axes.centre))?),
    }
}

/// The default affine part: `p ↦ s R (p − c) + c + d·v` with `R` the rotation by `--rotate`
/// ([`DEFAULT_ROTATION_DEG`]) about `u`, `s` = [`DEFAULT_SCALE`], `d` = `--shift`
/// ([`DEFAULT_SHIFT_MM`]); `u = v = (1, 1, 1)/√3`, or drawn from `--seed`.
fn default_affine(args: &Options<'_>, centre: Vec3) -> Matrix4<f64> {
    let [axis, direction] = directions(args);
    let axis = Unit::new_normalize(axis);
    let linear =
        Rotation3::from_axis_angle(&axis, args.rotate.to_radians()).matrix() * DEFAULT_SCALE;
    let mut m = linear.to_homogeneous();
    let offset = centre + direction * args.shift - linear * centre;
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&offset);
    m
}

/// The axis of the default rotation and the direction of its shift: `(1, 1, 1)/√3` both, or
/// drawn from `--seed`.
fn directions(args: &Options<'_>) -> [Vec3; 2] {
    match args.stress.seed {
        Some(seed) => {
            let d = seeded_directions(seed, 2);
            [d[0], d[1]]
        }
        None => [Vec3::new(1.0, 1.0, 1.0).normalize(); 2],
    }
}

/// The comment lines at the top of the configs: where the case comes from, the warp, the
/// choice of σ.
fn header(args: &Options<'_>, warp: &Warp, g: &Geometry) -> String {
    let name = file_name(args.template);
    let affine = match args.affine {
        Some(path) => format!("the affine map of {}", file_name(path)),
        None => {
            let [u, v] = directions(args);
            format!(
                "the default affine map: rotation {}° about ({:.3}, {:.3}, {:.3}) and\n# \
                 scaling {DEFAULT_SCALE} about c, shift {} mm along ({:.3}, {:.3}, {:.3})",
                args.rotate, u.x, u.y, u.z, args.shift, v.x, v.y, v.z
            )
        }
    };
    format!(
        "# Synthetic case made from the template {name} by `medial synth --from`
# (--bend {bend} --twist {twist}).
# phi(p) = c + t + A F B_kappa(T_tau(F^T (p - c))): a twist (tau = {tau:.6} rad/mm) and a bend
# (kappa = {kappa:.6} 1/mm) of the template's long principal axis (z of F) across its thinnest
# principal direction (x of F), about c = ({c0:.3}, {c1:.3}, {c2:.3}) mm, then
# {affine}.
# template.vtk is the template; target_boundary.vtk its boundary points moved by phi (an SSD
# target with known correspondence); target.nii.gz the moved boundary, midpoint subdivided twice,
# rasterized at {spacing} mm; affine.txt the affine part p -> A (p - c) + c + t.
# sigma = the mean spoke length ({spoke:.2} mm, about the half thickness: small against the wall
# so that the flow can move medial and boundary points apart, as the constraints need), kept
# within [mean boundary edge / 2, long extent / 8] = [{lo:.2}, {hi:.2}] mm.
",
        bend = args.bend,
        twist = args.twist,
        tau = warp.twist,
        kappa = warp.bend,
        c0 = warp.centre.x,
        c1 = warp.centre.y,
        c2 = warp.centre.z,
        spacing = args.spacing,
        spoke = g.mean_spoke_mm,
        lo = g.mean_edge_mm / 2.0,
        hi = g.long_extent_mm / 8.0,
    )
}

fn figures(args: &Options<'_>, warp: &Warp, axes: &PrincipalAxes, points: &[Vec3]) -> WarpFigures {
    let column = |k: usize| {
        let v = warp.frame.matrix().column(k);
        [v[0], v[1], v[2]]
    };
    WarpFigures {
        centre_mm: warp.centre.into(),
        long_axis: column(2),
        bend_direction: column(0),
        extent_mm: axes.extent.into(),
        bend_deg: args.bend,
        twist_deg: args.twist,
        curvature_per_mm: warp.bend,
        twist_rad_per_mm: warp.twist,
        affine_determinant: warp.linear.determinant(),
        max_bend_fraction: points
            .iter()
            .map(|p| warp.bend * warp.local(p).x)
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

/// The file name of `path` (the path itself if it has none).
fn file_name(path: &Path) -> String {
    path.file_name()
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// Mean and maximum of `values` (0, 0 for none).
fn mean_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (sum, max, n) = values.fold((0.0, 0.0f64, 0usize), |(s, m, n), v| {
        (s + v, m.max(v), n + 1)
    });
    (sum / n.max(1) as f64, max)
}
