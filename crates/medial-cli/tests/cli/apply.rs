//! `medial apply` end to end on a real fit (a short fit of examples/t001-bent to its bent
//! boundary): meshes carried both ways, the template's boundary coming out at the fit's last
//! boundary, a label image pulled back with its warp read back against the point map, the
//! per-atom table against the medial VTK, and the refusals.

use crate::common::{f, medial, one_line_error, reseal, run_json, s, text};
use medial_core::image::Volume;
use medial_core::Vec3;
use medial_io::nifti_volume::{read_nifti, read_nifti_file, write_nifti, NiftiType};
use medial_io::vtk::{read_polydata, write_polydata, PolyData, WriteOptions};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The shipped example.
fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/t001-bent")
        .join(name)
}

/// The time steps of the test fit.
const STEPS: usize = 10;

/// A short fit of t001-bent to its bent boundary points (SSD, one AL iteration), run once for
/// all tests: the fit folder.
fn fit_dir() -> &'static Path {
    static FIT: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, out) = FIT.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("fit.toml");
        let toml = format!(
            "[model]\ntemplate = \"{}\"\n[flow]\nsigma = 1.41\ntime_steps = {STEPS}\n\
             kinetic_weight = 0.005\n[output]\nevery_time_point = true\n[[stage]]\n\
             name = \"boundary\"\nattachment = \"ssd\"\ntarget = \"{}\"\nmu = 20.0\n\
             al_iterations = 1\nmax_iterations = 60\ntolerance_deg = 90.0\n\
             tolerance_pct = 100.0\n",
            example("template.vtk").display(),
            example("target_boundary.vtk").display()
        );
        std::fs::write(&config, toml).unwrap();
        let out = dir.path().join("out");
        let o = medial(&["fit", s(&config), "--out", s(&out), "-q"]);
        assert!(o.status.success(), "the fit failed: {}", text(&o.stderr));
        (dir, out)
    });
    out
}

fn apply(args: &[&str]) -> Value {
    let mut all = vec!["apply", s(fit_dir())];
    all.extend_from_slice(args);
    run_json(&all)
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

fn last_boundary() -> PolyData {
    read_polydata(&fit_dir().join(format!("flow/boundary_t{STEPS:03}.vtk"))).unwrap()
}

#[test]
fn the_template_comes_out_at_the_fits_last_boundary_and_goes_back() {
    let dir = tempfile::tempdir().unwrap();
    let (moved, back) = (dir.path().join("moved.vtk"), dir.path().join("back.vtk"));
    let template = read_polydata(&example("template.vtk")).unwrap();
    let summary = apply(&[s(&example("template.vtk")), "--out", s(&moved)]);
    assert_eq!(summary["direction"], "forward");
    let carried = read_polydata(&moved).unwrap();
    let error = max_distance(&carried.points, &last_boundary().points);
    println!("template boundary through apply vs the fit's last boundary: {error:e} mm");
    assert!(error < 1e-9, "{error} mm");
    // The cells and the arrays are kept (but the normals).
    assert_eq!(carried.polygons, template.polygons);
    let names = |d: &PolyData| -> Vec<String> {
        (d.point_data.iter())
            .filter(|a| a.kind != medial_io::vtk::ArrayKind::Normals)
            .map(|a| a.name.clone())
            .collect()
    };
    assert_eq!(names(&carried), names(&template));
    assert!(names(&carried).iter().any(|n| n == "MedialIndex"));
    assert!(f(&summary["max_displacement_mm"]) > 1.0, "{summary}");
    apply(&[s(&moved), "--out", s(&back), "--inverse"]);
    let round_trip = max_distance(&read_polydata(&back).unwrap().points, &template.points);
    println!("round trip φ₁⁻¹(φ₁(x)) of the template boundary: {round_trip:e} mm");
    assert!(round_trip < 1e-7, "{round_trip} mm");
}

#[test]
fn meshes_of_other_formats_are_carried_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let (obj, back) = (dir.path().join("moved.obj"), dir.path().join("back.obj"));
    apply(&[
        s(&example("target_boundary.vtk")),
        "--out",
        s(&obj),
        "--inverse",
    ]);
    apply(&[s(&obj), "--out", s(&back)]);
    let (a, b) = (
        medial_io::mesh::read_mesh(&back).unwrap(),
        medial_io::mesh::read_mesh(&example("target_boundary.vtk")).unwrap(),
    );
    assert_eq!(a.triangles(), b.triangles());
    assert!(max_distance(a.points(), b.points()) < 1e-7);
    // Pulled back, the bent target lies near the template (as near as the fit came).
    let template = read_polydata(&example("template.vtk")).unwrap();
    let pulled = medial_io::mesh::read_mesh(&obj).unwrap();
    let before = max_distance(b.points(), &template.points);
    let after = max_distance(pulled.points(), &template.points);
    assert!(after < 0.5 * before, "{after} vs {before} mm");
}

/// The template's interior as labels on a 0.5 mm grid: 1, and 2 where x is above its middle.
fn label_image(dir: &Path) -> PathBuf {
    let mask = dir.join("mask.nii.gz");
    let o = medial(&[
        "rasterize",
        s(&example("template.vtk")),
        "--spacing",
        "0.5",
        "--out",
        s(&mask),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v = read_nifti(&mask).unwrap();
    let mid = 0.5 * (v.voxel_centre([0, 0, 0]).x + v.voxel_centre([v.dims()[0] - 1, 0, 0]).x);
    let [nx, ny, _] = v.dims();
    let labels = (v.data().iter().enumerate())
        .map(|(n, &x)| {
            let c = v.voxel_centre([n % nx, (n / nx) % ny, n / (nx * ny)]);
            x * if c.x > mid { 2.0 } else { 1.0 }
        })
        .collect();
    let path = dir.join("labels.nii.gz");
    let volume = Volume::new(v.dims(), labels, *v.voxel_to_world()).unwrap();
    write_nifti(&path, &volume, NiftiType::U8).unwrap();
    path
}

/// The voxel overlap of the foregrounds of two volumes on one grid.
fn dice(a: &Volume, b: &Volume) -> f64 {
    let (mut both, mut sum) = (0.0, 0.0);
    for (x, y) in a.data().iter().zip(b.data()) {
        both += f64::from(u8::from(*x > 0.0 && *y > 0.0));
        sum += f64::from(u8::from(*x > 0.0)) + f64::from(u8::from(*y > 0.0));
    }
    2.0 * both / sum
}

/// Voxel centres of `grid` (every 3rd along each axis) as a VTK point set in `path`.
fn grid_points(grid: &Volume, path: &Path) -> Vec<Vec3> {
    let [nx, ny, nz] = grid.dims();
    let points: Vec<Vec3> = (0..nz)
        .step_by(3)
        .flat_map(|k| {
            (0..ny)
                .step_by(3)
                .flat_map(move |j| (0..nx).step_by(3).map(move |i| [i, j, k]))
        })
        .map(|index| grid.voxel_centre(index))
        .collect();
    let data = PolyData {
        points: points.clone(),
        vertices: (0..points.len()).map(|i| vec![i]).collect(),
        ..PolyData::default()
    };
    write_polydata(path, &data, WriteOptions::default()).unwrap();
    points
}

#[test]
fn a_label_image_is_pulled_back_and_its_warp_matches_the_point_map_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let labels = label_image(dir.path());
    let target = example("target.nii.gz");
    let (out, warp) = (
        dir.path().join("moved.nii.gz"),
        dir.path().join("warp.nii.gz"),
    );
    let summary = apply(&[
        s(&labels),
        "--out",
        s(&out),
        "--like",
        s(&target),
        "--warp",
        s(&warp),
    ]);
    println!("image pull-back: {summary}");
    assert_eq!(summary["labels"], true);
    let moved = read_nifti_file(&out).unwrap();
    assert!(moved.labels && moved.datatype == NiftiType::U8);
    assert!(moved
        .volume
        .data()
        .iter()
        .all(|&v| [0.0, 1.0, 2.0].contains(&v)));
    assert!(moved.volume.data().contains(&2.0));
    let target_mask = read_nifti(&target).unwrap();
    assert_eq!(moved.volume.dims(), target_mask.dims());
    // The carried template overlaps the target far better than the template itself.
    let unmoved = dir.path().join("unmoved.nii.gz");
    let o = medial(&[
        "rasterize",
        s(&example("template.vtk")),
        "--like",
        s(&target),
        "--out",
        s(&unmoved),
    ]);
    assert!(o.status.success());
    let (after, before) = (
        dice(&moved.volume, &target_mask),
        dice(&read_nifti(&unmoved).unwrap(), &target_mask),
    );
    println!("voxel Dice with the target: {before:.3} → {after:.3}");
    assert!(after > 0.8 && after > before + 0.1, "{before} → {after}");
    // The warp sends a grid point y to y + d(y) = F⁻¹(y), as the inverse point map does.
    let warp = medial_io::warp::read_warp(&warp).unwrap();
    let (points, pulled) = (dir.path().join("grid.vtk"), dir.path().join("pulled.vtk"));
    let y = grid_points(&target_mask, &points);
    apply(&[s(&points), "--out", s(&pulled), "--inverse"]);
    let by_warp: Vec<Vec3> = y.iter().map(|p| warp.map(p)).collect();
    let error = max_distance(&by_warp, &read_polydata(&pulled).unwrap().points);
    // Within the control grid's tolerance (0.01 voxel of 0.5 mm) and float32's rounding.
    assert!(error < 0.005 + 1e-5, "warp vs point map: {error} mm");
    // With --inverse, the warp of an image carried back holds F.
    let (back, inverse_warp) = (dir.path().join("back.nii"), dir.path().join("inverse.nii"));
    apply(&[
        s(&out),
        "--out",
        s(&back),
        "--inverse",
        "--like",
        s(&labels),
        "--warp",
        s(&inverse_warp),
    ]);
    let warp = medial_io::warp::read_warp(&inverse_warp).unwrap();
    let grid = read_nifti(&labels).unwrap();
    let (points, pushed) = (dir.path().join("grid2.vtk"), dir.path().join("pushed.vtk"));
    let x = grid_points(&grid, &points);
    apply(&[s(&points), "--out", s(&pushed)]);
    let by_warp: Vec<Vec3> = x.iter().map(|p| warp.map(p)).collect();
    let error = max_distance(&by_warp, &read_polydata(&pushed).unwrap().points);
    let spacing = grid.spacing().min();
    assert!(
        error < 0.01 * spacing + 1e-5,
        "inverse warp vs point map: {error} mm"
    );
    // Carried there and back, the labels mostly come back.
    let round = read_nifti(&back).unwrap();
    assert!(dice(&round, &grid) > 0.9, "{}", dice(&round, &grid));
}

/// The rows of a CSV file with a header, as numbers.
fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn the_atom_table_agrees_with_the_medial_vtk() {
    let dir = fit_dir();
    let (header, rows) = csv_rows(&dir.join("atoms.csv"));
    assert_eq!(
        header,
        [
            "atom",
            "spokes",
            "thickness_t0",
            "thickness_t1",
            "x_t1",
            "y_t1",
            "z_t1",
            "max_spoke_normal_deg",
            "mismatch_pct",
            "fidelity"
        ]
    );
    assert_eq!(rows.len(), 189);
    let medial = |n: usize| read_polydata(&dir.join(format!("flow/medial_t{n:03}.vtk"))).unwrap();
    let (start, end) = (medial(0), medial(STEPS));
    let array = |d: &PolyData, name: &str| d.point_array(name).unwrap().values.clone();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
    for (m, row) in rows.iter().enumerate() {
        assert_eq!(row[0], m as f64);
        assert!([1.0, 2.0].contains(&row[1]));
        assert!(close(row[2], array(&start, "Thickness")[m]), "atom {m}");
        assert!(close(row[3], array(&end, "Thickness")[m]), "atom {m}");
        for c in 0..3 {
            assert!(close(row[4 + c], end.points[m][c]), "atom {m}");
        }
        assert!(close(row[8], array(&end, "SpokeMismatch")[m]), "atom {m}");
        assert!(close(row[9], array(&end, "BallResidual")[m]), "atom {m}");
        assert!(row[7] >= 0.0 && row[7] <= 90.0);
    }
    let spokes: f64 = rows.iter().map(|r| r[1]).sum();
    assert_eq!(spokes, 314.0);
    let npy = medial_io::npy::read_npy(&dir.join("atoms.npy")).unwrap();
    assert_eq!(npy.shape, [189, 10]);
    assert_eq!(npy.data, rows.concat());
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let files: Vec<&str> = (summary["files"].as_array().unwrap().iter())
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        files.contains(&"atoms.csv") && files.contains(&"atoms.npy"),
        "{files:?}"
    );
}

/// A copy of the fit folder's files (not its sub-folders; its links followed) in `dir`.
fn copy_fit(dir: &Path) -> PathBuf {
    let copy = dir.join("fit");
    std::fs::create_dir_all(&copy).unwrap();
    for entry in std::fs::read_dir(fit_dir()).unwrap().flatten() {
        if entry.path().is_file() {
            std::fs::copy(entry.path(), copy.join(entry.file_name())).unwrap();
        }
    }
    copy
}

#[test]
fn what_is_not_a_complete_fit_or_does_not_fit_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (example("template.vtk"), dir.path().join("o.vtk"));
    let args = |fit: &Path| -> Vec<String> {
        ["apply", s(fit), s(&input), "--out", s(&out)]
            .map(String::from)
            .to_vec()
    };
    let run = |fit: &Path, code, needles: &[&str]| {
        let a = args(fit);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        one_line_error(&a, code, needles)
    };
    run(
        dir.path(),
        1,
        &["not a complete fit folder", "summary.json"],
    );
    let copy = copy_fit(dir.path());
    std::fs::write(copy.join("summary.json"), "{\"status\": \"conv").unwrap();
    run(&copy, 1, &["not a complete fit folder", "malformed"]);
    let copy = copy_fit(&dir.path().join("b"));
    medial_io::npy::write_npy(&copy.join("momenta.npy"), &[2, 3], &[0.0; 6]).unwrap();
    run(&copy, 1, &["momenta.npy", "differ from the SHA-256"]);
    reseal(&copy);
    run(&copy, 1, &["momenta.npy", "[10, 503, 3]"]);
    let copy = copy_fit(&dir.path().join("c"));
    let momenta = medial_io::npy::read_npy(&copy.join("momenta.npy")).unwrap();
    let doubled: Vec<f64> = momenta.data.iter().map(|u| 2.0 * u).collect();
    medial_io::npy::write_npy(&copy.join("momenta.npy"), &momenta.shape, &doubled).unwrap();
    reseal(&copy);
    run(&copy, 1, &["have changed since the fit"]);
    let fit = fit_dir();
    let image = example("target.nii.gz");
    one_line_error(
        &[
            "apply",
            s(fit),
            s(&input),
            "--out",
            s(&out),
            "--warp",
            "w.nii.gz",
        ],
        2,
        &["--like"],
    );
    one_line_error(
        &["apply", s(fit), s(&image), "--out", s(&out)],
        2,
        &["both be images"],
    );
}
