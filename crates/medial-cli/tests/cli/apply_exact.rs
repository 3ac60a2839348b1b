//! `medial apply` carries exactly the fitted map (issue 34) and images through a control grid
//! within its tolerance of the exact map (issue 32): an automatic fit of the toy to its target
//! points moved by an anisotropic affine map (so the initial map is affine and the template is
//! projected after it).

use crate::common::{f, medial, run_json, s, text};
use medial_core::Vec3;
use medial_io::vtk::read_polydata;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The time steps of an automatic point fit.
fn last_boundary(dir: &Path) -> PathBuf {
    let mut b: Vec<PathBuf> = std::fs::read_dir(dir.join("flow"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("boundary_t")
        })
        .collect();
    b.sort();
    b.pop().unwrap()
}

/// The synthetic case and the automatic fit's folder, made once.
fn case() -> &'static (tempfile::TempDir, PathBuf, PathBuf) {
    static CASE: OnceLock<(tempfile::TempDir, PathBuf, PathBuf)> = OnceLock::new();
    CASE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let case = dir.path().join("toy");
        let affine = dir.path().join("affine.txt");
        std::fs::write(&affine, "1.12 0 0 0\n0 0.93 0 0\n0 0 1 0\n0 0 0 1\n").unwrap();
        let o = medial(&["synth", "toy", "--out", s(&case), "--affine", s(&affine)]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let out = dir.path().join("fit");
        let o = medial(&[
            "fit",
            "--template",
            s(&case.join("template.vtk")),
            "--target",
            s(&case.join("target_boundary.vtk")),
            "--out",
            s(&out),
            "-q",
        ]);
        let err = text(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(err.contains("initial affine"), "{err}");
        assert!(
            err.contains("projected onto its constraints after the affine map"),
            "{err}"
        );
        (dir, case, out)
    })
}

fn points(path: &Path) -> Vec<Vec3> {
    read_polydata(path).unwrap().points
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

#[test]
fn the_given_template_goes_to_the_fits_last_boundary_alignment_and_projection_included() {
    let (dir, case, fit) = case();
    let template = case.join("template.vtk");
    let (moved, back) = (dir.path().join("moved.vtk"), dir.path().join("back.vtk"));
    let summary = run_json(&["apply", s(fit), s(&template), "--out", s(&moved)]);
    assert_eq!(summary["template_space"], "given");
    assert!(summary.get("voxels").is_none(), "{summary}");
    assert_eq!(
        summary["points"].as_u64(),
        Some(points(&template).len() as u64)
    );
    let error = max_distance(&points(&moved), &points(&last_boundary(fit)));
    println!("given template through apply vs the fit's last boundary: {error:e} mm");
    assert!(error <= 1e-9, "{error} mm");
    let fitted = max_distance(&points(&moved), &points(&fit.join("fitted_template.vtk")));
    assert!(fitted <= 1e-9, "{fitted} mm");
    run_json(&["apply", s(fit), s(&moved), "--out", s(&back), "--inverse"]);
    let round_trip = max_distance(&points(&back), &points(&template));
    println!("back to the given template: {round_trip:e} mm");
    assert!(round_trip <= 1e-6, "{round_trip} mm");
}

#[test]
fn the_aligned_template_goes_there_by_the_flow_alone() {
    let (dir, _, fit) = case();
    let aligned = fit.join("aligned_template.vtk");
    let moved = dir.path().join("moved_aligned.vtk");
    let summary = run_json(&[
        "apply",
        s(fit),
        s(&aligned),
        "--out",
        s(&moved),
        "--template-space",
        "aligned",
    ]);
    assert_eq!(summary["template_space"], "aligned");
    let error = max_distance(&points(&moved), &points(&last_boundary(fit)));
    assert!(error <= 1e-9, "{error} mm");
    // Read as the given template's space, the aligned template is carried by A once more:
    // far from the fit (the mistake issue 34 describes).
    let twice = dir.path().join("twice.vtk");
    run_json(&["apply", s(fit), s(&aligned), "--out", s(&twice)]);
    let off = max_distance(&points(&twice), &points(&last_boundary(fit)));
    assert!(off > 0.1, "{off} mm");
}

/// The largest distance between the warps of two pull-backs (RAS or LPS alike), voxels of
/// `spacing` mm.
fn warp_difference(a: &Path, b: &Path, spacing: f64) -> f64 {
    let (a, b) = (
        medial_io::warp::read_warp(a).unwrap(),
        medial_io::warp::read_warp(b).unwrap(),
    );
    let n = a.components[0].data().len();
    (0..n)
        .map(|i| {
            let d = Vec3::from_fn(|c, _| a.components[c].data()[i] - b.components[c].data()[i]);
            d.norm()
        })
        .fold(0.0, f64::max)
        / spacing
}

#[test]
fn images_through_the_control_grid_are_within_the_tolerance_of_the_exact_map() {
    let (dir, case, fit) = case();
    let image = case.join("target.nii.gz");
    let spacing = medial_io::nifti_volume::read_nifti(&image)
        .unwrap()
        .spacing()
        .min();
    for inverse in [false, true] {
        let run = |exact: bool| {
            let tag = format!("{inverse}_{exact}");
            let out = dir.path().join(format!("out_{tag}.nii.gz"));
            let warp = dir.path().join(format!("warp_{tag}.nii.gz"));
            let mut args = vec![
                "apply",
                s(fit),
                s(&image),
                "--out",
                s(&out),
                "--warp",
                s(&warp),
            ];
            if inverse {
                args.push("--inverse");
            }
            if exact {
                args.push("--exact");
            }
            (run_json(&args), warp)
        };
        let (grid, grid_warp) = run(false);
        let (exact, exact_warp) = run(true);
        assert!(grid.get("points").is_none(), "{grid}");
        assert_eq!(grid["voxels"], exact["voxels"]);
        assert!(
            grid["control_grid"]["stride"].as_u64().unwrap() >= 1,
            "{grid}"
        );
        assert!(exact.get("control_grid").is_none(), "{exact}");
        // float32 warps: a few 1e-7 mm of rounding besides the map's own difference.
        let voxels = warp_difference(&grid_warp, &exact_warp, spacing);
        println!(
            "inverse {inverse}: grid vs exact, max {voxels:.2e} voxels; {:.3} s against {:.3} s",
            f(&grid["seconds"]),
            f(&exact["seconds"])
        );
        assert!(voxels <= 0.01, "{voxels} voxels");
        assert!(f(&grid["max_displacement_mm"]) > 1.0, "{grid}");
    }
}

#[test]
fn a_bad_tolerance_is_a_one_line_error() {
    let (dir, case, fit) = case();
    let o = medial(&[
        "apply",
        s(fit),
        s(&case.join("target.nii.gz")),
        "--out",
        s(&dir.path().join("x.nii.gz")),
        "--tolerance",
        "0",
    ]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(err.contains("--tolerance"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
