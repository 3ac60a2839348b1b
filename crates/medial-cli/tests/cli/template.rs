//! End-to-end tests of `medial template` through the built binary (issue 10): templates built
//! from a synthetic cup's segmentation and from the toy's (three sheets meeting at a seam) and
//! its mesh (`medial synth`, their templates rasterized by `medial rasterize`) meet the targets
//! in their JSON figures and in the files they write; the sheet found in a real leaflet's
//! segmentation lies on cmrep's fitted sheet and its Voronoi skeleton; bad input ends with a
//! one-line error and a non-zero exit.

use crate::common::{data, f, medial, one_line_error, run_json, s, text};
use medial_core::construction::MedialSheet;
use medial_core::image::volume::Volume;
use medial_core::mesh::distance::SurfaceDistance;
use medial_core::mesh::topology::{check_closed_oriented_manifold, check_outward};
use medial_core::mesh::TriMesh;
use medial_core::model::SpokeMetrics;
use medial_core::Vec3;
use medial_io::nifti_volume::{read_nifti, write_nifti, NiftiType};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The synthetic cup's template rasterized with 0.5 mm voxels, written into `dir`.
fn cup_mask(dir: &Path) -> PathBuf {
    synth_mask(dir, "cup").1
}

/// `medial synth SHAPE` into `dir/SHAPE` and its template rasterized with 0.5 mm voxels into
/// `dir/SHAPE.nii.gz`: the case folder and the mask.
fn synth_mask(dir: &Path, shape: &str) -> (PathBuf, PathBuf) {
    let case = dir.join(shape);
    run_json(&["synth", shape, "--out", s(&case), "-q"]);
    let mask = dir.join(format!("{shape}.nii.gz"));
    run_json(&[
        "rasterize",
        s(&case.join("template.vtk")),
        "--spacing",
        "0.5",
        "--out",
        s(&mask),
        "-q",
    ]);
    (case, mask)
}

/// The figures' targets (issue 10) hold.
fn assert_targets(figures: &Value) {
    let dice = f(&figures["dice"]);
    let angle = f(&figures["max_spoke_normal_deg"]);
    let mismatch = f(&figures["max_spoke_mismatch_pct"]);
    assert!(dice >= 0.95, "voxel Dice {dice}");
    // Against the input's own grid: segmentations only (null for a mesh).
    if !figures["dice_input_grid"].is_null() {
        assert!(f(&figures["dice_input_grid"]) >= 0.95, "{figures}");
    }
    assert!(angle <= 0.1, "max spoke-normal {angle}°");
    assert!(mismatch <= 0.1, "max spoke mismatch {mismatch} %");
    // No wall of the shape left out of the sheet (islands of noise hold far less than 1 %).
    assert!(f(&figures["medial_left_out"]) < 0.01, "{figures}");
    for key in [
        "closed_manifold",
        "outward",
        "self_intersection_free",
        "meets_targets",
    ] {
        assert_eq!(figures[key], Value::Bool(true), "{key}: {figures}");
    }
}

#[test]
fn a_template_of_the_synthetic_cup_meets_the_targets() {
    let dir = tempfile::tempdir().unwrap();
    let mask = cup_mask(dir.path());
    // The template's folder need not exist: it is made (before the work, not found missing
    // at its end).
    let out = dir.path().join("templates/cup/template.vtk");
    let sheet = dir.path().join("sheet.vtk");
    let figures = run_json(&[
        "template",
        s(&mask),
        "--out",
        s(&out),
        "--sheet",
        s(&sheet),
        "--atoms",
        "100",
        "-q",
    ]);
    eprintln!("{figures:#}");
    assert_targets(&figures);
    assert!(f(&figures["dice_before_fit"]) < f(&figures["dice"]));
    assert_eq!(figures["sheets"], 1);
    assert_eq!(figures["seams"], 0);
    assert_eq!(figures["atoms_by_spokes"][2], 0, "no seam atoms on a cup");
    let atoms = figures["atoms"].as_u64().unwrap();
    assert!((80..=200).contains(&atoms), "{atoms} atoms for --atoms 100");
    let [thin, thick] = [0, 1].map(|i| f(&figures["thickness_mm"][i]));
    // The cup's wall is 4–8 mm thick (crates/medial-core/src/synth); the free edge of the
    // rasterized cut rim, a wedge whose medial axis thins to its tip, comes out thinner
    // (2.8 mm measured with --atoms 100).
    assert!(
        thin > 2.0 && thick < 9.0 && thin < thick,
        "{thin}–{thick} mm"
    );

    // The figures are also written beside the template, and agree with what was printed.
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("json")).unwrap())
            .unwrap();
    assert_eq!(written["atoms"], figures["atoms"]);
    assert_eq!(written["dice"], figures["dice"]);

    // The template file, read back independently, is what the figures say.
    let template = medial_io::cmrep::read_template(&out).expect("a cmrep template");
    assert_eq!(template.medial_count() as u64, atoms);
    let m = SpokeMetrics::compute(&template, template.landmarks());
    assert!(
        m.max_spoke_normal_deg <= 0.1 + 1e-9,
        "{}",
        m.max_spoke_normal_deg
    );
    assert!(100.0 * m.max_spoke_mismatch <= 0.1 + 1e-9);
    let boundary = template.boundary_mesh().unwrap();
    check_closed_oriented_manifold(&boundary).expect("closed, manifold");
    check_outward(&boundary).expect("outward");
    // The sheet is written too, with its radius.
    let sheet = medial_io::sheet::read_sheet(&sheet, "Radius").expect("a medial sheet");
    assert!(sheet.radius().iter().all(|&r| r > 0.0));
}

/// A noisy segmentation of the shipped toy: 10 % of its boundary voxels flipped (`medial synth
/// --from --flip 0.1 --seed 1`). As given its sheet folds in the band stitched to the seam at
/// 300, 600 and 1,200 atoms; built again from the segmentation smoothed by half a voxel
/// (decision 0414) it is sound, and the figures say why it was.
#[test]
fn a_noisy_segmentation_of_the_toy_builds_its_three_sheets() {
    let dir = tempfile::tempdir().unwrap();
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy/template.vtk");
    let case = dir.path().join("noisy");
    let noisy = ["--flip", "0.1", "--seed", "1"];
    run_json(
        &[
            &["synth", "--from", s(&toy), "--out", s(&case), "-q"][..],
            &noisy,
        ]
        .concat(),
    );
    let shape = case.join("target.nii.gz");
    let out = dir.path().join("noisy.vtk");
    let figures = run_json(&["template", s(&shape), "--out", s(&out), "-q"]);
    assert_targets(&figures);
    let counts = (figures["sheets"].as_u64(), figures["seams"].as_u64());
    assert_eq!(counts, (Some(3), Some(1)), "{figures}");
    let why = figures["denoised"]
        .as_str()
        .expect("built from the smoothed segmentation");
    assert!(why.contains("folds"), "{why}");
}

#[test]
fn a_template_of_the_toy_has_its_three_sheets_stitched_at_its_seam() {
    let dir = tempfile::tempdir().unwrap();
    let (case, mask) = synth_mask(dir.path(), "toy");
    // Three sheets meeting at one seam, from the segmentation, from the mesh itself, and from
    // the toy's target segmentation (twisted, bent and mapped affinely: curved sheets).
    let shapes = [
        ("mask", mask),
        ("mesh", case.join("template.vtk")),
        ("warped", case.join("target.nii.gz")),
    ];
    for (name, shape) in shapes {
        let out = dir.path().join(format!("{name}.vtk"));
        let sheet = dir.path().join(format!("{name}_sheet.vtk"));
        let work = dir.path().join(format!("{name}_work"));
        let figures = run_json(&[
            "template",
            s(&shape),
            "--out",
            s(&out),
            "--sheet",
            s(&sheet),
            "--work",
            s(&work),
            "-q",
        ]);
        eprintln!("toy {name}: {figures:#}");
        assert_targets(&figures);
        assert_eq!(figures["dice_input_grid"].is_null(), name == "mesh");
        assert_eq!(
            (figures["sheets"].as_u64(), figures["seams"].as_u64()),
            (Some(3), Some(1))
        );
        let by_spokes: Vec<u64> = (0..3)
            .map(|k| figures["atoms_by_spokes"][k].as_u64().unwrap())
            .collect();
        assert!(by_spokes.iter().all(|&n| n > 0), "{by_spokes:?}");
        // About the default 300 atoms (278 from the mask, 382 from the mesh, 324 from the
        // target since decision 0408: the sheets' lattices have whole rings, and three
        // samplings at most are tried to come nearer).
        let atoms = figures["atoms"].as_u64().unwrap();
        assert!(
            (240..=400).contains(&atoms),
            "{name}: {atoms} atoms for 300"
        );
        // The template file: its seam atoms have three spokes, as many as the figures say.
        let template = medial_io::cmrep::read_template(&out).expect("a cmrep template");
        let three = (0..template.medial_count())
            .filter(|&m| template.spokes(m).len() == 3)
            .count();
        assert_eq!(three as u64, by_spokes[2]);
        // Its `Sheet` point array: the wall of each boundary point's atom, −1 on the seam
        // (every atom of three spokes), each of the three sheets present.
        let data = medial_io::vtk::read_polydata(&out).unwrap();
        let sheet_of = &data.point_array_ci("Sheet").expect("a Sheet array").values;
        let mut walls = std::collections::BTreeSet::new();
        for (b, &m) in template.medial_index().iter().enumerate() {
            if template.spokes(m).len() == 3 {
                assert_eq!(
                    sheet_of[b], -1.0,
                    "{name}: seam atom {m} labelled {}",
                    sheet_of[b]
                );
            } else if sheet_of[b] >= 0.0 {
                walls.insert(sheet_of[b] as i64);
            }
        }
        assert_eq!(
            walls.into_iter().collect::<Vec<_>>(),
            vec![0, 1, 2],
            "{name}"
        );
        let boundary = template.boundary_mesh().unwrap();
        check_closed_oriented_manifold(&boundary).expect("closed, manifold");
        check_outward(&boundary).expect("outward");
        // The sheet written: a seam of edges in three triangles, no edge in more.
        let sheet = medial_io::sheet::read_sheet(&sheet, "Radius").expect("a medial sheet");
        let mut edges: std::collections::HashMap<(usize, usize), usize> = Default::default();
        for t in sheet.triangles() {
            for k in 0..3 {
                let (u, v) = (t[k], t[(k + 1) % 3]);
                *edges.entry((u.min(v), u.max(v))).or_default() += 1;
            }
        }
        let seam_edges = edges.values().filter(|&&n| n == 3).count();
        assert!(seam_edges >= 4, "{seam_edges} seam edges");
        assert!(edges.values().all(|&n| n <= 3));
        assert_work_folder(&work, &figures, &sheet);
    }
}

/// What `--work` wrote for a toy built at once from 300 atoms: its medial points on three
/// sheets and one seam, the three sheets' lattices, the seam's polyline, and the stitched sheet
/// (the one `--sheet` wrote, labelled by sheet, −1 on the seam).
fn assert_work_folder(work: &Path, figures: &Value, sheet_written: &MedialSheet) {
    let labels = |path: &Path, name: &str| -> std::collections::BTreeSet<i64> {
        let data = medial_io::vtk::read_polydata(path).unwrap();
        let array = data
            .point_array_ci(name)
            .unwrap_or_else(|| panic!("{name} in {path:?}"));
        assert_eq!(array.values.len(), data.points.len());
        array.values.iter().map(|&v| v as i64).collect()
    };
    assert!(read_nifti(&work.join("shape_mask.nii.gz")).is_ok());
    let points = work.join("medial_points.vtk");
    let data = medial_io::vtk::read_polydata(&points).unwrap();
    assert_eq!(
        data.points.len() as u64,
        figures["medial_points"].as_u64().unwrap()
    );
    assert_eq!(labels(&points, "Sheet"), [-1, 0, 1, 2].into());
    assert_eq!(labels(&points, "Seam"), [-1, 0].into());
    let sampling = work.join("300_atoms");
    assert_eq!(
        labels(&sampling.join("lattices.vtk"), "Sheet"),
        [0, 1, 2].into()
    );
    let seams = medial_io::vtk::read_polydata(&sampling.join("seams.vtk")).unwrap();
    assert_eq!(seams.lines.len(), 1);
    let stitched = medial_io::vtk::read_polydata(&sampling.join("sheet.vtk")).unwrap();
    assert_eq!(stitched.points, sheet_written.points());
    assert_eq!(
        labels(&sampling.join("sheet.vtk"), "Sheet"),
        [-1, 0, 1, 2].into()
    );
}

/// A build that fails after finding the medial points (four sheets meeting at one seam, which
/// no medial template can hold) leaves them in `--work`: the mask and the medial points, with
/// the four sheets and the seam that made it fail.
#[test]
fn a_failed_build_leaves_what_it_found_in_the_work_folder() {
    let dir = tempfile::tempdir().unwrap();
    // Two slabs 3 mm thick crossing at right angles, extruded: an X in cross-section.
    let dims = [60, 60, 40];
    let inside = |i: usize, j: usize, k: usize| {
        let slab = |u: usize, v: usize| (27..33).contains(&u) && (8..52).contains(&v);
        (5..35).contains(&k) && (slab(i, j) || slab(j, i))
    };
    let mut data = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                data.push(if inside(i, j, k) { 1.0 } else { 0.0 });
            }
        }
    }
    let affine = nalgebra::Matrix4::new_nonuniform_scaling(&Vec3::repeat(0.5));
    let cross = dir.path().join("cross.nii.gz");
    write_nifti(
        &cross,
        &Volume::new(dims, data, affine).unwrap(),
        NiftiType::U8,
    )
    .unwrap();
    let work = dir.path().join("work");
    let out = dir.path().join("t.vtk");
    one_line_error(
        &["template", s(&cross), "--out", s(&out), "--work", s(&work)],
        1,
        &["4 triangles", "4 sheets meet along it"],
    );
    assert!(!out.exists());
    assert!(read_nifti(&work.join("shape_mask.nii.gz")).is_ok());
    let points = medial_io::vtk::read_polydata(&work.join("medial_points.vtk")).unwrap();
    let label_set = |name: &str| -> std::collections::BTreeSet<i64> {
        let array = points.point_array_ci(name).unwrap();
        array.values.iter().map(|&v| v as i64).collect()
    };
    assert_eq!(label_set("Sheet"), [-1, 0, 1, 2, 3].into());
    assert_eq!(label_set("Seam"), [-1, 0].into());
}

/// biv-me's template heart (a real two-ventricle myocardium, 1 mm) as given: three sheets
/// meeting along the RV insertion seam, built with default options into a sound template
/// (decisions 0402, 0406, 0408), built again from 600 atoms (decision 0409) for its Dice below
/// the 0.95 target at 300 (0.920 once mended where it crossed itself after the fit, decision
/// 0410; 0.943 from 600). Under the 0.95 of [`assert_targets`]: guarded at the 0.93. The
/// same heart on other grids: [`the_biv_me_heart_builds_wherever_its_voxels_fall`].
#[test]
fn the_biv_me_heart_builds_as_three_sheets_meeting_at_a_seam() {
    let heart = data("bivme/template_myocardium.nii.gz");
    let dir = tempfile::tempdir().unwrap();
    assert_heart_template("as given", &heart, &dir.path().join("heart.vtk"));
}

/// The biv-me heart moved by a fraction of a voxel (a stand-in for the same heart segmented on
/// another grid: before decision 0408 that move found no seam) and turned by 24.4° (a heart
/// scanned at an angle to the world axes, its voxels resampled), each built as
/// [`the_biv_me_heart_builds_as_three_sheets_meeting_at_a_seam`]: moved, 0.930 from 300 atoms;
/// turned, 0.934 from 600. Without decision 0413's rule (a lattice that turns past 90° laid
/// again on its closed region) the turned heart's 600- and 1,200-atom sheets fold by 177–179°
/// and its template stays at 300 atoms and 0.921 (a rotation drawn at random, never tuned on;
/// its addendum). Two builds of 1.5–3 minutes each: run with `--ignored` (decision 0200's
/// addendum of 2026-12-08).
#[test]
#[ignore]
fn the_biv_me_heart_builds_wherever_its_voxels_fall() {
    let dir = tempfile::tempdir().unwrap();
    let heart = data("bivme/template_myocardium.nii.gz");
    let mask = read_nifti(&heart).unwrap();
    let [nx, ny, nz] = mask.dims().map(|n| n as f64);
    let centre = Vec3::new(nx - 1.0, ny - 1.0, nz - 1.0) / 2.0;
    let turn = nalgebra::Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vec3::new(0.9614, -0.2750, -0.0136)),
        24.39_f64.to_radians(),
    );
    let cases = [
        (
            "moved by (0.1, 0.4, 0.9) voxel",
            2,
            translation(&Vec3::new(-0.1, -0.4, -0.9)),
        ),
        (
            "turned by 24.4°",
            mask.dims().into_iter().max().unwrap() / 6,
            translation(&centre) * turn.inverse().to_homogeneous() * translation(&-centre),
        ),
    ];
    for (k, (name, pad, motion)) in cases.into_iter().enumerate() {
        let shape = dir.path().join(format!("heart{k}.nii.gz"));
        write_nifti(&shape, &resampled(&mask, pad, motion), NiftiType::U8).unwrap();
        assert_heart_template(name, &shape, &dir.path().join(format!("heart{k}.vtk")));
    }
}

/// `medial template` of the heart `shape` with default options, written to `out`: three sheets
/// and one seam, ten or more three-spoke atoms, built again at more atoms and kept, voxel Dice
/// ≥ 0.93, ≤ 0.1° and ≤ 0.1 %, closed, manifold, outward and free of self-intersection.
fn assert_heart_template(name: &str, shape: &Path, out: &Path) {
    let figures = run_json(&["template", s(shape), "--out", s(out), "-q"]);
    let counts = (figures["sheets"].as_u64(), figures["seams"].as_u64());
    assert_eq!(counts, (Some(3), Some(1)), "{name}: {figures}");
    assert!(
        figures["atoms_by_spokes"][2].as_u64().unwrap() >= 10,
        "{name}: {figures}"
    );
    assert!(f(&figures["dice"]) >= 0.93, "{name}: {figures}");
    let again = &figures["sampled_again"];
    assert_ne!(
        again["kept"], again["first"],
        "{name}: built again and kept: {figures}"
    );
    assert!(again["not_kept"].is_array(), "{figures}");
    assert!(figures["band_put_back"].is_array(), "{figures}");
    assert!(figures["spokes_shortened"]["atoms"].is_array(), "{figures}");
    assert!(
        f(&figures["max_spoke_normal_deg"]) <= 0.1,
        "{name}: {figures}"
    );
    assert!(
        f(&figures["max_spoke_mismatch_pct"]) <= 0.1,
        "{name}: {figures}"
    );
    for key in ["closed_manifold", "outward", "self_intersection_free"] {
        assert_eq!(figures[key], Value::Bool(true), "{name}, {key}: {figures}");
    }
}

/// The translation by `by` as a homogeneous matrix.
fn translation(by: &Vec3) -> nalgebra::Matrix4<f64> {
    nalgebra::Matrix4::new_translation(by)
}

/// The segmentation `mask` on its own grid `pad` voxels wider each side, moved: the new image at
/// voxel `v` (the old grid's numbering) holds the old one at `motion · v`, its foreground
/// interpolated trilinearly and cut at one half.
fn resampled(mask: &Volume, pad: usize, motion: nalgebra::Matrix4<f64>) -> Volume {
    let dims = mask.dims().map(|n| n + 2 * pad);
    let padded = translation(&Vec3::repeat(-(pad as f64)));
    let sampled = (mask.foreground(None))
        .resampled(dims, mask.voxel_to_world() * (motion * padded))
        .unwrap();
    let data = sampled
        .data()
        .iter()
        .map(|&v| f64::from(u8::from(v > 0.5)))
        .collect();
    Volume::new(dims, data, mask.voxel_to_world() * padded).unwrap()
}

/// The distances (mm) from `points` to the nearest point of `sheet` (its triangles), ascending.
fn to_sheet(points: &[Vec3], sheet: &MedialSheet) -> Vec<f64> {
    let surface = TriMesh::new(sheet.points().to_vec(), sheet.triangles().to_vec()).unwrap();
    let surface = SurfaceDistance::new(&surface).unwrap();
    let mut d: Vec<f64> = points.iter().map(|p| surface.distance(p)).collect();
    d.sort_by(f64::total_cmp);
    d
}

/// Per point of `points`, its radius in `radius` less that of the nearest of `others` in
/// `other_radius` (mm).
fn radius_difference(
    points: &[Vec3],
    radius: &[f64],
    others: &[Vec3],
    other_radius: &[f64],
) -> Vec<f64> {
    (points.iter().zip(radius))
        .map(|(p, r)| {
            let nearest = (0..others.len())
                .min_by(|&a, &b| (p - others[a]).norm().total_cmp(&(p - others[b]).norm()))
                .unwrap();
            r - other_radius[nearest]
        })
        .collect()
}

/// The mean of `values`.
fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

#[test]
fn the_leaflet_sheet_lies_on_cmreps_fitted_sheet_and_on_its_voronoi_skeleton() {
    let data = data("cmrep/leaflets");
    let dir = tempfile::tempdir().unwrap();
    let (out, sheet) = (dir.path().join("leaflet.vtk"), dir.path().join("sheet.vtk"));
    let shape = data.join("target_anterior.nii.gz");
    run_json(&[
        "template",
        s(&shape),
        "--out",
        s(&out),
        "--sheet",
        s(&sheet),
        "--no-fit",
        "-q",
    ]);
    let ours = medial_io::sheet::read_sheet(&sheet, "Radius").unwrap();
    let cmrep = medial_io::sheet::read_sheet(&data.join("anterior_def1_A.vtk"), "Radius").unwrap();
    // The voxels are 0.83 × 0.82 × 0.73 mm.
    let ours_to_cmrep = to_sheet(ours.points(), &cmrep);
    let cmrep_to_ours = to_sheet(cmrep.points(), &ours);
    // The skeleton's points (its `Radius`, 2.3 mm on average, up to 4.0 mm, is not the
    // leaflet's half thickness: not compared).
    let skeleton = medial_io::vtk::read_polydata(&data.join("skeleton_anterior.vtk")).unwrap();
    let mut ours_to_skeleton: Vec<f64> = (ours.points().iter())
        .map(|p| {
            (skeleton.points.iter())
                .map(|q| (p - q).norm())
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    ours_to_skeleton.sort_by(f64::total_cmp);
    let against_cmrep =
        radius_difference(ours.points(), ours.radius(), cmrep.points(), cmrep.radius());
    let median = |d: &[f64]| d[d.len() / 2];
    eprintln!(
        "leaflet: {} vertices; to cmrep's sheet mean {:.3} median {:.3} max {:.3} mm, cmrep's {} \
         to ours mean {:.3} max {:.3} mm; to the skeleton's {} points mean {:.3} median {:.3} \
         mm; radius less cmrep's {:.3} mm on average",
        ours.points().len(),
        mean(&ours_to_cmrep),
        median(&ours_to_cmrep),
        ours_to_cmrep[ours_to_cmrep.len() - 1],
        cmrep.points().len(),
        mean(&cmrep_to_ours),
        cmrep_to_ours[cmrep_to_ours.len() - 1],
        skeleton.points.len(),
        mean(&ours_to_skeleton),
        median(&ours_to_skeleton),
        mean(&against_cmrep),
    );
    // Within half a voxel of cmrep's sheet on average, and cmrep's sheet (which reaches
    // further into the rim: ours ends where the two sides stop facing each other) within a
    // voxel of ours; half of ours within half a voxel of the skeleton's points (4,205 of
    // them, a few tenths of a millimetre apart). Our radius is larger than cmrep's: cmrep's
    // sheet inflated holds 694 mm³, the segmentation 1,919 mm³ (3,862 voxels of 0.497 mm³).
    assert!(mean(&ours_to_cmrep) <= 0.4, "{ours_to_cmrep:?}");
    assert!(mean(&cmrep_to_ours) <= 0.8, "{cmrep_to_ours:?}");
    assert!(median(&ours_to_skeleton) <= 0.4, "{ours_to_skeleton:?}");
    assert!(mean(&against_cmrep) > 0.0, "{against_cmrep:?}");
}

#[test]
fn bad_input_gives_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let mask = cup_mask(dir.path());
    let out = dir.path().join("t.vtk");
    let sheet = dir.path().join("t_sheet.vtk");
    let (out, sheet) = (s(&out), s(&sheet));

    // An empty segmentation: every voxel 0.
    let image = read_nifti(&mask).unwrap();
    let empty_volume = Volume::new(
        image.dims(),
        vec![0.0; image.data().len()],
        *image.voxel_to_world(),
    )
    .unwrap();
    let empty = dir.path().join("empty.nii.gz");
    write_nifti(&empty, &empty_volume, NiftiType::U8).unwrap();
    let line = one_line_error(
        &["template", s(&empty), "--out", out, "--sheet", sheet],
        1,
        &["empty"],
    );
    assert!(line.contains("empty.nii.gz"), "{line}");
    // A label no voxel has.
    one_line_error(
        &["template", s(&mask), "--out", out, "--label", "7"],
        1,
        &["empty", "labelled 7"],
    );
    // A missing file.
    one_line_error(
        &["template", "no/such/shape.nii.gz", "--out", out],
        1,
        &["no/such/shape.nii.gz"],
    );
    // Not a NIfTI file.
    let garbage = dir.path().join("garbage.nii.gz");
    std::fs::write(&garbage, "not an image").unwrap();
    one_line_error(&["template", s(&garbage), "--out", out], 1, &["garbage"]);
    // Meshes: not a VTK file, a mesh without points, an open mesh, an unknown extension, a
    // missing mesh.
    let write = |name: &str, content: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, content).unwrap();
        path
    };
    let header = "# vtk DataFile Version 3.0\nmesh\nASCII\nDATASET POLYDATA\n";
    let meshes = [
        ("not_vtk.vtk", "not a mesh".to_string(), "legacy VTK"),
        (
            "no_points.vtk",
            format!("{header}POINTS 0 float\nPOLYGONS 0 0\n"),
            "no points",
        ),
        (
            "open.vtk",
            format!("{header}POINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 4\n3 0 1 2\n"),
            "open",
        ),
    ];
    for (name, content, expected) in meshes {
        let mesh = write(name, &content);
        one_line_error(
            &["template", s(&mesh), "--out", out, "--sheet", sheet],
            1,
            &[name, expected],
        );
    }
    let text_file = write("shape.txt", "1 2 3");
    one_line_error(
        &["template", s(&text_file), "--out", out],
        1,
        &["shape.txt", "extension"],
    );
    one_line_error(
        &["template", "no/such/mesh.vtk", "--out", out],
        1,
        &["no/such/mesh.vtk"],
    );
    // --label with a mesh (the open one written above).
    let open = dir.path().join("open.vtk");
    one_line_error(
        &["template", s(&open), "--out", out, "--label", "1"],
        2,
        &["--label"],
    );
    // Wrong command lines (exit 2).
    // (clap prints its usage line after a conflict: exit 2, the error on the first line)
    let o = medial(&[
        "template",
        s(&mask),
        "--out",
        out,
        "--atoms",
        "100",
        "--spacing",
        "2",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = text(&o.stderr);
    assert!(err.starts_with("error: ") && err.lines().next().unwrap().contains("--spacing"));
    one_line_error(
        &["template", s(&mask), "--out", out, "--voxel=-1"],
        2,
        &["--voxel"],
    );
    // Nothing was written: no template, no sheet, no figures.
    for path in [out, sheet, s(&Path::new(out).with_extension("json"))] {
        assert!(!Path::new(path).exists(), "{path} was written");
    }
    let o = medial(&["template", s(&mask)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
}
