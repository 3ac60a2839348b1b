//! `medial stats`: a general linear model at every point or cell of a mesh whose array holds one
//! component per subject (meshglm's input), or at every atom of a `medial batch` cohort
//! ([`cohort`]), with permutation inference; the statistics and the per-atom measures are
//! [`medial_stats`]'s, this module reads the inputs, calls it and writes the results.

use crate::error::CliError;
use crate::output::{print_json, write_json, write_options, write_text};
use crate::report::study::{stats_page, MapMesh, Tested};
use medial_io::vtk::{self, ArrayKind, DataArray, PolyData, ValueType};
use medial_stats::permutation::critical_value;
use medial_stats::{
    atom_values, cluster_outlines, diffusion_time, Alignment, AtomMeasure, Contrast,
    ContrastResult, Design, Elements, Mesh, Observations, Options, SheetNormals, Study, Support,
    TableOptions, Tail, TfceParameters,
};
use serde::Serialize;
use std::path::{Path, PathBuf};

pub mod cohort;

use cohort::{Cohort, LeftOut};

/// Test a design's contrasts at every element of a mesh.
#[derive(clap::Args, Debug)]
pub struct StatsArgs {
    /// A legacy VTK triangle mesh with an array of one component per subject (--array), or a
    /// `medial batch` folder (DIR/cohort.csv and each subject's fit: a measure at every atom,
    /// on the template's medial sheet; the design's `subject` column names the subjects).
    #[arg(value_name = "INPUT")]
    pub input: PathBuf,
    /// The design: a CSV table with a header (.csv: columns by name, text columns categorical,
    /// an intercept added), or meshglm's whitespace matrix taken as it is (any other name).
    #[arg(long, value_name = "DESIGN")]
    pub design: PathBuf,
    /// A contrast, repeatable: `name: group[patient] - group[control]`, weights `-1 1 0.05`,
    /// rows separated by `;` for an F-test, or a file with one row per line (meshglm's).
    #[arg(long = "contrast", value_name = "C", required = true)]
    pub contrasts: Vec<String>,
    /// Output folder (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The array of the subjects' values [default: Y]; with a cohort folder the measure at
    /// every atom [default: thickness]: thickness, spoke_pos, spoke_neg (the spoke on the + / −
    /// side of the template's medial normal), spoke1, spoke2, spoke3, displacement (of the
    /// medial point along the template's normal, mm), ball_residual, or any atoms.csv column.
    #[arg(long, value_name = "NAME")]
    pub array: Option<String>,
    /// Cohort folder: the template the subjects were fitted from [default: the first
    /// subject's template.vtk, or the template its config.toml names].
    #[arg(long, value_name = "TEMPLATE.vtk")]
    pub template: Option<PathBuf>,
    /// Cohort folder, --array displacement: how each fitted model is placed on the template
    /// first: none, rigid (rotation and translation of the medial points, least squares) or
    /// similarity (and scale).
    #[arg(long, value_name = "HOW", default_value = "rigid")]
    pub align: Alignment,
    /// The array is on the triangles (CELL_DATA), not the points.
    #[arg(long)]
    pub cell: bool,
    /// Random permutations (all distinct ones when they are fewer); 0: parametric p only.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub permutations: usize,
    /// Seed of the permutations.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,
    /// Cluster-forming threshold on t (|t| with --two-sided, F for an F-test).
    #[arg(long, value_name = "T")]
    pub threshold: Option<f64>,
    /// Threshold-free cluster enhancement.
    #[arg(long)]
    pub tfce: bool,
    /// TFCE's extent power E.
    #[arg(long, value_name = "E", default_value_t = 0.5)]
    pub tfce_e: f64,
    /// TFCE's height power H.
    #[arg(long, value_name = "H", default_value_t = 2.0)]
    pub tfce_h: f64,
    /// TFCE's height step.
    #[arg(long, value_name = "DH", default_value_t = 0.1)]
    pub tfce_dh: f64,
    /// Test cᵀβ ≠ 0 rather than cᵀβ > 0.
    #[arg(long)]
    pub two_sided: bool,
    /// Benjamini–Hochberg q-values of the parametric p (array `q`).
    #[arg(long)]
    pub fdr: bool,
    /// Smooth every subject's map on the mesh first (heat diffusion), FWHM in mm.
    #[arg(long, value_name = "MM")]
    pub fwhm: Option<f64>,
    /// Fewest subjects with a value (not NaN) for an element to be tested.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub min_observations: usize,
    /// An array on the same elements: elements where it is not 0 are left out.
    #[arg(long, value_name = "NAME")]
    pub exclude: Option<String>,
    /// A file of one number per subject (whitespace-separated): subjects with 0 are left out.
    #[arg(long, value_name = "FILE")]
    pub row_mask: Option<PathBuf>,
    /// CSV design: the columns to use, comma-separated [default: all but subject/id].
    #[arg(long, value_name = "A,B", value_delimiter = ',')]
    pub columns: Option<Vec<String>>,
    /// CSV design: columns to take as categorical even if numeric, comma-separated.
    #[arg(long, value_name = "A,B", value_delimiter = ',')]
    pub categorical: Vec<String>,
    /// CSV design: the reference level of a categorical column, `COLUMN=LEVEL`, repeatable.
    #[arg(long = "reference", value_name = "COLUMN=LEVEL")]
    pub references: Vec<String>,
    /// CSV design: no intercept column.
    #[arg(long)]
    pub no_intercept: bool,
}

/// One line for a statistics error.
fn stats_error(e: medial_stats::StatsError) -> CliError {
    CliError::Input(format!("stats: {e}"))
}

fn read_text(path: &Path) -> Result<String, CliError> {
    std::fs::read_to_string(path).map_err(|e| CliError::io(path, e))
}

/// The design, from a CSV table or meshglm's matrix.
fn read_design(args: &StatsArgs) -> Result<Design, CliError> {
    let text = read_text(&args.design)?;
    let is_csv = args
        .design
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let design = if is_csv {
        let references = args
            .references
            .iter()
            .map(|r| match r.split_once('=') {
                Some((c, l)) => Ok((c.trim().to_string(), l.trim().to_string())),
                None => Err(CliError::Usage(format!(
                    "--reference {r}: expected COLUMN=LEVEL"
                ))),
            })
            .collect::<Result<_, _>>()?;
        let options = TableOptions {
            columns: args.columns.clone(),
            categorical: args.categorical.clone(),
            references,
            intercept: !args.no_intercept,
        };
        Design::from_csv(&text, &options)
    } else {
        Design::from_whitespace(&text)
    };
    design.map_err(|e| CliError::Input(format!("{}: {e}", args.design.display())))
}

/// A contrast given as text or as a file.
fn read_contrast(spec: &str, design: &Design) -> Result<Contrast, CliError> {
    let path = Path::new(spec);
    if path.is_file() {
        let name = path
            .file_stem()
            .map_or(spec.into(), |s| s.to_string_lossy());
        Contrast::parse_file(&name, &read_text(path)?, design)
            .map_err(|e| CliError::Input(format!("{}: {e}", path.display())))
    } else {
        Contrast::parse(spec, design).map_err(stats_error)
    }
}

/// What `medial stats` prints and writes as summary.json.
#[derive(Serialize)]
struct Summary {
    /// `stats`: what wrote the folder ([`crate::results::refuse_other_results`]).
    command: &'static str,
    input: PathBuf,
    #[serde(flatten)]
    source: Source,
    array: String,
    support: &'static str,
    subjects: usize,
    elements: usize,
    design_columns: Vec<String>,
    fwhm_mm: Option<f64>,
    diffusion_time_mm2: Option<f64>,
    tfce: Option<TfceSettings>,
    contrasts: Vec<ContrastSummary>,
}

#[derive(Serialize)]
struct TfceSettings {
    e: f64,
    h: f64,
    dh: f64,
}

#[derive(Serialize)]
struct ContrastSummary {
    name: String,
    folder: PathBuf,
    weights: Vec<Vec<f64>>,
    statistic: &'static str,
    two_sided: bool,
    elements_tested: usize,
    max_statistic: f64,
    min_p: f64,
    permutations: Option<usize>,
    exact_permutations: Option<bool>,
    seed: Option<u64>,
    min_p_fwer: Option<f64>,
    fwer_significant_elements: Option<usize>,
    cluster_threshold: Option<f64>,
    clusters: Option<usize>,
    significant_clusters: Option<usize>,
    min_p_tfce: Option<f64>,
    /// The critical value of each null distribution at FWER 5 % (the smallest value with p ≤ 0.05).
    critical_statistic: Option<f64>,
    critical_cluster_area_mm2: Option<f64>,
    critical_tfce: Option<f64>,
}

fn finite_min(v: &[f64]) -> f64 {
    v.iter()
        .copied()
        .filter(|x| !x.is_nan())
        .fold(f64::INFINITY, f64::min)
}

fn array(name: &str, components: usize, values: Vec<f64>, kind: ArrayKind) -> DataArray {
    DataArray {
        name: name.into(),
        components,
        values,
        kind,
        value_type: ValueType::Double,
    }
}

/// The arrays of one contrast's results.
fn result_arrays(r: &ContrastResult) -> Vec<DataArray> {
    let statistic = if r.rows == 1 { "t" } else { "F" };
    let mut arrays = vec![
        array(statistic, 1, r.statistic.clone(), ArrayKind::Scalars),
        array("beta", r.rows, r.estimate.clone(), ArrayKind::Field),
        array("beta_std", r.rows, r.standardised.clone(), ArrayKind::Field),
        array("p", 1, r.p.clone(), ArrayKind::Field),
    ];
    let mut field = |name: &str, values: &Option<Vec<f64>>| {
        if let Some(v) = values {
            arrays.push(array(name, 1, v.clone(), ArrayKind::Field));
        }
    };
    field("q", &r.q);
    field("p_fwer", &r.p_fwer);
    field("tfce", &r.tfce);
    field("p_tfce", &r.p_tfce);
    if let Some(c) = &r.clusters {
        let labels = c.found.labels.iter().map(|&l| l as f64).collect();
        arrays.push(DataArray {
            value_type: ValueType::Int,
            ..array("cluster", 1, labels, ArrayKind::Field)
        });
        arrays.push(array("p_cluster", 1, c.element_p(), ArrayKind::Field));
    }
    arrays
}

/// clusters.csv: one row per cluster.
fn clusters_csv(r: &ContrastResult, centre: &dyn Fn(usize) -> [f64; 3]) -> Option<String> {
    let c = r.clusters.as_ref()?;
    let mut text = String::from(
        "cluster,sign,elements,area_mm2,mass,peak,peak_element,peak_x,peak_y,peak_z,p_area,p_mass\n",
    );
    for (k, cluster) in c.found.clusters.iter().enumerate() {
        let [x, y, z] = centre(cluster.peak_element);
        text += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}\n",
            cluster.id,
            if cluster.positive { "+" } else { "-" },
            cluster.elements,
            cluster.area,
            cluster.mass,
            cluster.peak,
            cluster.peak_element,
            x,
            y,
            z,
            c.p_area[k],
            c.p_mass[k]
        );
    }
    Some(text)
}

/// A folder name from a contrast's name.
fn slug(k: usize, name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .take(40)
        .collect();
    format!("{}_{}", k + 1, clean.trim_matches('_'))
}

/// What is tested: the mesh, its elements' data (one value per subject), the design whose rows
/// are those subjects, and how the results are written.
struct Prepared {
    /// The mesh's points (the template's medial points for a cohort).
    points: Vec<medial_core::Vec3>,
    triangles: Vec<[usize; 3]>,
    support: Support,
    design: Design,
    observations: Observations,
    exclude: Option<Vec<bool>>,
    /// A cohort's template boundary, where the results are also written.
    boundary: Option<Boundary>,
    /// Point arrays written beside the results (a cohort's medial normals).
    extra: Vec<DataArray>,
    /// The array (or a cohort's measure) tested.
    array: String,
    /// What the summary says of the input.
    source: Source,
}

/// A template's boundary and the atom of each of its points (`stats_boundary.vtk`: the
/// results at every boundary point are its atom's).
struct Boundary {
    points: Vec<medial_core::Vec3>,
    triangles: Vec<[usize; 3]>,
    atom_of: Vec<usize>,
}

/// The input as the summary records it.
#[derive(Serialize)]
struct Source {
    kind: &'static str,
    /// A cohort's template.
    template: Option<PathBuf>,
    /// A cohort's subjects, in the design's order.
    subject_names: Option<Vec<String>>,
    /// The subjects the design names whose fits are not usable (left out of the test).
    left_out: Option<Vec<LeftOut>>,
    /// A cohort's displacement alignment.
    alignment: Option<&'static str>,
}

/// The input mesh and its array (meshglm's input).
fn prepare_mesh(args: &StatsArgs) -> Result<Prepared, CliError> {
    let data = vtk::read_polydata(&args.input)?;
    let support = if args.cell {
        Support::Cells
    } else {
        Support::Points
    };
    let triangles = data
        .triangles()
        .map_err(|m| CliError::Input(format!("{}: {m}", args.input.display())))?;
    if args.cell && data.cell_count() != triangles.len() {
        return Err(CliError::Input(format!(
            "{}: --cell needs a mesh of triangles only ({} cells, {} triangles)",
            args.input.display(),
            data.cell_count(),
            triangles.len()
        )));
    }
    let arrays = if args.cell {
        &data.cell_data
    } else {
        &data.point_data
    };
    let find = |name: &str| {
        arrays.iter().find(|a| a.name == name).ok_or_else(|| {
            let names: Vec<&str> = arrays.iter().map(|a| a.name.as_str()).collect();
            CliError::Input(format!(
                "{}: no {} array named '{name}' (it has: {})",
                args.input.display(),
                if args.cell { "cell" } else { "point" },
                names.join(", ")
            ))
        })
    };
    let array_name = args.array.as_deref().unwrap_or("Y");
    let values = find(array_name)?;
    let design = read_design(args)?;
    if values.components != design.subjects() {
        return Err(CliError::Input(format!(
            "{}: array '{}' has {} components, the design {} subjects (rows)",
            args.input.display(),
            array_name,
            values.components,
            design.subjects()
        )));
    }
    let observations =
        Observations::new(values.components, values.values.clone()).map_err(stats_error)?;
    let exclude = match &args.exclude {
        Some(name) => {
            let a = find(name)?;
            if a.components != 1 {
                return Err(CliError::Input(format!(
                    "--exclude {name}: the array has {} components, not 1",
                    a.components
                )));
            }
            Some(a.values.iter().map(|&v| v != 0.0).collect())
        }
        None => None,
    };
    Ok(Prepared {
        points: data.points.clone(),
        triangles,
        support,
        design,
        observations,
        exclude,
        boundary: None,
        extra: Vec::new(),
        array: array_name.into(),
        source: Source {
            kind: "mesh",
            template: None,
            subject_names: None,
            left_out: None,
            alignment: None,
        },
    })
}

/// A `medial batch` folder: the measure `--array` at every atom of every subject the design
/// names, on the template's medial sheet.
fn prepare_cohort(args: &StatsArgs) -> Result<Prepared, CliError> {
    let refuse = |what: &str| {
        CliError::Usage(format!(
            "{what} applies to a mesh input, not to a cohort folder ({})",
            args.input.display()
        ))
    };
    if args.cell {
        return Err(refuse("--cell"));
    }
    if args.exclude.is_some() {
        return Err(refuse("--exclude"));
    }
    let cohort = Cohort::read(&args.input)?;
    let matched = read_design(args)?
        .match_subjects(&cohort.candidates())
        .map_err(|e| CliError::Input(format!("{}: {e}", args.design.display())))?;
    let left_out = matched
        .left_out
        .into_iter()
        .map(|(subject, why)| LeftOut::noted(subject, why))
        .collect();
    let design = matched.design;
    let names: Vec<&str> = matched
        .subjects
        .iter()
        .map(|&k| cohort.subjects[k].0.as_str())
        .collect();
    let (template_path, template) = cohort.template(args.template.as_deref(), &names)?;
    let normals = SheetNormals::new(&template);
    let array_name = args.array.as_deref().unwrap_or("thickness");
    let measure = AtomMeasure::parse(array_name);
    let alignment = args.align;
    let atoms = template.medial_count();
    let per_subject = names
        .iter()
        .map(|name| match &measure {
            AtomMeasure::Column(column) => cohort.atoms_column(name, column, atoms),
            _ => {
                let fitted = cohort.fitted(name)?;
                atom_values(&template, &normals, &fitted, &measure, alignment).map_err(|e| {
                    CliError::Input(format!(
                        "{}: {e}: was it fitted from another template?",
                        cohort
                            .subject_dir(name)
                            .join("fitted_template.vtk")
                            .display()
                    ))
                })
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n = names.len();
    let values = (0..atoms * n).map(|k| per_subject[k % n][k / n]).collect();
    let observations = Observations::new(n, values).map_err(stats_error)?;
    let normal_values = normals
        .normals()
        .iter()
        .flat_map(|n| n.unwrap_or([f64::NAN; 3]))
        .collect();
    Ok(Prepared {
        points: template.medial_points().to_vec(),
        triangles: template.medial_triangles().to_vec(),
        support: Support::Points,
        design,
        observations,
        exclude: None,
        boundary: Some(Boundary {
            points: template.boundary_points().to_vec(),
            triangles: template.boundary_triangles().to_vec(),
            atom_of: template.medial_index().to_vec(),
        }),
        extra: vec![array("medial_normal", 3, normal_values, ArrayKind::Field)],
        array: array_name.into(),
        source: Source {
            kind: "cohort",
            template: Some(template_path),
            subject_names: Some(names.iter().map(|s| s.to_string()).collect()),
            left_out: Some(left_out),
            alignment: (measure == AtomMeasure::Displacement).then_some(alignment.name()),
        },
    })
}

/// Reads, tests every contrast, writes DIR/stats.vtk, DIR/clusters.csv, DIR/clusters_edges.vtk
/// and DIR/summary.json (with several contrasts, each one's files in DIR/K_NAME/), prints the
/// summary.
pub fn run(args: &StatsArgs) -> Result<(), CliError> {
    crate::results::refuse_other_results(&args.out, "stats")?;
    let input = if args.input.is_dir() {
        if !Cohort::is_cohort(&args.input) {
            return Err(CliError::Input(format!(
                "{}: a folder without cohort.csv: not a `medial batch` folder",
                args.input.display()
            )));
        }
        prepare_cohort(args)?
    } else {
        if args.template.is_some() {
            return Err(CliError::Usage(
                "--template applies to a cohort folder, not to a mesh input".into(),
            ));
        }
        prepare_mesh(args)?
    };
    let support = input.support;
    let points: Vec<[f64; 3]> = input.points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let triangles = &input.triangles;
    let mesh = Mesh::new(points.clone(), triangles.clone())
        .map_err(|e| CliError::Input(format!("{}: {e}", args.input.display())))?;
    let design = &input.design;
    let contrasts = args
        .contrasts
        .iter()
        .map(|c| read_contrast(c, design))
        .collect::<Result<Vec<_>, _>>()?;
    let rows = match &args.row_mask {
        Some(path) => {
            let numbers = medial_stats::design::parse_matrix(&read_text(path)?).map_err(
                |(place, problem)| {
                    CliError::Input(format!("{}, {place}: {problem}", path.display()))
                },
            )?;
            Some(numbers.iter().flatten().map(|&v| v != 0.0).collect())
        }
        None => None,
    };
    let options = Options {
        tail: if args.two_sided {
            Tail::Both
        } else {
            Tail::Positive
        },
        permutations: args.permutations,
        seed: args.seed,
        cluster_threshold: args.threshold,
        tfce: args.tfce.then_some(TfceParameters {
            extent_power: args.tfce_e,
            height_power: args.tfce_h,
            step: args.tfce_dh,
        }),
        fdr: args.fdr,
        min_observations: args.min_observations,
        exclude: input.exclude.clone(),
        rows,
        fwhm: args.fwhm,
    };
    let elements = Elements::new(&mesh, support);
    let study =
        Study::new(design, &input.observations, Some(&elements), options).map_err(stats_error)?;
    let centre = |e: usize| match support {
        Support::Points => points[e],
        Support::Cells => {
            let t = triangles[e];
            [0, 1, 2].map(|d| t.iter().map(|&i| points[i][d]).sum::<f64>() / 3.0)
        }
    };
    std::fs::create_dir_all(&args.out).map_err(|e| CliError::io(&args.out, e))?;
    let mut summaries = Vec::new();
    let mut results = Vec::new();
    for (k, contrast) in contrasts.iter().enumerate() {
        let r = study.test(contrast).map_err(stats_error)?;
        let folder = if contrasts.len() == 1 {
            args.out.clone()
        } else {
            args.out.join(slug(k, contrast.name()))
        };
        std::fs::create_dir_all(&folder).map_err(|e| CliError::io(&folder, e))?;
        let mut out = PolyData::from_triangles(&input.points, triangles);
        let arrays = result_arrays(&r);
        if let Some(boundary) = &input.boundary {
            let mut on_boundary = PolyData::from_triangles(&boundary.points, &boundary.triangles);
            on_boundary.point_data = arrays
                .iter()
                .map(|a| DataArray {
                    values: boundary
                        .atom_of
                        .iter()
                        .flat_map(|&m| a.values[m * a.components..(m + 1) * a.components].to_vec())
                        .collect(),
                    ..a.clone()
                })
                .collect();
            vtk::write_polydata(
                &folder.join("stats_boundary.vtk"),
                &on_boundary,
                write_options(true),
            )?;
        }
        if args.cell {
            out.cell_data = arrays;
        } else {
            out.point_data = arrays;
            out.point_data.extend(input.extra.iter().cloned());
        }
        vtk::write_polydata(&folder.join("stats.vtk"), &out, write_options(true))?;
        let clusters_table =
            clusters_csv(&r, &centre).map(|text| (text, folder.join("clusters.csv")));
        if let Some((text, path)) = &clusters_table {
            write_text(path, text)?;
        }
        if let Some(c) = &r.clusters {
            let outline = cluster_outlines(&mesh, support, &c.found.labels);
            let ids = outline.iter().map(|&(_, id)| id as f64).collect();
            let edges = PolyData {
                points: input.points.clone(),
                lines: outline.iter().map(|(pair, _)| pair.to_vec()).collect(),
                cell_data: vec![DataArray {
                    value_type: ValueType::Int,
                    ..array("cluster", 1, ids, ArrayKind::Scalars)
                }],
                ..PolyData::default()
            };
            vtk::write_polydata(
                &folder.join("clusters_edges.vtk"),
                &edges,
                write_options(true),
            )?;
        }
        summaries.push(contrast_summary(contrast, &r, folder));
        results.push((r, clusters_table));
    }
    let map_mesh = medial_core::TriMesh::new(input.points.clone(), triangles.clone())
        .map_err(|e| CliError::Input(format!("{}: {e}", args.input.display())))?;
    let tested: Vec<Tested> = contrasts
        .iter()
        .zip(&results)
        .map(|(contrast, (result, clusters))| Tested {
            contrast,
            result,
            clusters: clusters.clone(),
        })
        .collect();
    let page = stats_page(
        &args.input.display().to_string(),
        study.design(),
        &MapMesh {
            mesh: &map_mesh,
            cells: args.cell,
        },
        &tested,
    )?;
    write_text(&args.out.join("report.html"), &page)?;
    let summary = Summary {
        command: "stats",
        input: args.input.clone(),
        source: input.source,
        array: input.array,
        support: match support {
            Support::Cells => "cells",
            Support::Points if input.boundary.is_some() => "atoms",
            Support::Points => "points",
        },
        subjects: study.design().subjects(),
        elements: elements.len(),
        design_columns: design.names().to_vec(),
        fwhm_mm: args.fwhm,
        diffusion_time_mm2: args.fwhm.map(diffusion_time),
        tfce: args.tfce.then_some(TfceSettings {
            e: args.tfce_e,
            h: args.tfce_h,
            dh: args.tfce_dh,
        }),
        contrasts: summaries,
    };
    write_json(&args.out.join("summary.json"), &summary)?;
    print_json(&summary)?;
    eprintln!("results in {}", args.out.display());
    Ok(())
}

fn contrast_summary(contrast: &Contrast, r: &ContrastResult, folder: PathBuf) -> ContrastSummary {
    let magnitude: Vec<f64> = match r.tail {
        Tail::Both => r.statistic.iter().map(|v| v.abs()).collect(),
        Tail::Positive => r.statistic.clone(),
    };
    let clusters = r.clusters.as_ref();
    ContrastSummary {
        name: r.name.clone(),
        folder,
        weights: contrast
            .matrix()
            .row_iter()
            .map(|row| row.iter().copied().collect())
            .collect(),
        statistic: if r.rows == 1 { "t" } else { "F" },
        two_sided: r.tail == Tail::Both,
        elements_tested: r.statistic.iter().filter(|v| !v.is_nan()).count(),
        max_statistic: magnitude
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f64::NEG_INFINITY, f64::max),
        min_p: finite_min(&r.p),
        permutations: r.permutations.map(|p| p.count),
        exact_permutations: r.permutations.map(|p| p.exact),
        seed: r.permutations.filter(|p| !p.exact).map(|p| p.seed),
        min_p_fwer: r.p_fwer.as_deref().map(finite_min),
        fwer_significant_elements: r
            .p_fwer
            .as_ref()
            .map(|p| p.iter().filter(|&&v| v <= 0.05).count()),
        cluster_threshold: clusters.map(|c| c.threshold),
        clusters: clusters.map(|c| c.found.clusters.len()),
        significant_clusters: clusters
            .filter(|_| r.permutations.is_some())
            .map(|c| c.p_area.iter().filter(|&&p| p <= 0.05).count()),
        min_p_tfce: r.p_tfce.as_deref().map(finite_min),
        critical_statistic: critical_value(&r.null.statistic, 0.05),
        critical_cluster_area_mm2: critical_value(&r.null.area, 0.05),
        critical_tfce: critical_value(&r.null.tfce, 0.05),
    }
}
