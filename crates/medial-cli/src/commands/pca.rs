//! `medial pca`: the shape modes of a `medial batch` cohort ([`medial_stats::modes`]): reads
//! the fitted models of the usable subjects, calls the library and writes the modes, the
//! scores and the shapes along each mode.

use crate::commands::stats::cohort::{Cohort, LeftOut};
use crate::error::CliError;
use crate::output::{print_json, write_json, write_options, write_text};
use crate::report::study::pca_page;
use medial_core::Vec3;
use medial_io::gltf_flow::{AnimatedSurface, FlowAnimation};
use medial_io::vtk::{self, ArrayKind, DataArray, PolyData, SeriesFile, ValueType};
use medial_stats::shape::AtomShape;
use medial_stats::{shape_modes, Alignment, ShapeModes, ShapeOf};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Shape modes of a cohort's fitted models.
#[derive(clap::Args, Debug)]
pub struct PcaArgs {
    /// A `medial batch` folder (DIR/cohort.csv and each subject's fitted_template.vtk); the
    /// subjects whose fits are usable (status converged or budget) are analysed.
    #[arg(value_name = "BATCH_DIR")]
    pub input: PathBuf,
    /// Output folder (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The shapes: atoms (the medial points and radii) or boundary (the boundary points).
    #[arg(long, value_name = "WHAT", default_value = "atoms")]
    pub of: ShapeOf,
    /// The modes written (at most the cohort's).
    #[arg(long, value_name = "K", default_value_t = 5)]
    pub modes: usize,
    /// Generalised Procrustes alignment first: similarity (rotation, translation and scale),
    /// rigid, or none (the models as fitted).
    #[arg(long, value_name = "HOW", default_value = "similarity")]
    pub align: Alignment,
    /// Only these subjects (names as in cohort.csv, comma-separated) [default: every subject
    /// whose fit is usable].
    #[arg(long, value_name = "A,B", value_delimiter = ',')]
    pub subjects: Option<Vec<String>>,
}

/// The standard deviations of the frames of each mode's series.
const FRAMES_SD: [f64; 9] = [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0];

/// What `medial pca` prints and writes as summary.json.
#[derive(Serialize)]
struct Summary {
    /// `pca`: what wrote the folder ([`crate::results::refuse_other_results`]).
    command: &'static str,
    input: PathBuf,
    of: &'static str,
    alignment: &'static str,
    subjects: Vec<String>,
    left_out: Vec<LeftOut>,
    gpa_rounds: usize,
    total_variance_mm2: f64,
    modes_found: usize,
    modes: Vec<ModeSummary>,
}

/// One mode in the summary and in modes.csv.
#[derive(Serialize)]
struct ModeSummary {
    mode: usize,
    variance_mm2: f64,
    sd_mm: f64,
    explained: f64,
    cumulative: f64,
    series: Vec<PathBuf>,
    /// The frames as one animated glTF file.
    animation: PathBuf,
}

/// The triangles of the shapes' meshes: the boundary's, and the medial sheet's for atoms.
struct Meshes {
    boundary: Vec<[usize; 3]>,
    medial: Option<Vec<[usize; 3]>>,
}

impl Meshes {
    /// The files of `shape` named `stem` in `dir`: `STEM_boundary.vtk`, and for atoms
    /// `STEM_medial.vtk` (the medial sheet with the atoms' `Radius`). Returns their names.
    fn write(
        &self,
        modes: &ShapeModes,
        shape: &AtomShape,
        dir: &Path,
        stem: &str,
    ) -> Result<Vec<String>, CliError> {
        let points = |p: &[[f64; 3]]| p.iter().map(|&x| Vec3::from(x)).collect::<Vec<_>>();
        let boundary = PolyData::from_triangles(&points(&modes.boundary(shape)), &self.boundary);
        let mut written = vec![(format!("{stem}_boundary.vtk"), boundary)];
        if let Some(triangles) = &self.medial {
            let mut medial = PolyData::from_triangles(&points(&shape.points), triangles);
            medial.point_data = vec![DataArray {
                name: "Radius".into(),
                components: 1,
                values: shape.radii.clone(),
                kind: ArrayKind::Scalars,
                value_type: ValueType::Double,
            }];
            written.push((format!("{stem}_medial.vtk"), medial));
        }
        for (name, data) in &written {
            vtk::write_polydata(&dir.join(name), data, write_options(true))?;
        }
        Ok(written.into_iter().map(|(name, _)| name).collect())
    }
}

impl Meshes {
    /// The shapes of a mode's frames (at [`FRAMES_SD`]) as one animation: the boundary
    /// (translucent) and, for atoms, the medial sheet, coloured by the local thickness (twice
    /// the radius; a boundary point takes its atom's); frame n at time `FRAMES_SD[n] + 2` (a
    /// glTF time is not negative), so the animation runs from −2 SD through the mean to +2 SD.
    fn animation(&self, modes: &ShapeModes, shapes: &[AtomShape]) -> FlowAnimation {
        let points = |p: &[[f64; 3]]| p.iter().map(|&x| Vec3::from(x)).collect::<Vec<_>>();
        let thickness: Vec<Vec<f64>> = shapes
            .iter()
            .map(|s| s.radii.iter().map(|r| 2.0 * r).collect())
            .collect();
        let atoms = self.medial.is_some();
        let mut surfaces = vec![AnimatedSurface {
            name: "boundary".into(),
            triangles: self.boundary.clone(),
            frames: shapes.iter().map(|s| points(&modes.boundary(s))).collect(),
            values: if atoms {
                thickness
                    .iter()
                    .map(|t| modes.atom_of().iter().map(|&m| t[m]).collect())
                    .collect()
            } else {
                Vec::new()
            },
            opacity: if atoms { 0.35 } else { 1.0 },
        }];
        if let Some(triangles) = &self.medial {
            surfaces.push(AnimatedSurface {
                name: "medial".into(),
                triangles: triangles.clone(),
                frames: shapes.iter().map(|s| points(&s.points)).collect(),
                values: thickness.clone(),
                opacity: 1.0,
            });
        }
        let range = thickness
            .iter()
            .flatten()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], &v| {
                [lo.min(v), hi.max(v)]
            });
        FlowAnimation {
            times: FRAMES_SD.iter().map(|sd| sd + 2.0).collect(),
            surfaces,
            value_range: if range[0] < range[1] {
                range
            } else {
                [0.0, 1.0]
            },
            value_name: "thickness (mm)".into(),
        }
    }
}

/// The usable subjects of `cohort` and those left out, among `--subjects` when given (each of
/// which must be a subject of the cohort).
fn chosen<'a>(
    cohort: &'a Cohort,
    args: &PcaArgs,
) -> Result<(Vec<&'a str>, Vec<LeftOut>), CliError> {
    let Some(wanted) = &args.subjects else {
        return Ok(cohort.usable());
    };
    let candidates = cohort.candidates();
    if let Some(unknown) = (wanted.iter()).find(|w| !candidates.iter().any(|c| c.name == *w)) {
        return Err(CliError::Input(format!(
            "--subjects: no subject '{unknown}' in {}",
            args.input.join("cohort.csv").display()
        )));
    }
    Ok(cohort.usable_of(|name| wanted.iter().any(|w| w == name)))
}

/// Reads the cohort, computes its modes, writes DIR/modes.csv, DIR/scores.csv,
/// DIR/mean_boundary.vtk (and mean_medial.vtk), each mode's ±2 SD shapes as
/// DIR/modeK_boundary.vtk.series (and modeK_medial.vtk.series) of the frames in DIR/modeK/ and
/// as the animation DIR/modeK.glb, DIR/report.html, and
/// DIR/summary.json; prints the summary.
pub fn run(args: &PcaArgs) -> Result<(), CliError> {
    crate::results::refuse_other_results(&args.out, "pca")?;
    if args.modes == 0 {
        return Err(CliError::Usage("--modes 0: write at least one mode".into()));
    }
    let cohort = Cohort::read(&args.input)?;
    let (names, left_out) = chosen(&cohort, args)?;
    let models = names
        .iter()
        .map(|name| cohort.fitted(name))
        .collect::<Result<Vec<_>, _>>()?;
    let modes = shape_modes(&models, args.of, args.align)
        .map_err(|e| CliError::Input(format!("{}: {e}", args.input.display())))?;
    let meshes = Meshes {
        boundary: models[0].boundary_triangles().to_vec(),
        medial: (args.of == ShapeOf::Atoms).then(|| models[0].medial_triangles().to_vec()),
    };
    std::fs::create_dir_all(&args.out).map_err(|e| CliError::io(&args.out, e))?;
    meshes.write(&modes, &modes.gpa.mean, &args.out, "mean")?;
    let explained = modes.pca.explained();
    let k = args.modes.min(modes.pca.modes.len());
    let mut summaries = Vec::with_capacity(k);
    let mut cumulative = 0.0;
    for (mode, &fraction) in explained.iter().enumerate().take(k) {
        let folder = format!("mode{}", mode + 1);
        let dir = args.out.join(&folder);
        std::fs::create_dir_all(&dir).map_err(|e| CliError::io(&dir, e))?;
        let mut frames: Vec<Vec<SeriesFile>> = Vec::new();
        let mut shapes = Vec::with_capacity(FRAMES_SD.len());
        for (n, &sd) in FRAMES_SD.iter().enumerate() {
            let shape = modes
                .shape_at(mode, sd)
                .map_err(|e| CliError::Input(e.to_string()))?;
            let names = meshes.write(&modes, &shape, &dir, &format!("{n:02}"))?;
            frames.resize_with(names.len(), Vec::new);
            for (list, name) in frames.iter_mut().zip(names) {
                list.push(SeriesFile {
                    name: format!("{folder}/{name}"),
                    time: sd,
                });
            }
            shapes.push(shape);
        }
        let glb = args.out.join(format!("{folder}.glb"));
        medial_io::gltf_flow::write_flow_glb(&glb, &meshes.animation(&modes, &shapes))?;
        let mut series = Vec::new();
        for (list, kind) in frames.iter().zip(["boundary", "medial"]) {
            let path = args.out.join(format!("{folder}_{kind}.vtk.series"));
            vtk::write_series(&path, list)?;
            series.push(path);
        }
        cumulative += fraction;
        summaries.push(ModeSummary {
            mode: mode + 1,
            variance_mm2: modes.pca.variances[mode],
            sd_mm: modes.pca.variances[mode].sqrt(),
            explained: fraction,
            cumulative,
            series,
            animation: glb,
        });
    }
    let mut table = String::from("mode,variance_mm2,sd_mm,explained,cumulative\n");
    for m in &summaries {
        table.push_str(&format!(
            "{},{},{},{},{}\n",
            m.mode, m.variance_mm2, m.sd_mm, m.explained, m.cumulative
        ));
    }
    write_text(&args.out.join("modes.csv"), &table)?;
    let mut scores = String::from("subject");
    for m in 1..=k {
        scores.push_str(&format!(",pc{m}"));
    }
    scores.push('\n');
    for (row, name) in names.iter().enumerate() {
        scores.push_str(name);
        for m in 0..k {
            scores.push_str(&format!(",{}", modes.pca.scores[(row, m)]));
        }
        scores.push('\n');
    }
    write_text(&args.out.join("scores.csv"), &scores)?;
    let subjects: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let page = pca_page(
        &args.input.display().to_string(),
        &explained,
        &modes.pca.scores.columns(0, k).into_owned(),
        &subjects,
    )?;
    write_text(&args.out.join("report.html"), &page)?;
    let summary = Summary {
        command: "pca",
        input: args.input.clone(),
        of: args.of.name(),
        alignment: args.align.name(),
        subjects,
        left_out,
        gpa_rounds: modes.gpa.rounds,
        total_variance_mm2: modes.pca.total_variance,
        modes_found: modes.pca.modes.len(),
        modes: summaries,
    };
    write_json(&args.out.join("summary.json"), &summary)?;
    print_json(&summary)?;
    eprintln!("results in {}", args.out.display());
    Ok(())
}
