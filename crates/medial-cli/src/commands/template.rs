//! `medial template`: a medial template from a shape (a segmentation or a closed mesh), built
//! as the paper builds one by hand, automatically:
//! 1. the shape as a mask on a grid fine enough for its thinnest wall (a third of the 10th
//!    percentile of the half thicknesses found on a first, coarser grid);
//! 2. its medial sheet with a radius per vertex ([`sheet_of_mask`]: exact distance and feature
//!    transform, wide-angle ridge points, sheets and seams, per sheet a chart and a harmonic
//!    map of its region onto a triangular-lattice hexagon; sheets meeting at a seam stitched
//!    along it into edges of three triangles);
//! 3. one Loop subdivision, inflation and projection onto the medial constraints;
//! 4. the automatic constrained Dice fit of that template to the mask itself (`medial fit`'s
//!    own schedule, run in process), then projection again, so that the template matches its
//!    shape and its constraints hold to the projection's tolerance.
//!
//! It writes the template, optionally the sheet, and its figures as JSON (printed too).

use crate::commands::fit::{self, FitOptions, Inputs};
use crate::error::CliError;
use crate::memory;
use crate::output::{model_error, print_json, write_json, write_options, TemplateSummary};
use medial_core::build::inflate::{inflate, self_intersections};
use medial_core::build::project::{project, ProjectOptions};
use medial_core::build::skeleton::chart::ChartKind;
use medial_core::build::skeleton::{medial_points, MIN_FEATURE_ANGLE_DEG};
use medial_core::build::{sheet_of_mask, MedialSheet, Sampling, ShapeSheet};
use medial_core::image::rasterize::{grid_around, grid_around_bounds, rasterize, voxel_dice};
use medial_core::image::Volume;
use medial_core::mesh::topology::{check_closed_oriented_manifold, check_outward};
use medial_core::mesh::Bounds;
use medial_core::model::template::MAX_SPOKES;
use medial_core::model::{MedialTemplate, SpokeMetrics};
use medial_core::TriMesh;
use medial_io::nifti_volume::{write_nifti, NiftiType};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Atoms of a template when neither --atoms nor --spacing is given.
const DEFAULT_ATOMS: usize = 300;
/// Most voxels of the fine grid.
const MAX_VOXELS: usize = 32_000_000;
/// The fine voxel is this fraction of the thin half thickness.
const VOXELS_PER_RADIUS: f64 = 3.0;
/// Percentile of the half thicknesses taken as the thin wall.
const THIN_PERCENTILE: f64 = 0.10;
/// Grid margin around the shape, voxels.
const MARGIN_VOXELS: f64 = 3.0;
/// Voxels along the longest side of a mesh's first, coarse grid.
const COARSE_VOXELS: f64 = 96.0;
/// The targets of a template against its shape (the issue's): voxel Dice.
const TARGET_DICE: f64 = 0.95;

/// The largest spoke–normal angle of a finished template, degrees.
const MAX_ANGLE_DEG: f64 = 0.1;

/// The largest spoke mismatch of a finished template, %.
const MAX_MISMATCH_PCT: f64 = 0.1;

/// Build a medial template from a segmentation or a closed mesh.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("sampling").args(["spacing", "atoms"])))]
pub struct TemplateArgs {
    /// The shape: a binary segmentation (.nii, .nii.gz, .exr; foreground = value > 0 or
    /// --label; a graded signed image, a level set, is cut at 0 on the fine grid) or a closed
    /// triangle mesh (.vtk, .obj, .gltf, .glb), world coordinates in mm.
    /// One sheet: a disc, a bowl or a strip (heart wall, placenta, leaflet, cmrep's t001), or
    /// sheets meeting at seams (the paper's toy: three sheets, one seam).
    #[arg(value_name = "SHAPE")]
    pub shape: PathBuf,
    /// The template to write (cmrep boundary template, legacy VTK).
    #[arg(long, value_name = "TEMPLATE.vtk")]
    pub out: PathBuf,
    /// Also write the medial sheet found (before subdivision; point array Radius, mm): the
    /// input `medial inflate` takes.
    #[arg(long, value_name = "SHEET.vtk")]
    pub sheet: Option<PathBuf>,
    /// Distance between neighbouring atoms of the template, mm.
    #[arg(long, value_name = "MM")]
    pub spacing: Option<f64>,
    /// About this many atoms in the template [default: 300].
    #[arg(long, value_name = "N")]
    pub atoms: Option<usize>,
    /// With a segmentation: the foreground label [default: every voxel > 0].
    #[arg(long, value_name = "L")]
    pub label: Option<f64>,
    /// Voxel size of the grid the medial sheet is found on, mm [default: a third of the thin
    /// half thickness, at most the input's voxel].
    #[arg(long, value_name = "MM")]
    pub voxel: Option<f64>,
    /// Where the figures are written as JSON [default: TEMPLATE with extension .json].
    #[arg(long, value_name = "FIGURES.json")]
    pub figures: Option<PathBuf>,
    /// Keep the fit of the template to its shape in this folder (the files of `medial fit`,
    /// and shape_mask.nii.gz and initial_template.vtk) [default: a temporary folder].
    #[arg(long, value_name = "DIR")]
    pub work: Option<PathBuf>,
    /// Skip the Dice fit to the shape (step 4): the projected inflation of the sheet.
    #[arg(long)]
    pub no_fit: bool,
    /// Write binary legacy VTK instead of ASCII.
    #[arg(long)]
    pub binary: bool,
}

/// The shape as read.
enum Shape {
    /// A binary mask on the input's grid (1 inside), and the input itself when it is a graded
    /// signed image without --label (a level set, foreground `v > 0`): the fine grid then
    /// follows the zero crossing of its trilinear interpolant, not the whole voxels of the mask.
    Mask(Box<Volume>, Option<Box<Volume>>),
    /// A closed triangle mesh (mm).
    Mesh(TriMesh),
}

impl Shape {
    fn read(args: &TemplateArgs) -> Result<Self, CliError> {
        let name = args.shape.to_string_lossy().to_ascii_lowercase();
        if [".nii", ".nii.gz", ".exr"]
            .iter()
            .any(|e| name.ends_with(e))
        {
            let image = medial_io::volume::read_volume(&args.shape)?;
            let mask = Box::new(image.foreground(args.label));
            let graded =
                (args.label.is_none() && image.is_graded_signed()).then(|| Box::new(image));
            Ok(Self::Mask(mask, graded))
        } else if args.label.is_some() {
            Err(CliError::Usage("--label needs a segmentation".into()))
        } else {
            Ok(Self::Mesh(medial_io::mesh::read_mesh(&args.shape)?))
        }
    }

    /// The voxel of the first, coarse grid: half the input's smallest voxel, or a
    /// [`COARSE_VOXELS`]th of a mesh's longest side.
    fn coarse_voxel(&self) -> Result<f64, CliError> {
        Ok(match self {
            Self::Mask(mask, _) => mask.spacing().min() / 2.0,
            Self::Mesh(_) => self.bounds()?.extent().max() / COARSE_VOXELS,
        })
    }

    /// The shape as a mask (1 inside) on an axis-aligned grid of voxel `h` with
    /// [`MARGIN_VOXELS`] around it: the mesh rasterized, or the mask sampled trilinearly and
    /// cut at ½. Refused past [`MAX_VOXELS`] or the memory limit.
    fn on_grid(&self, h: f64, path: &Path) -> Result<Volume, CliError> {
        let margin = MARGIN_VOXELS * h;
        let (dims, to_world) = match self {
            Self::Mesh(mesh) => grid_around(mesh, h, margin),
            Self::Mask(..) => grid_around_bounds(&self.bounds()?, h, margin),
        }
        .map_err(|e| model_error(path, e))?;
        let voxels: usize = dims.iter().product();
        if voxels > MAX_VOXELS {
            return Err(CliError::Input(format!(
                "a grid of {h:.3} mm voxels around {} is {}×{}×{} = {voxels} voxels, more than \
                 {MAX_VOXELS}; give a larger --voxel",
                path.display(),
                dims[0],
                dims[1],
                dims[2]
            )));
        }
        memory::check_grid(dims)?;
        let mask = match self {
            Self::Mesh(mesh) => rasterize(mesh, dims, to_world),
            Self::Mask(mask, graded) => {
                let (image, cut) = match graded {
                    Some(graded) => (graded, 0.0),
                    None => (mask, 0.5),
                };
                image.resampled(dims, to_world).and_then(|v| {
                    let data = v.data().iter().map(|&x| f64::from(u8::from(x > cut)));
                    Volume::new(dims, data.collect(), to_world)
                })
            }
        };
        mask.map_err(|e| model_error(path, e))
    }

    /// The bounding box of the shape (the mask's foreground voxels, or the mesh's points).
    fn bounds(&self) -> Result<Bounds, CliError> {
        match self {
            Self::Mask(mask, _) => mask.support_bounds(),
            Self::Mesh(mesh) => Bounds::of(mesh.points()),
        }
        .ok_or_else(|| CliError::Input("the shape is empty".into()))
    }
}

/// What `medial template` prints and writes.
#[derive(Serialize)]
struct TemplateFigures {
    shape: PathBuf,
    template: PathBuf,
    /// Voxel of the grid the sheet was found on, mm.
    voxel_mm: f64,
    grid_dims: [usize; 3],
    /// Medial points found (ridge voxel pairs).
    medial_points: usize,
    /// Per sheet, the chart it was sampled in: sphere (a bowl) or plane.
    chart: Vec<ChartKind>,
    /// Per sheet, the rows of its lattice hexagon either side of its middle row, and how many
    /// edges it is stretched by along it (0: regular, a round sheet).
    rings: Vec<usize>,
    stretch: Vec<usize>,
    /// Sheets and seams of the medial points (the sheets are stitched along the seams).
    sheets: usize,
    seams: usize,
    /// Voxel Dice of the template against the shape on the fine grid.
    dice: f64,
    /// Voxel Dice against the input segmentation on its own grid (segmentations only).
    dice_input_grid: Option<f64>,
    /// Whether the figures meet the targets: Dice ≥ 0.95, constraints ≤ 0.1° and ≤ 0.1 %,
    /// closed, manifold, outward, no self-intersection.
    meets_targets: bool,
    max_spoke_normal_deg: f64,
    max_spoke_mismatch_pct: f64,
    atoms: usize,
    /// Atoms with 1, 2 and 3 spokes (free edge, sheet, seam).
    atoms_by_spokes: [usize; MAX_SPOKES],
    /// Smallest and largest local thickness (2 × mean spoke), mm.
    thickness_mm: [f64; 2],
    closed_manifold: bool,
    outward: bool,
    self_intersection_free: bool,
    /// Dice of the projected inflation before the fit to the shape.
    dice_before_fit: f64,
    /// Largest landmark move of the final projection, mm.
    final_projection_move_mm: f64,
    fit_seconds: f64,
    seconds: f64,
    summary: TemplateSummary,
}

/// Builds the template of `args.shape` and writes it with its figures.
pub fn run(args: &TemplateArgs, threads: usize, quiet: bool) -> Result<(), CliError> {
    let start = Instant::now();
    let sampling = match (args.atoms, args.spacing) {
        (Some(n), _) => Sampling::Atoms(n),
        (None, Some(s)) => Sampling::Spacing(s),
        (None, None) => Sampling::Atoms(DEFAULT_ATOMS),
    };
    let shape = Shape::read(args)?;
    shape.bounds().map_err(|_| {
        CliError::Input(match shape {
            Shape::Mask(..) => format!(
                "{}: the segmentation is empty (no voxel {})",
                args.shape.display(),
                args.label
                    .map_or_else(|| "> 0".to_owned(), |l| format!("labelled {l}"))
            ),
            Shape::Mesh(_) => format!("{}: the mesh has no points", args.shape.display()),
        })
    })?;
    let (mask, voxel) = fine_mask(&shape, args)?;
    let found = sheet_of_mask(&mask, sampling).map_err(|e| model_error(&args.shape, e))?;
    let initial = inflated(&found.sheet, &args.shape)?;
    let dice_before_fit = dice_of(&initial, &mask, &args.shape)?;
    let fit_start = Instant::now();
    let fitted = if args.no_fit {
        initial
    } else {
        fit_to_shape(&initial, &mask, args, threads, quiet)?
    };
    let fit_seconds = fit_start.elapsed().as_secs_f64();
    let projection =
        project(&fitted, &ProjectOptions::default()).map_err(|e| model_error(&args.shape, e))?;
    let template = projection.template;
    let figures = figures_of(
        &template,
        &found,
        &shape,
        &mask,
        voxel,
        args,
        [dice_before_fit, projection.max_displacement, fit_seconds],
    )?;
    // Nothing is written before everything has been computed, so that a failure leaves no
    // half-written output.
    medial_io::cmrep::write_template(&args.out, &template, write_options(args.binary))?;
    if let Some(path) = &args.sheet {
        medial_io::sheet::write_sheet(path, &found.sheet, write_options(args.binary))?;
    }
    let figures = TemplateFigures {
        seconds: start.elapsed().as_secs_f64(),
        ..figures
    };
    let path = args
        .figures
        .clone()
        .unwrap_or_else(|| args.out.with_extension("json"));
    write_json(&path, &figures)?;
    print_json(&figures)?;
    figures.verdict(&args.out)
}

impl TemplateFigures {
    /// [`verdict`] of these figures.
    fn verdict(&self, out: &Path) -> Result<(), CliError> {
        let defects = [
            (self.closed_manifold, "not a closed oriented manifold"),
            (self.outward, "not outward"),
            (self.self_intersection_free, "self-intersecting"),
        ];
        let spokes = [self.max_spoke_normal_deg, self.max_spoke_mismatch_pct];
        verdict(out, defects, spokes, self.dice)
    }
}

/// `Ok` for a template that can be used: every check of `defects` (whether it holds, what the
/// boundary is when it does not) holds, else [`CliError::Unsound`] (exit 3), and its largest
/// spoke–normal angle (°) and mismatch (%) are within the targets, else
/// [`CliError::ConstraintsNotMet`] (exit 4). A Dice below the target only warns: the template is
/// sound, the figures say how well it matches.
fn verdict(
    out: &Path,
    defects: [(bool, &str); 3],
    [angle_deg, mismatch_pct]: [f64; 2],
    dice: f64,
) -> Result<(), CliError> {
    let causes: Vec<&str> = (defects.iter())
        .filter(|(holds, _)| !holds)
        .map(|&(_, what)| what)
        .collect();
    if !causes.is_empty() {
        return Err(CliError::Unsound(format!(
            "{}: the template's boundary is {} (written with its figures, marked in them)",
            out.display(),
            causes.join(", ")
        )));
    }
    if !(angle_deg <= MAX_ANGLE_DEG && mismatch_pct <= MAX_MISMATCH_PCT) {
        return Err(CliError::ConstraintsNotMet(format!(
            "{}: the template ends at {angle_deg:.3}° and {mismatch_pct:.3} %, above \
             {MAX_ANGLE_DEG}° / {MAX_MISMATCH_PCT} % (written with its figures)",
            out.display()
        )));
    }
    if dice < TARGET_DICE {
        tracing::warn!(
            "{}: Dice {dice:.3} against the shape, below the target {TARGET_DICE}",
            out.display()
        );
    }
    Ok(())
}

/// The shape on its fine grid and that grid's voxel (mm): `--voxel`, or a third of the
/// [`THIN_PERCENTILE`] of the half thicknesses found on a coarse grid, at most the coarse
/// voxel.
fn fine_mask(shape: &Shape, args: &TemplateArgs) -> Result<(Volume, f64), CliError> {
    let voxel = match args.voxel {
        Some(h) if h.is_finite() && h > 0.0 => h,
        Some(h) => {
            return Err(CliError::Usage(format!(
                "--voxel must be a positive number of mm, got {h}"
            )))
        }
        None => {
            let h0 = shape.coarse_voxel()?;
            let coarse = shape.on_grid(h0, &args.shape)?;
            let points = medial_points(&coarse, MIN_FEATURE_ANGLE_DEG)
                .map_err(|e| model_error(&args.shape, e))?;
            let mut radii: Vec<f64> = points.iter().map(|p| p.radius).collect();
            radii.sort_by(f64::total_cmp);
            let thin = radii[(THIN_PERCENTILE * (radii.len() - 1) as f64) as usize];
            (thin / VOXELS_PER_RADIUS).min(h0)
        }
    };
    Ok((shape.on_grid(voxel, &args.shape)?, voxel))
}

/// The sheet Loop-subdivided once, inflated and projected onto its constraints.
fn inflated(sheet: &MedialSheet, path: &Path) -> Result<MedialTemplate, CliError> {
    let error = |e| model_error(path, e);
    let inflated = inflate(&sheet.loop_subdivide().map_err(error)?).map_err(error)?;
    let template = MedialTemplate::new(
        inflated.boundary,
        inflated.medial_index,
        inflated.medial_points,
    )
    .map_err(error)?;
    Ok(project(&template, &ProjectOptions::default())
        .map_err(error)?
        .template)
}

/// The automatic fit of `template` to `mask` (as `medial fit --template --image` runs it) in
/// the work folder; the fitted template.
fn fit_to_shape(
    template: &MedialTemplate,
    mask: &Volume,
    args: &TemplateArgs,
    threads: usize,
    quiet: bool,
) -> Result<MedialTemplate, CliError> {
    let temporary;
    let work = match &args.work {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| CliError::io(dir, e))?;
            dir.clone()
        }
        None => {
            temporary = tempfile::tempdir().map_err(|e| CliError::io(Path::new("<tmp>"), e))?;
            temporary.path().to_path_buf()
        }
    };
    let initial = work.join("initial_template.vtk");
    let image = work.join("shape_mask.nii.gz");
    medial_io::cmrep::write_template(&initial, template, write_options(true))?;
    write_nifti(&image, mask, NiftiType::U8)?;
    let out = work.join("fit");
    let inputs = Inputs {
        template: Some(initial),
        image: Some(image),
        label: None,
        target: None,
        surface: None,
    };
    let resolved = fit::resolve(None, &inputs, &out)?;
    let options = FitOptions {
        out: out.clone(),
        threads,
        quiet,
        checkpoint_every: None,
        resume: false,
    };
    match fit::run(&resolved, &options) {
        // The final projection enforces the constraints the fit left above tolerance.
        Ok(_) | Err(CliError::ConstraintsNotMet(_)) => {}
        // The fit stopped where the model would fold and wrote its last sound iterate: the
        // template is that iterate (its figures say whether it meets the targets).
        Err(CliError::Unsound(message)) => {
            tracing::warn!(
                "the fit to the shape stopped early, keeping its last sound iterate: {message}"
            );
        }
        Err(e) => return Err(e),
    }
    Ok(medial_io::cmrep::read_template(
        &out.join("fitted_template.vtk"),
    )?)
}

/// Voxel Dice of the template's boundary against `mask` on its grid.
fn dice_of(template: &MedialTemplate, mask: &Volume, path: &Path) -> Result<f64, CliError> {
    let boundary = template.boundary_mesh().map_err(|e| model_error(path, e))?;
    voxel_dice(&boundary, mask).map_err(|e| model_error(path, e))
}

/// The figures of the final template (`[Dice before the fit, last projection move, fit
/// seconds]` as measured by the caller; `seconds` filled in by the caller).
fn figures_of(
    template: &MedialTemplate,
    found: &ShapeSheet,
    shape: &Shape,
    mask: &Volume,
    voxel: f64,
    args: &TemplateArgs,
    [dice_before_fit, moved, fit_seconds]: [f64; 3],
) -> Result<TemplateFigures, CliError> {
    let boundary = template
        .boundary_mesh()
        .map_err(|e| model_error(&args.out, e))?;
    let dice = voxel_dice(&boundary, mask).map_err(|e| model_error(&args.out, e))?;
    let dice_input_grid = match shape {
        Shape::Mask(input, _) => {
            Some(voxel_dice(&boundary, input).map_err(|e| model_error(&args.out, e))?)
        }
        Shape::Mesh(_) => None,
    };
    let metrics = SpokeMetrics::compute(template, template.landmarks());
    let summary = TemplateSummary::of(template);
    let closed_manifold = check_closed_oriented_manifold(&boundary).is_ok();
    let outward = check_outward(&boundary).is_ok();
    let self_intersection_free = self_intersections(&boundary).is_empty();
    let fold = |f: fn(f64, f64) -> f64, init| metrics.thickness.iter().copied().fold(init, f);
    let meets_targets = dice >= TARGET_DICE
        && summary.max_spoke_normal_deg <= MAX_ANGLE_DEG
        && summary.max_spoke_mismatch_pct <= MAX_MISMATCH_PCT
        && closed_manifold
        && outward
        && self_intersection_free;
    Ok(TemplateFigures {
        shape: args.shape.clone(),
        template: args.out.clone(),
        voxel_mm: voxel,
        grid_dims: mask.dims(),
        medial_points: found.medial_points.len(),
        chart: found.lattices.iter().map(|l| l.chart.kind).collect(),
        rings: found.lattices.iter().map(|l| l.rings).collect(),
        stretch: found.lattices.iter().map(|l| l.stretch).collect(),
        sheets: found.branching.sheets,
        seams: found.branching.seams,
        dice,
        dice_input_grid,
        meets_targets,
        max_spoke_normal_deg: summary.max_spoke_normal_deg,
        max_spoke_mismatch_pct: summary.max_spoke_mismatch_pct,
        atoms: summary.atoms,
        atoms_by_spokes: summary.atoms_by_spokes,
        thickness_mm: [fold(f64::min, f64::INFINITY), fold(f64::max, 0.0)],
        closed_manifold,
        outward,
        self_intersection_free,
        dice_before_fit,
        final_projection_move_mm: moved,
        fit_seconds,
        seconds: 0.0,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_or_unprojected_template_is_not_a_success() {
        let out = Path::new("t.vtk");
        let sound = [(true, "a"), (true, "b"), (true, "c")];
        assert!(
            verdict(out, sound, [0.05, 0.05], 0.9).is_ok(),
            "a low Dice only warns"
        );
        let folded = [
            (true, "a"),
            (false, "not outward"),
            (false, "self-intersecting"),
        ];
        let e = verdict(out, folded, [0.0, 0.0], 0.99).unwrap_err();
        assert_eq!(e.exit_code(), 3);
        assert!(
            e.to_string().contains("not outward, self-intersecting"),
            "{e}"
        );
        for spokes in [[0.2, 0.0], [0.0, 0.2], [f64::NAN, 0.0]] {
            let e = verdict(out, sound, spokes, 0.99).unwrap_err();
            assert_eq!(e.exit_code(), 4, "{spokes:?}: {e}");
        }
    }
}
