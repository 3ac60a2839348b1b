//! Medial sheets recovered from shapes with a known medial sheet: the synthetic cup and the
//! toy (three sheets meeting at a seam), their templates rasterized (the templates' own medial
//! points are the true sheet; its radius is their distance to the templates' boundary).

use medial::construction::{sheet_of_mask, MedialAxis, MedialSheet, Sampling, ShapeSheet};
use medial::image::rasterize::{grid_around, rasterize};
use medial::mesh::distance::SurfaceDistance;
use medial::model::{MedialTemplate, SpokeMetrics};
use medial::synth::{Shape, SyntheticCase};
use medial::Vec3;

/// Voxel of the rasterized shapes, mm.
const VOXEL: f64 = 0.4;

/// The closest point of triangle `abc` to `p` and its barycentric weights (Ericson, Real-Time
/// Collision Detection, 5.1.5).
fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, [f64; 3]) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + v * ab + w * ac, [1.0 - v - w, v, w])
}

/// The closest point to `p` of the template's medial sheet and the spoke radius (the mean
/// spoke, interpolated) there.
fn to_sheet(template: &MedialTemplate, radius: &[f64], p: Vec3) -> (Vec3, f64) {
    let m = template.medial_points();
    template
        .medial_triangles()
        .iter()
        .map(|t| {
            let (q, w) = closest_on_triangle(p, m[t[0]], m[t[1]], m[t[2]]);
            let r = w[0] * radius[t[0]] + w[1] * radius[t[1]] + w[2] * radius[t[2]];
            (q, r)
        })
        .min_by(|a, b| (p - a.0).norm().total_cmp(&(p - b.0).norm()))
        .expect("a sheet has triangles")
}

/// The template of a synthetic shape, and the medial axis and sheet recovered from its
/// rasterization.
fn recover(shape: Shape) -> (MedialTemplate, MedialAxis, ShapeSheet) {
    let case = SyntheticCase::build(shape).unwrap();
    let template = case.projection.template;
    let boundary = template.boundary_mesh().unwrap();
    let (dims, to_world) = grid_around(&boundary, VOXEL, 3.0 * VOXEL).unwrap();
    let mask = rasterize(&boundary, dims, to_world).unwrap();
    let axis = MedialAxis::of_mask(&mask).unwrap();
    let found = axis.sheet(Sampling::Atoms(300)).unwrap();
    (template, axis, found)
}

/// How far a recovered vertex is from the true sheet and how far its radius is from the
/// true ones (mm).
struct VertexError {
    /// Distance to the true sheet.
    distance: f64,
    /// Recovered radius less the shape's medial radius at the closest true medial point: its
    /// distance to the shape's boundary, the radius of the largest ball there inside the shape.
    radius: f64,
    /// Recovered radius less the template's spoke radius there. Near a free edge the template's
    /// spokes are longer than the distance to its own boundary mesh: the boundary triangles
    /// from the last spokes of each side to the rim's spoke cut the spheres the spokes
    /// describe (a polyhedral wedge, up to 1 mm inside them at 2 mm from the toy's rim), so
    /// the shape rasterized has the thinner medial axis of that wedge there.
    spoke: f64,
}

/// Per vertex of the recovered sheet `found` inside it (off its free edges: the rasterized rim
/// is a polyhedral wedge whose medial axis thins to its tip, not the rounded rim the spokes
/// describe; and off its seams) its [`VertexError`] against the template.
fn sheet_errors(template: &MedialTemplate, found: &ShapeSheet) -> Vec<VertexError> {
    let border: std::collections::HashSet<usize> = found.border.iter().copied().collect();
    let seam_vertices: usize = found.seams.iter().map(|s| s.points.len()).sum();
    vertex_errors(template, &found.sheet, |k| {
        !border.contains(&k) && k >= seam_vertices
    })
}

/// The [`VertexError`] against the template of each vertex of `sheet` that `kept` keeps.
fn vertex_errors(
    template: &MedialTemplate,
    sheet: &MedialSheet,
    kept: impl Fn(usize) -> bool,
) -> Vec<VertexError> {
    let metrics = SpokeMetrics::compute(template, template.landmarks());
    let radius: Vec<f64> = metrics.thickness.iter().map(|t| t / 2.0).collect();
    let boundary = SurfaceDistance::new(&template.boundary_mesh().unwrap()).unwrap();
    (sheet.points().iter().zip(sheet.radius()).enumerate())
        .filter(|(k, _)| kept(*k))
        .map(|(_, (p, r))| {
            let (q, spoke) = to_sheet(template, &radius, *p);
            VertexError {
                distance: (p - q).norm(),
                radius: r - boundary.distance(&q),
                spoke: r - spoke,
            }
        })
        .collect()
}

/// The points of `sheet` on its free edges (edges of one triangle).
fn free_points(sheet: &MedialSheet) -> std::collections::HashSet<usize> {
    let mut count: std::collections::HashMap<(usize, usize), usize> = Default::default();
    for t in sheet.triangles() {
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            *count.entry((u.min(v), u.max(v))).or_default() += 1;
        }
    }
    (count.into_iter())
        .filter(|&(_, n)| n == 1)
        .flat_map(|((u, v), _)| [u, v])
        .collect()
}

/// The figures of `errors` as one line, and the largest radius error against the shape's
/// medial radius (mm): distance mean and max, radius error mean and max |·| against the
/// medial radius and against the spokes.
fn summary(errors: &[VertexError]) -> (String, [f64; 3]) {
    let (mean_d, max_d) = mean_max(errors.iter().map(|e| e.distance));
    let n = errors.len() as f64;
    let mean = |f: fn(&VertexError) -> f64| errors.iter().map(f).sum::<f64>() / n;
    let max_abs =
        |f: fn(&VertexError) -> f64| errors.iter().map(|e| f(e).abs()).fold(0.0, f64::max);
    let (mean_r, max_r) = (mean(|e| e.radius), max_abs(|e| e.radius));
    let (mean_s, max_s) = (mean(|e| e.spoke), max_abs(|e| e.spoke));
    let line = format!(
        "{} vertices, distance mean {mean_d:.3} max {max_d:.3} mm; radius error mean {mean_r:.3} \
         max |{max_r:.3}| mm (against the spokes: mean {mean_s:.3} max |{max_s:.3}| mm)",
        errors.len()
    );
    (line, [mean_d, max_d, max_r])
}

/// The mean and the largest of `values`.
fn mean_max(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count() as f64;
    (values.clone().sum::<f64>() / n, values.fold(0.0, f64::max))
}

#[test]
fn the_cup_sheet_is_recovered_within_half_a_voxel_on_average_and_its_radius_within_a_voxel() {
    let (template, _, found) = recover(Shape::Cup);
    let (line, [mean_d, max_d, max_r]) = summary(&sheet_errors(&template, &found));
    eprintln!("cup: {line}");
    assert!(
        mean_d <= VOXEL / 2.0,
        "sheet {mean_d} mm from the true one on average"
    );
    assert!(max_d <= VOXEL, "sheet {max_d} mm from the true one");
    assert!(max_r <= VOXEL, "radius off by {max_r} mm");
}

#[test]
fn the_subdivided_cup_sheet_stays_on_the_medial_sheet_where_plain_subdivision_leaves_it() {
    // Loop subdivision moves each point towards its neighbours' mean, off a curved sheet; the
    // template's atoms are the subdivided sheet's points placed again on the medial points.
    let (template, _, found) = recover(Shape::Cup);
    let subdivided = found.subdivided().unwrap().sheet;
    let plain = found.sheet.loop_subdivide().unwrap();
    assert_eq!(subdivided.triangles(), plain.triangles());
    let free = free_points(&subdivided);
    let errors =
        |sheet: &MedialSheet| summary(&vertex_errors(&template, sheet, |k| !free.contains(&k)));
    let (line, [mean_d, max_d, max_r]) = errors(&subdivided);
    let (plain_line, [plain_mean, plain_max, _]) = errors(&plain);
    eprintln!("cup subdivided: {line}\nplain Loop subdivision: {plain_line}");
    assert!(
        mean_d <= VOXEL / 2.0,
        "{mean_d} mm from the true sheet on average"
    );
    // The row next to the free edge, where the rasterized rim thins to a wedge, lies a little
    // farther off than the coarse sheet's inner points.
    assert!(max_d <= 1.5 * VOXEL, "{max_d} mm from the true sheet");
    assert!(max_r <= VOXEL, "radius off by {max_r} mm");
    assert!(
        mean_d < plain_mean && max_d < plain_max,
        "placed {mean_d}/{max_d} mm, plain subdivision {plain_mean}/{plain_max} mm"
    );
}

/// The distance from `p` to the polyline `line` (mm).
fn to_polyline(line: &[Vec3], p: &Vec3) -> f64 {
    line.windows(2)
        .map(|w| {
            let e = w[1] - w[0];
            let t = ((p - w[0]).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            (p - (w[0] + t * e)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn the_toy_seam_is_recovered_within_a_voxel_its_sheets_within_half_a_voxel_on_average_and_their_radius_within_a_voxel(
) {
    let (template, axis, found) = recover(Shape::Toy);
    let counts = axis.branches.counts;
    assert_eq!((counts.sheets, counts.seams), (3, 1));
    // The true seam: the template's medial edges in three triangles, along z (its ends, where
    // it meets the free edges, are corners with one spoke per region there).
    let mut in_triangles: std::collections::HashMap<(usize, usize), usize> = Default::default();
    for t in template.medial_triangles() {
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            *in_triangles.entry((u.min(v), u.max(v))).or_default() += 1;
        }
    }
    let mut on_seam: Vec<usize> = (in_triangles.iter())
        .filter(|&(_, &n)| n == 3)
        .flat_map(|(&(u, v), _)| [u, v])
        .collect();
    on_seam.sort_unstable();
    on_seam.dedup();
    let z = |m: &usize| template.medial_points()[*m].z;
    on_seam.sort_by(|a, b| z(a).total_cmp(&z(b)));
    let seam: Vec<Vec3> = on_seam
        .iter()
        .map(|&m| template.medial_points()[m])
        .collect();
    let recovered = &found.seams[0].points;
    // Off its ends (on the free edges, as the sheets' free-edge vertices are left out below).
    let inner = &recovered[1..recovered.len() - 1];
    let (mean_seam, max_seam) = mean_max(inner.iter().map(|p| to_polyline(&seam, p)));
    // Its ends, where the sheets' free edges meet it, lie where the wide-angle medial points of
    // the rounded rim end: beyond the true ends (z = ±12 mm), within the true end's radius.
    let metrics = SpokeMetrics::compute(&template, template.landmarks());
    let true_end = seam[seam.len() - 1].z;
    let end_radius = metrics.thickness[on_seam[on_seam.len() - 1]] / 2.0;
    let found_ends = [recovered[0].z, recovered[recovered.len() - 1].z];
    let (lo, hi) = (
        found_ends[0].min(found_ends[1]),
        found_ends[0].max(found_ends[1]),
    );
    let (line, [mean_d, _, max_r]) = summary(&sheet_errors(&template, &found));
    eprintln!(
        "toy: seam {} vertices, off its ends distance mean {mean_seam:.3} max {max_seam:.3} \
         mm, ends {lo:.2} {hi:.2} mm (true ±{true_end:.2}, radius {end_radius:.2}); sheets: {line}",
        recovered.len()
    );
    assert!(max_seam <= VOXEL, "seam {max_seam} mm from the true one");
    for end in [-lo, hi] {
        assert!(
            end >= true_end - VOXEL && end <= true_end + end_radius,
            "seam end at ±{end} mm"
        );
    }
    assert!(
        mean_d <= VOXEL / 2.0,
        "sheets {mean_d} mm from the true ones on average"
    );
    assert!(max_r <= VOXEL, "sheets' radius off by {max_r} mm");
}

#[test]
fn a_branching_shape_gets_about_the_atoms_asked_for() {
    let case = SyntheticCase::build(Shape::Toy).unwrap();
    let boundary = case.projection.template.boundary_mesh().unwrap();
    let (dims, to_world) = grid_around(&boundary, VOXEL, 3.0 * VOXEL).unwrap();
    let mask = rasterize(&boundary, dims, to_world).unwrap();
    // Whole rings make a lattice's count jump (the toy's 12 × 24 mm sheets at 300 atoms: 29,
    // 34 or 58 points each), and the stitching drops a band along the seam: the sheets are
    // sampled again at a spacing corrected by the count (at 0.5 mm voxels, rounding the rings
    // alone gave 1.26 and 0.97 times as many).
    for asked in [300, 1000] {
        let found = sheet_of_mask(&mask, Sampling::Atoms(asked)).unwrap();
        let ratio = found.sheet.subdivided_point_count() as f64 / asked as f64;
        eprintln!("toy, {asked} atoms asked: {ratio:.2} times as many");
        assert!(
            (0.8..=1.25).contains(&ratio),
            "{asked} asked: {ratio:.2} times as many"
        );
    }
}

#[test]
fn the_toy_band_along_its_seam_is_placed_on_the_medial_sheets_and_can_be_put_back() {
    // The stitching's band from each sheet's cut to the seam is a straight strip of triangles;
    // its atoms are placed on the medial points like the others, and kept as subdivided beside.
    let (template, _, found) = recover(Shape::Toy);
    let subdivided = found.subdivided().unwrap();
    let sheet = &subdivided.sheet;
    let free = free_points(sheet);
    let band: Vec<usize> = (0..sheet.points().len())
        .filter(|&m| subdivided.band[m].is_some() && !free.contains(&m))
        .collect();
    let in_band = |k: usize| band.binary_search(&k).is_ok();
    let (line, [mean_d, _, max_r]) = summary(&vertex_errors(&template, sheet, in_band));
    let (straight, moved) = subdivided
        .band_put_back(sheet, 0..sheet.points().len())
        .unwrap();
    let (straight_line, [straight_d, ..]) = summary(&vertex_errors(&template, &straight, in_band));
    eprintln!("toy band placed: {line}\nas subdivided: {straight_line}");
    // Placed: 0.034 mm on average; as subdivided 0.069 mm.
    assert!(
        mean_d < straight_d,
        "placed {mean_d} mm, subdivided {straight_d} mm"
    );
    assert!(band.len() >= 20, "{} band atoms", band.len());
    assert!(
        mean_d <= VOXEL / 2.0,
        "band {mean_d} mm from the true sheets on average"
    );
    assert!(max_r <= VOXEL, "band radius off by {max_r} mm");
    // Every band atom the fit moved is put back, and nothing else; a second time, none.
    let expected: Vec<usize> = (0..sheet.points().len())
        .filter(|&m| subdivided.band[m].is_some_and(|(p, _)| p != sheet.points()[m]))
        .collect();
    assert_eq!(moved, expected);
    let (_, again) = subdivided
        .band_put_back(&straight, 0..sheet.points().len())
        .unwrap();
    assert!(again.is_empty(), "{again:?}");
    for &m in &moved {
        assert_eq!(
            (straight.points()[m], straight.radius()[m]),
            subdivided.band[m].unwrap()
        );
    }
}
