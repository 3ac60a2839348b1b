//! `medial template`: a medial template from a shape (a segmentation or a closed mesh): reads
//! the shape, builds the template ([`template_of_shape`]: the steps are the engine's), writes
//! it with its figures as JSON (printed too), and exits by their verdict.

use crate::error::CliError;
use crate::memory;
use crate::output::{model_error, print_json, write_json, write_options};
use medial_core::construction::from_shape::{
    template_of_shape_watched, BuildStep, Shape, TemplateFigures, TemplateOptions, Verdict,
    DEFAULT_ATOMS, LEFT_OUT_LIMIT, MAX_ANGLE_DEG, MAX_MISMATCH_PCT, TARGET_DICE,
};
use medial_core::construction::Sampling;
use medial_io::nifti_volume::{write_nifti, NiftiType};
use medial_io::sheet::{
    labels, lattices_polydata, medial_axis_polydata, seams_polydata, sheet_polydata,
};
use medial_io::vtk::{write_polydata, WriteOptions};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

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
    /// About this many atoms in the template, at most 100000 [default: 300].
    #[arg(long, value_name = "N", value_parser = atom_count)]
    pub atoms: Option<usize>,
    /// With a segmentation: the foreground label [default: every voxel > 0].
    #[arg(long, value_name = "L")]
    pub label: Option<f64>,
    /// Voxel size of the grid the medial sheet is found on, mm [default: a third of the thin
    /// half thickness, at most the input's half voxel, coarsened as little as needed to stay
    /// within 32 million voxels and the memory limit].
    #[arg(long, value_name = "MM", value_parser = positive_mm)]
    pub voxel: Option<f64>,
    /// Where the figures are written as JSON [default: TEMPLATE with extension .json].
    #[arg(long, value_name = "FIGURES.json")]
    pub figures: Option<PathBuf>,
    /// Also write what the template was built from into this folder, each step as it is
    /// taken, so that a build that fails leaves them: the shape on the grid the sheet was found
    /// on (shape_mask.nii.gz: the image the template was fitted to), its medial points
    /// (medial_points.vtk: point arrays Radius in mm, Sheet and Seam, −1 on none), and for
    /// each sampling tried (a folder such as 300_atoms/) each sheet's lattice before the
    /// stitching (lattices.vtk), the seams of a branching shape (seams.vtk) and the sheet
    /// as inflated (sheet.vtk: Radius, and Sheet, −1 on a seam).
    #[arg(long, value_name = "DIR")]
    pub work: Option<PathBuf>,
    /// Skip the Dice fit to the shape (step 6 of docs/template.md): the projected inflation of the sheet.
    #[arg(long)]
    pub no_fit: bool,
    /// Write binary legacy VTK instead of ASCII.
    #[arg(long)]
    pub binary: bool,
}

/// The most atoms `--atoms` takes: the engine's sheet lattices stop at 64 rings (about 50,000
/// atoms a sheet), so a larger count only spends minutes before failing (issue 33).
const MAX_ATOMS: usize = 100_000;

/// `--atoms`: a count from 1 to [`MAX_ATOMS`], refused at once beyond.
fn atom_count(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if (1..=MAX_ATOMS).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected a count of atoms from 1 to {MAX_ATOMS}, got '{text}' (a medial sheet's \
             lattice takes at most about 50000 atoms)"
        )),
    }
}

/// `--voxel`: a positive number of mm.
fn positive_mm(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(h) if h.is_finite() && h > 0.0 => Ok(h),
        _ => Err(format!("expected a positive number of mm, got '{text}'")),
    }
}

/// Reads the shape of `args`: a segmentation (its foreground) or a closed mesh.
fn read_shape(args: &TemplateArgs) -> Result<Shape, CliError> {
    let name = args.shape.to_string_lossy().to_ascii_lowercase();
    if [".nii", ".nii.gz", ".exr"]
        .iter()
        .any(|e| name.ends_with(e))
    {
        let image = medial_io::volume::read_volume(&args.shape)?;
        Ok(Shape::of_segmentation(&image, args.label))
    } else if args.label.is_some() {
        Err(CliError::Usage("--label needs a segmentation".into()))
    } else {
        Ok(Shape::Mesh(medial_io::mesh::read_mesh(&args.shape)?))
    }
}

/// What `medial template` prints and writes: the files, the engine's figures and the time.
#[derive(Serialize)]
struct Printed<'a> {
    shape: &'a Path,
    template: &'a Path,
    #[serde(flatten)]
    figures: &'a TemplateFigures,
    seconds: f64,
}

/// Builds the template of `args.shape` and writes it with its figures.
pub fn run(args: &TemplateArgs) -> Result<(), CliError> {
    let start = Instant::now();
    let sampling = match (args.atoms, args.spacing) {
        (Some(n), _) => Sampling::Atoms(n),
        (None, Some(s)) => Sampling::Spacing(s),
        (None, None) => Sampling::Atoms(DEFAULT_ATOMS),
    };
    // The output's folder exists before the work starts, so that a missing one is not found
    // only at the end.
    if let Some(folder) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder).map_err(|e| CliError::io(folder, e))?;
    }
    let shape = read_shape(args)?;
    if shape.bounds().is_err() {
        return Err(CliError::Input(match shape {
            Shape::Mask(..) => format!(
                "{}: the segmentation is empty (no voxel {})",
                args.shape.display(),
                args.label
                    .map_or_else(|| "> 0".to_owned(), |l| format!("labelled {l}"))
            ),
            Shape::Mesh(_) => format!("{}: the mesh has no points", args.shape.display()),
        }));
    }
    let options = TemplateOptions {
        sampling,
        voxel: args.voxel,
        fit: !args.no_fit,
    };
    let mut work = match &args.work {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| CliError::io(dir, e))?;
            Some(WorkFolder::new(dir, write_options(args.binary)))
        }
        None => None,
    };
    let built = template_of_shape_watched(&shape, &options, memory::limit(), &mut |step| {
        if let Some(work) = &mut work {
            work.write(step);
        }
    });
    let built = built.map_err(|e| match e {
        medial_core::Error::Memory { .. } => CliError::from(e),
        e => model_error(&args.shape, e),
    })?;
    if let Some(e) = work.and_then(|w| w.error) {
        return Err(e);
    }
    if let Some(why) = &built.fit_stopped_early {
        tracing::warn!("the fit to the shape stopped early, keeping its last sound iterate: {why}");
    }
    let lowered = &built.figures.radius_lowered;
    if !lowered.atoms.is_empty() {
        let when = match lowered.refits {
            0 => "at inflation, where the inflated boundary would have intersected itself".into(),
            n => format!(
                "where the boundary intersected itself, at inflation or after the fit; the \
                 template was fitted {n} more time{}",
                if n == 1 { "" } else { "s" }
            ),
        };
        tracing::warn!(
            "the radius was lowered at {} atoms (to {:.0} % at least; `radius_lowered` lists them) \
             {when}",
            lowered.atoms.len(),
            100.0 * lowered.least_factor,
        );
    }
    let shortened = &built.figures.spokes_shortened;
    if !shortened.atoms.is_empty() {
        tracing::warn!(
            "the spokes of {} atoms were shortened after the last fit (to {:.0} % at least; \
             `spokes_shortened` lists them) where the boundary still intersected itself",
            shortened.atoms.len(),
            100.0 * shortened.least_factor,
        );
    }
    if let Some(again) = &built.figures.sampled_again {
        let not_kept: Vec<&str> = again.not_kept.iter().map(|n| &n.sampling[..]).collect();
        let kept = if again.kept == again.first {
            "the first is kept".to_string()
        } else {
            format!("the one built again from {} is kept", again.kept)
        };
        let others = if not_kept.is_empty() {
            String::new()
        } else {
            format!(" and not the one from {}", not_kept.join(" or "))
        };
        tracing::warn!(
            "the template from {} fell short ({}); {kept}{others} (`sampled_again` says why)",
            again.first,
            again.why,
        );
    }
    if built.figures.denoised.is_some() {
        tracing::warn!(
            "the segmentation as given gave no sound template; it was built from the \
             segmentation smoothed by half a voxel, its noise taken out (`denoised` says why)"
        );
    }
    let put_back = &built.figures.band_put_back;
    if !put_back.is_empty() {
        tracing::info!(
            "{} atoms of a seam's band stay on the straight band from the sheet's cut to the seam \
             (`band_put_back` lists them): on the medial points the boundary crossed itself there",
            put_back.len()
        );
    }
    if let Some(wanted) = built.figures.voxel_wanted_mm {
        tracing::info!(
            "the thinnest wall asks for {wanted:.3} mm voxels; the grid is {:.3} mm to stay within \
             the voxel and memory limits",
            built.figures.voxel_mm
        );
    }
    // Nothing is written before everything has been computed, so that a failure leaves no
    // half-written output.
    // The template as cmrep writes it, with the sheet of each boundary point's atom (`Sheet`,
    // −1 on a seam): a wall per colour in ParaView, and per-wall figures in a study.
    let mut data = medial_io::cmrep::template_to_polydata(&built.template);
    let sheet_of: Vec<_> = (built.template.medial_index().iter())
        .map(|&b| built.atom_sheet[b])
        .collect();
    data.point_data.push(labels("Sheet", &sheet_of));
    write_polydata(&args.out, &data, write_options(args.binary))?;
    if let Some(path) = &args.sheet {
        medial_io::sheet::write_sheet(path, &built.found.sheet, write_options(args.binary))?;
    }
    let printed = Printed {
        shape: &args.shape,
        template: &args.out,
        figures: &built.figures,
        seconds: start.elapsed().as_secs_f64(),
    };
    let path = args
        .figures
        .clone()
        .unwrap_or_else(|| args.out.with_extension("json"));
    write_json(&path, &printed)?;
    print_json(&printed)?;
    verdict(&args.out, &built.figures)
}

/// `--work`: the steps of the build ([`BuildStep`]) written into a folder as they are taken,
/// the first error kept (the build goes on; the command reports it after the build's own).
struct WorkFolder<'a> {
    dir: &'a Path,
    options: WriteOptions,
    error: Option<CliError>,
}

impl<'a> WorkFolder<'a> {
    fn new(dir: &'a Path, options: WriteOptions) -> Self {
        Self {
            dir,
            options,
            error: None,
        }
    }

    /// Writes `step` unless an earlier step failed to be written.
    fn write(&mut self, step: BuildStep<'_>) {
        if self.error.is_none() {
            self.error = self.written(step).err();
        }
    }

    fn written(&self, step: BuildStep<'_>) -> Result<(), CliError> {
        match step {
            BuildStep::Mask(mask) => {
                write_nifti(&self.dir.join("shape_mask.nii.gz"), mask, NiftiType::U8)?
            }
            BuildStep::MedialAxis(axis) => write_polydata(
                &self.dir.join("medial_points.vtk"),
                &medial_axis_polydata(axis),
                self.options,
            )?,
            BuildStep::Sheet(sampling, found) => {
                let dir = self.dir.join(match sampling {
                    Sampling::Atoms(n) => format!("{n}_atoms"),
                    Sampling::Spacing(s) => format!("spacing_{s:.3}_mm"),
                });
                std::fs::create_dir_all(&dir).map_err(|e| CliError::io(&dir, e))?;
                let lattices = lattices_polydata(&found.lattices);
                write_polydata(&dir.join("lattices.vtk"), &lattices, self.options)?;
                if !found.seams.is_empty() {
                    let seams = seams_polydata(&found.seams);
                    write_polydata(&dir.join("seams.vtk"), &seams, self.options)?;
                }
                let mut sheet = sheet_polydata(&found.sheet);
                sheet
                    .point_data
                    .push(labels("Sheet", &found.sheet_of_point));
                write_polydata(&dir.join("sheet.vtk"), &sheet, self.options)?;
            }
        }
        Ok(())
    }
}

/// The exit of `medial template` by the figures' verdict ([`TemplateFigures::verdict`]): an
/// unsound boundary is [`CliError::Unsound`] (exit 3), constraints above the targets
/// [`CliError::ConstraintsNotMet`] (exit 4), a wall of the shape left out of the sheet
/// [`CliError::Incomplete`] (exit 1); a Dice below the target only warns.
fn verdict(out: &Path, figures: &TemplateFigures) -> Result<(), CliError> {
    match figures.verdict() {
        Err(Verdict::Unsound(causes)) => Err(CliError::Unsound(format!(
            "{}: the template's boundary is {} (written with its figures, marked in them)",
            out.display(),
            causes.join(", ")
        ))),
        Err(Verdict::ConstraintsNotMet(angle_deg, mismatch_pct)) => {
            Err(CliError::ConstraintsNotMet(format!(
                "{}: the template ends at {angle_deg:.3}° and {mismatch_pct:.3} %, above \
                 {MAX_ANGLE_DEG}° / {MAX_MISMATCH_PCT} % (written with its figures)",
                out.display()
            )))
        }
        Err(Verdict::WallLeftOut(share)) => Err(CliError::Incomplete(format!(
            "{}: a piece of the shape's medial points holding {:.0} % of it (more than \
             {:.0} %) does not reach the rest and is left out of the template: a thin wall that \
             tapers into a thick one? The template misses that wall (written with its figures)",
            out.display(),
            100.0 * share,
            100.0 * LEFT_OUT_LIMIT
        ))),
        Ok(()) => {
            if figures.dice < TARGET_DICE {
                tracing::warn!(
                    "{}: Dice {:.3} against the shape, below the target {TARGET_DICE}",
                    out.display(),
                    figures.dice
                );
            }
            Ok(())
        }
    }
}
