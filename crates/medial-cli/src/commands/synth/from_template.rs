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
use crate::output::{model_error, print_json, TemplateSummary};
use medial_core::fit::plan::Geometry;
use medial_core::mesh::topology::signed_volume;
use medial_core::mesh::PrincipalAxes;
use medial_core::synth::{target_boundary, target_surface, Warp};
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
}

/// The options of one case from a template, defaults applied.
struct Options<'a> {
    template: &'a Path,
    out: &'a Path,
    bend: f64,
    twist: f64,
    affine: Option<&'a Path>,
    spacing: f64,
    margin: f64,
}

impl<'a> Options<'a> {
    fn of(args: &'a SynthArgs, template: &'a Path) -> Self {
        Self {
            template,
            out: &args.out,
            bend: args.warp.bend.unwrap_or(DEFAULT_BEND_DEG),
            twist: args.warp.twist.unwrap_or(DEFAULT_TWIST_DEG),
            affine: args.warp.affine.as_deref(),
            spacing: args.spacing.unwrap_or(DEFAULT_SPACING_MM),
            margin: args.margin,
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
    let target = target_boundary(&boundary, &warp).map_err(in_template)?;
    let surface = target_surface(&boundary, &warp).map_err(in_template)?;
    let image = target_image(&surface, args.spacing, args.margin)?;
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
        boundary
            .points()
            .iter()
            .zip(target.points())
            .map(|(p, q)| (q - moved(p)).norm()),
    );
    let template_summary = TemplateSummary::of(&template);
    print_json(&WarpSummary {
        template_file: args.template.into(),
        out: args.out.into(),
        warp: figures(args, &warp, &axes, boundary.points()),
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
        None => Ok(bent.with_affine(&default_affine(axes.centre))?),
    }
}

/// The default affine part: `p ↦ s R (p − c) + c + d·u` with `R` the rotation by
/// [`DEFAULT_ROTATION_DEG`] about `u = (1, 1, 1)/√3`, `s` = [`DEFAULT_SCALE`], `d` =
/// [`DEFAULT_SHIFT_MM`].
fn default_affine(centre: Vec3) -> Matrix4<f64> {
    let axis = Unit::new_normalize(Vec3::new(1.0, 1.0, 1.0));
    let linear = Rotation3::from_axis_angle(&axis, DEFAULT_ROTATION_DEG.to_radians()).matrix()
        * DEFAULT_SCALE;
    let mut m = linear.to_homogeneous();
    let offset = centre + axis.into_inner() * DEFAULT_SHIFT_MM - linear * centre;
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&offset);
    m
}

/// The comment lines at the top of the configs: where the case comes from, the warp, the
/// choice of σ.
fn header(args: &Options<'_>, warp: &Warp, g: &Geometry) -> String {
    let name = file_name(args.template);
    let affine = match args.affine {
        Some(path) => format!("the affine map of {}", file_name(path)),
        None => format!(
            "the default affine map: rotation {DEFAULT_ROTATION_DEG}° about (1,1,1)/√3 and\n# \
             scaling {DEFAULT_SCALE} about c, shift {DEFAULT_SHIFT_MM} mm along (1,1,1)/√3"
        ),
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
