//! Template inflation from a medial sheet (docs/method.md §9.1): flat slab, the paper's three-sheet toy,
//! the real placenta sheet against cmrep's own inflation, Loop subdivision, and errors.

use std::collections::{BTreeMap, HashMap};
use std::f64::consts::PI;
use std::path::Path;

use medial::construction::inflate::{
    inflate, self_intersections, Inflated, MedialSheet, RadiusLimit,
};
use medial::mesh::topology::{signed_volume, MeshDefect};
use medial::synth::parameter_grid;
use medial::{Error, Vec3};
use proptest::prelude::*;

use medial::testing::meshes::octahedron;

const CMREP: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/cmrep/");

// ---------------------------------------------------------------------------------------------
// Builders

/// A sheet over `parameter_grid(nu, nv)`: points `f(u, v)`, radii `r(point)`.
fn grid_sheet(
    nu: usize,
    nv: usize,
    f: impl Fn(f64, f64) -> Vec3,
    r: impl Fn(&Vec3) -> f64,
) -> MedialSheet {
    let (params, triangles) = parameter_grid(nu, nv).expect("at least one cell each way");
    let points: Vec<Vec3> = params.iter().map(|p| f(p[0], p[1])).collect();
    let radius = points.iter().map(&r).collect();
    MedialSheet::new(points, triangles, radius).expect("valid grid sheet")
}

/// The flat square `[0, side]²` in the plane z = 0, `n × n` cells.
fn square(n: usize, side: f64, r: impl Fn(&Vec3) -> f64) -> MedialSheet {
    grid_sheet(n, n, |u, v| Vec3::new(side * u, side * v, 0.0), r)
}

/// The angles of the three sheets of the toy about the seam (the z axis).
const Y_ANGLES: [f64; 3] = [
    PI / 2.0,
    PI / 2.0 + 2.0 * PI / 3.0,
    PI / 2.0 + 4.0 * PI / 3.0,
];

/// The paper's toy: three rectangular sheets `width × length` (`nw × nz` cells each) meeting
/// along the seam `x = y = 0, 0 ≤ z ≤ length` at 120°; sheet 1 is oriented the other way.
/// The seam points are points `0 ..= nz`.
fn y_sheet(nw: usize, nz: usize, width: f64, length: f64, radius: f64) -> MedialSheet {
    let (params, cells) = parameter_grid(nw, nz).expect("at least one cell each way");
    let mut points: Vec<Vec3> = (0..=nz)
        .map(|j| Vec3::new(0.0, 0.0, length * j as f64 / nz as f64))
        .collect();
    let mut triangles = Vec::new();
    for (s, angle) in Y_ANGLES.iter().enumerate() {
        let dir = Vec3::new(angle.cos(), angle.sin(), 0.0);
        let mut global = Vec::with_capacity(params.len());
        for (k, p) in params.iter().enumerate() {
            if k % (nw + 1) == 0 {
                global.push(k / (nw + 1));
            } else {
                global.push(points.len());
                points.push(width * p[0] * dir + Vec3::new(0.0, 0.0, length * p[1]));
            }
        }
        for t in &cells {
            let [a, b, c] = t.map(|v| global[v]);
            triangles.push(if s == 1 { [a, c, b] } else { [a, b, c] });
        }
    }
    let n = points.len();
    MedialSheet::new(points, triangles, vec![radius; n]).expect("valid Y sheet")
}

// ---------------------------------------------------------------------------------------------
// Independent checks of an inflation

/// The number of spokes of every atom.
fn spoke_counts(medial_index: &[usize], atoms: usize) -> Vec<usize> {
    let mut counts = vec![0; atoms];
    medial_index.iter().for_each(|&m| counts[m] += 1);
    counts
}

/// How many atoms have 1, 2, 3 spokes.
fn spoke_histogram(counts: &[usize]) -> [usize; 3] {
    let mut h = [0; 3];
    for &c in counts {
        assert!((1..=3).contains(&c), "an atom has {c} spokes");
        h[c - 1] += 1;
    }
    h
}

/// Asserts the boundary is closed and consistently oriented (each directed edge once, its
/// reverse once), that [`Inflated::volume`] is its enclosed volume, and that its points are
/// sorted by atom.
fn assert_valid(inflated: &Inflated) {
    let mut directed: HashMap<(usize, usize), usize> = HashMap::new();
    for t in inflated.boundary.triangles() {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(i, j), &n) in &directed {
        assert_eq!(n, 1, "directed boundary edge {i} → {j} occurs {n} times");
        assert_eq!(
            directed.get(&(j, i)),
            Some(&1),
            "boundary edge {i} → {j} has no twin"
        );
    }
    // The enclosed volume of the boundary, by the divergence theorem about the origin instead of
    // about the centroid: the two must agree.
    let about_origin = signed_volume(inflated.boundary.points(), inflated.boundary.triangles());
    assert!(
        (inflated.volume() - about_origin).abs() <= 1e-10 * about_origin.abs(),
        "volume {} but {about_origin} about the origin",
        inflated.volume()
    );
    assert!(
        inflated.medial_index.windows(2).all(|w| w[0] <= w[1]),
        "points not sorted by atom"
    );
    assert_eq!(
        inflated.medial_index.len(),
        inflated.boundary.points().len()
    );
}

/// The spokes `b − x_m` of every boundary point.
fn spokes(inflated: &Inflated) -> Vec<Vec3> {
    let p = inflated.boundary.points();
    (0..p.len())
        .map(|b| p[b] - inflated.medial_points[inflated.medial_index[b]])
        .collect()
}

// ---------------------------------------------------------------------------------------------
// (1) Flat square slab

#[test]
fn flat_square_inflates_to_a_slab_with_a_wedge_rim() {
    let (n, side, r) = (100, 10.0, 0.1);
    let sheet = square(n, side, |_| r);
    let inflated = inflate(&sheet).expect("flat square inflates");
    assert_valid(&inflated);

    let counts = spoke_counts(&inflated.medial_index, sheet.points().len());
    for (m, x) in sheet.points().iter().enumerate() {
        let border = x.x == 0.0 || x.y == 0.0 || x.x == side || x.y == side;
        assert_eq!(counts[m], if border { 1 } else { 2 }, "atom {m} at {x:?}");
    }
    let h = spoke_histogram(&counts);
    assert_eq!(h, [4 * n, (n - 1) * (n - 1), 0]);

    // Interior spokes are ±r·ẑ; border spokes are in the plane, perpendicular to the border.
    for (b, s) in spokes(&inflated).iter().enumerate() {
        let m = inflated.medial_index[b];
        if counts[m] == 2 {
            assert!(
                (s.x.abs() + s.y.abs()) < 1e-12 && (s.z.abs() - r).abs() < 1e-12,
                "spoke {b} = {s:?}"
            );
        } else {
            assert!(
                s.z.abs() < 1e-12 && (s.norm() - r).abs() < 1e-12,
                "border spoke {b} = {s:?}"
            );
        }
    }
    let x = sheet.points()[n / 2]; // the middle of the side y = 0
    let b = inflated
        .medial_index
        .iter()
        .position(|&m| m == n / 2)
        .unwrap();
    assert!((inflated.boundary.points()[b] - (x - Vec3::new(0.0, r, 0.0))).norm() < 1e-12);

    // The piecewise linear boundary: slab over the interior rows, a wedge of cross-section
    // r (h + r) along each side (planar strips from the first interior row at z = ±r to the rim),
    // and four corners that each add at most (h + r)² · 2r.
    let hh = side / n as f64;
    let inner = side - 2.0 * hh;
    let wedges = inner * inner * 2.0 * r + 4.0 * inner * r * (hh + r);
    let corners = 4.0 * (hh + r) * (hh + r) * 2.0 * r;
    let volume = inflated.volume();
    assert!(
        volume > wedges && volume < wedges + corners,
        "volume {volume} outside [{wedges}, {}]",
        wedges + corners
    );
    // Against the smooth slab with half-cylinder rims: the wedge rims lose ≈ r h + (π/2 − 1) r²
    // per unit length of border.
    let smooth = side * side * 2.0 * r + 4.0 * side * PI * r * r / 2.0;
    let deficit = (smooth - volume) / smooth;
    println!(
        "flat square: volume {volume:.4} mm³, smooth slab {smooth:.4} mm³, deficit {:.2} %",
        100.0 * deficit
    );
    assert!(deficit > 0.0 && deficit < 0.035, "deficit {deficit}");
}

#[test]
fn linear_radius_gives_exact_medial_spokes() {
    let grad = Vec3::new(0.08, -0.03, 0.0);
    let sheet = square(10, 10.0, |x| 1.0 + grad.dot(x));
    let inflated = inflate(&sheet).expect("linear radius inflates");
    assert_valid(&inflated);
    let counts = spoke_counts(&inflated.medial_index, sheet.points().len());
    let spokes = spokes(&inflated);
    let normal_part = (1.0 - grad.norm_squared()).sqrt();
    for (b, s) in spokes.iter().enumerate() {
        let m = inflated.medial_index[b];
        if counts[m] == 2 {
            let want = sheet.radius()[m] * (-grad + s.z.signum() * normal_part * Vec3::z());
            assert!((s - want).norm() < 1e-12, "spoke {b}: {s:?} vs {want:?}");
        }
    }
    // The envelope of the balls is a pair of planes; the spokes are normal to the boundary
    // triangles whose corners all belong to two-spoke atoms.
    let p = inflated.boundary.points();
    let mut checked = 0;
    for t in inflated.boundary.triangles() {
        if t.iter().all(|&b| counts[inflated.medial_index[b]] == 2) {
            let n = (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]])).normalize();
            for &b in t {
                assert!(
                    n.cross(&spokes[b].normalize()).norm() < 1e-12,
                    "spoke {b} not normal"
                );
            }
            checked += 1;
        }
    }
    assert!(checked > 100);
}

#[test]
fn orientation_of_the_sheet_does_not_matter() {
    let base = square(8, 4.0, |x| 0.3 + 0.02 * x.x);
    let flipped_triangles: Vec<[usize; 3]> = base
        .triangles()
        .iter()
        .enumerate()
        .map(|(t, &[a, b, c])| if t % 3 == 0 { [a, c, b] } else { [a, b, c] })
        .collect();
    let flipped = MedialSheet::new(
        base.points().to_vec(),
        flipped_triangles,
        base.radius().to_vec(),
    )
    .unwrap();
    let (one, two) = (inflate(&base).unwrap(), inflate(&flipped).unwrap());
    assert_valid(&two);
    assert_eq!(one.medial_index, two.medial_index);
    assert!((one.volume() - two.volume()).abs() < 1e-12 * one.volume());
    // Same points per atom (region order within an atom may differ).
    let by_atom = |inf: &Inflated| {
        let mut map: BTreeMap<usize, Vec<[i64; 3]>> = BTreeMap::new();
        for (b, p) in inf.boundary.points().iter().enumerate() {
            map.entry(inf.medial_index[b])
                .or_default()
                .push(p.map(|c| (c * 1e9).round() as i64).into());
        }
        map.values_mut().for_each(|v| v.sort_unstable());
        map
    };
    assert_eq!(by_atom(&one), by_atom(&two));
}

// ---------------------------------------------------------------------------------------------
// (2) The paper's toy: three sheets on one seam

#[test]
fn three_sheets_on_a_seam_give_three_spokes() {
    let (nw, nz, width, length, r) = (6, 8, 3.0, 4.0, 0.4);
    let sheet = y_sheet(nw, nz, width, length, r);
    let inflated = inflate(&sheet).expect("Y inflates");
    assert_valid(&inflated);
    let counts = spoke_counts(&inflated.medial_index, sheet.points().len());
    // Seam: 3 spokes inside, 1 at both ends (where the three free edges meet).
    for (j, &count) in counts.iter().enumerate().take(nz + 1) {
        assert_eq!(
            count,
            if j == 0 || j == nz { 1 } else { 3 },
            "seam atom {j}"
        );
    }
    let h = spoke_histogram(&counts);
    let border_per_sheet = 2 * nw + (nz - 1); // z = 0 and z = length rows (w ≥ 1), and w = width
    assert_eq!(
        h,
        [2 + 3 * border_per_sheet, 3 * (nw - 1) * (nz - 1), nz - 1]
    );

    // Seam spokes bisect the 120° regions; the seam ends point along ∓z.
    let spokes = spokes(&inflated);
    for (b, s) in spokes.iter().enumerate() {
        let m = inflated.medial_index[b];
        if m == 0 || m == nz {
            let want = Vec3::new(0.0, 0.0, if m == 0 { -r } else { r });
            assert!((s - want).norm() < 1e-12, "seam end spoke {b} = {s:?}");
        } else if m < nz {
            let angle = s.y.atan2(s.x).rem_euclid(2.0 * PI);
            let bisectors = Y_ANGLES.map(|a| (a + PI / 3.0).rem_euclid(2.0 * PI));
            assert!(
                bisectors.iter().any(|&a| (a - angle).abs() < 1e-9),
                "seam spoke {b} at {angle} rad"
            );
            assert!((s.norm() - r).abs() < 1e-12 && s.z.abs() < 1e-12);
        }
    }
    // Three slabs of 2r thickness, minus the rim wedges, roughly.
    let slabs = 3.0 * width * length * 2.0 * r;
    let volume = inflated.volume();
    println!(
        "Y toy: {} boundary points, volume {volume:.3} mm³ (three slabs {slabs:.3})",
        inflated.boundary.points().len()
    );
    assert!((volume - slabs).abs() < 0.1 * slabs, "volume {volume}");
}

#[test]
fn subdivided_y_inflates_and_keeps_its_seam() {
    // Sheet points come within 0.28 of the seam; the offsets of two sheets at 120° cross each
    // other unless the radius is below 0.28 · tan 60° = 0.49.
    let coarse = y_sheet(4, 4, 3.0, 4.0, 0.3);
    let sheet = coarse.loop_subdivide().unwrap();
    let inflated = inflate(&sheet).expect("subdivided Y inflates");
    assert_valid(&inflated);
    let counts = spoke_counts(&inflated.medial_index, sheet.points().len());
    assert_eq!(
        spoke_histogram(&counts)[2],
        7,
        "a seam of 9 points has 7 three-spoke atoms"
    );
    assert_eq!(inflated.limit, RadiusLimit::default(), "nothing to limit");
    // A radius of 0.5 folds the offsets of the sheets across the seam (0.5 > 0.49): it is
    // lowered there, to at most 0.6 · 0.28 · tan 60° = 0.29 next to the seam, and the rest of
    // the sheets keep theirs.
    let thick = MedialSheet::new(
        sheet.points().to_vec(),
        sheet.triangles().to_vec(),
        vec![0.5; sheet.points().len()],
    )
    .unwrap();
    let inflated = inflate(&thick).expect("the thick Y inflates once limited");
    assert_valid(&inflated);
    assert!(self_intersections(&inflated.boundary).is_empty());
    let limit = &inflated.limit;
    println!(
        "thick Y: {} of {} vertices lowered ({} bound), by up to {:.1} % (mean {:.1} %), {} \
         shrink rounds",
        limit.vertices.len(),
        thick.points().len(),
        limit.bound.len(),
        limit.max_pct(),
        limit.mean_pct(),
        limit.shrink_rounds
    );
    assert!(!limit.bound.is_empty() && limit.vertices.len() < thick.points().len());
    for &m in &limit.bound {
        let from_seam = thick.points()[m].xy().norm();
        assert!(
            from_seam < 1.0,
            "vertex {m} bound {from_seam} from the seam"
        );
    }
    assert!(
        limit.max_pct() > 40.0 && limit.max_pct() < 100.0,
        "{limit:?}"
    );
    for (&m, &pct) in limit.vertices.iter().zip(&limit.reduction_pct) {
        assert!(
            (inflated.radius[m] - 0.5 * (1.0 - pct / 100.0)).abs() < 1e-12,
            "vertex {m}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// (3) The placenta sheet against cmrep's inflation

fn read_vtk(name: &str) -> medial::io::vtk::PolyData {
    medial::io::vtk::read_polydata(Path::new(&format!("{CMREP}{name}"))).expect("read cmrep data")
}

fn point_array(data: &medial::io::vtk::PolyData, name: &str) -> Vec<f64> {
    data.point_data
        .iter()
        .find(|a| a.name == name)
        .unwrap_or_else(|| panic!("no array {name}"))
        .values
        .clone()
}

#[test]
fn placenta_matches_cmrep_structure() {
    let medial = read_vtk("placenta_template_anterioralign3.vtk");
    let sheet = MedialSheet::new(
        medial.points.clone(),
        medial.triangles().unwrap(),
        point_array(&medial, "Radius"),
    )
    .expect("placenta sheet");
    assert_eq!((sheet.points().len(), sheet.triangles().len()), (115, 204));
    let fine = sheet.loop_subdivide().unwrap();
    assert_eq!((fine.points().len(), fine.triangles().len()), (433, 816));
    let inflated = inflate(&fine).expect("placenta inflates");
    assert_valid(&inflated);
    assert_eq!(
        inflated.limit,
        RadiusLimit::default(),
        "a sheet that inflates as given keeps its radius"
    );
    let ours = spoke_histogram(&spoke_counts(&inflated.medial_index, fine.points().len()));

    let cmrep = read_vtk("placenta_template_anterioralign3_bcmrep.vtk");
    let cmrep_index: Vec<usize> = point_array(&cmrep, "MedialIndex")
        .iter()
        .map(|&m| m as usize)
        .collect();
    let cmrep_atoms = cmrep_index.iter().max().unwrap() + 1;
    let theirs = spoke_histogram(&spoke_counts(&cmrep_index, cmrep_atoms));
    let cmrep_triangles = cmrep.triangles().unwrap();
    println!(
        "placenta: ours {} points, {} triangles, atoms with 1/2/3 spokes {ours:?}; cmrep {} points, {} triangles, {theirs:?}; volume {:.0} mm³",
        inflated.boundary.points().len(),
        inflated.boundary.triangles().len(),
        cmrep.points.len(),
        cmrep_triangles.len(),
        inflated.volume()
    );
    assert_eq!(inflated.boundary.points().len(), cmrep.points.len());
    assert_eq!(inflated.boundary.triangles().len(), cmrep_triangles.len());
    assert_eq!(ours, theirs);
    assert_eq!(ours, [48, 385, 0]);

    // Geometry: the same surface within a fraction of a millimetre (radii 3–5 mm, edges ≈ 3 mm).
    let volume = |p: &[Vec3], t: &[[usize; 3]]| {
        t.iter()
            .map(|t| p[t[0]].dot(&p[t[1]].cross(&p[t[2]])) / 6.0)
            .sum::<f64>()
    };
    let cmrep_volume = volume(&cmrep.points, &cmrep_triangles);
    let nearest = |p: &Vec3, set: &[Vec3]| {
        set.iter()
            .map(|q| (q - p).norm())
            .fold(f64::INFINITY, f64::min)
    };
    let gaps: Vec<f64> = inflated
        .boundary
        .points()
        .iter()
        .map(|p| nearest(p, &cmrep.points))
        .collect();
    let (max_gap, mean_gap) = (
        gaps.iter().copied().fold(0.0, f64::max),
        gaps.iter().sum::<f64>() / gaps.len() as f64,
    );
    println!("placenta: volume ours {:.1} mm³, cmrep {cmrep_volume:.1} mm³; boundary point to cmrep's nearest: max {max_gap:.3} mm, mean {mean_gap:.3} mm", inflated.volume());
    assert!((inflated.volume() - cmrep_volume).abs() < 1e-3 * cmrep_volume);
    assert!(max_gap < 0.5 && mean_gap < 0.1);

    // Structure: matching atoms by the centroid of their boundary points is a bijection (the
    // original 115 vertices keep their numbers), and it maps our medial triangles onto cmrep's.
    let centroids = |p: &[Vec3], index: &[usize], atoms: usize| {
        let mut c = vec![Vec3::zeros(); atoms];
        let mut k = vec![0.0; atoms];
        index.iter().enumerate().for_each(|(b, &m)| {
            c[m] += p[b];
            k[m] += 1.0;
        });
        c.iter().zip(&k).map(|(c, k)| c / *k).collect::<Vec<_>>()
    };
    let ours_c = centroids(
        inflated.boundary.points(),
        &inflated.medial_index,
        fine.points().len(),
    );
    let theirs_c = centroids(&cmrep.points, &cmrep_index, cmrep_atoms);
    let map: Vec<usize> = ours_c
        .iter()
        .map(|c| {
            (0..cmrep_atoms)
                .min_by(|&i, &j| {
                    (theirs_c[i] - c)
                        .norm()
                        .total_cmp(&(theirs_c[j] - c).norm())
                })
                .unwrap()
        })
        .collect();
    let mut image = map.clone();
    image.sort_unstable();
    image.dedup();
    assert_eq!(image.len(), cmrep_atoms, "the atom matching is a bijection");
    assert!((0..115).all(|m| map[m] == m));
    let medial_triangles = |tris: &[[usize; 3]], atom: &dyn Fn(usize) -> usize| {
        let mut set: Vec<[usize; 3]> = tris
            .iter()
            .map(|t| {
                let mut m = t.map(atom);
                m.sort_unstable();
                m
            })
            .collect();
        set.sort_unstable();
        set.dedup();
        set
    };
    let ours_m = medial_triangles(inflated.boundary.triangles(), &|b| {
        map[inflated.medial_index[b]]
    });
    let theirs_m = medial_triangles(&cmrep_triangles, &|b| cmrep_index[b]);
    assert_eq!(ours_m.len(), 816);
    assert_eq!(ours_m, theirs_m);
}

// ---------------------------------------------------------------------------------------------
// Loop subdivision

#[test]
fn loop_subdivision_counts_and_stencils() {
    let n = 6;
    let base = square(n, 6.0, |_| 1.0);
    let centre = 3 * (n + 1) + 3; // (3, 3): even i + j, valence 8 in this grid
    let corner_cell = (n + 1) + 1; // (1, 1): valence 8 too
    let mut radius = vec![1.0; base.points().len()];
    radius[centre] = 2.0;
    let sheet =
        MedialSheet::new(base.points().to_vec(), base.triangles().to_vec(), radius).unwrap();
    let fine = sheet.loop_subdivide().unwrap();
    let edges = 3 * n * n + 2 * n; // grid edges plus one diagonal per cell
    assert_eq!(fine.points().len(), (n + 1) * (n + 1) + edges);
    assert_eq!(fine.triangles().len(), 4 * sheet.triangles().len());
    // Loop's β for valence 8: (5/8 − (3/8 + cos(π/4)/4)²)/8.
    let c = 0.375 + 0.25 * (PI / 4.0).cos();
    let beta = (0.625 - c * c) / 8.0;
    assert!((fine.radius()[centre] - (2.0 - 8.0 * beta)).abs() < 1e-14);
    assert!((fine.radius()[corner_cell] - 1.0).abs() < 1e-14);
    // Edge points next to the bump: 3/8 on its edges, 1/8 opposite it.
    let counts: HashMap<u64, usize> = fine.radius().iter().fold(HashMap::new(), |mut m, r| {
        *m.entry((r * 1e12).round() as u64).or_default() += 1;
        m
    });
    assert_eq!(
        counts[&((1.375 * 1e12) as u64)],
        8,
        "edge points on the 8 edges of the bump"
    );
    assert_eq!(
        counts[&((1.125 * 1e12) as u64)],
        8,
        "edge points opposite the bump"
    );
    // A flat sheet stays flat; the straight border stays straight with its points at the
    // crease weights (equally spaced points do not move).
    assert!(fine.points().iter().all(|p| p.z == 0.0));
    for (v, p) in sheet
        .points()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.y == 0.0 && p.x > 0.0 && p.x < 6.0)
    {
        assert!((fine.points()[v] - p).norm() < 1e-14, "border vertex {v}");
    }
}

#[test]
fn loop_subdivision_crease_and_corner_rules() {
    // Bend the Y's seam: the seam follows 1/8-3/4-1/8, the seam ends (where the three free
    // edges meet the seam) stay fixed, and edge points on the seam are midpoints.
    let y = y_sheet(2, 4, 2.0, 4.0, 0.5);
    let mut points = y.points().to_vec();
    for (j, p) in points.iter_mut().enumerate().take(5) {
        p.x = 0.1 * (j as f64) * (j as f64);
    }
    let sheet =
        MedialSheet::new(points.clone(), y.triangles().to_vec(), y.radius().to_vec()).unwrap();
    let fine = sheet.loop_subdivide().unwrap();
    assert_eq!(fine.points()[0], points[0]);
    assert_eq!(fine.points()[4], points[4]);
    for j in 1..4 {
        let want = 0.125 * points[j - 1] + 0.75 * points[j] + 0.125 * points[j + 1];
        assert!((fine.points()[j] - want).norm() < 1e-14, "seam vertex {j}");
    }
    let seam_midpoints = fine
        .points()
        .iter()
        .filter(|p| (0..4).any(|j| (**p - 0.5 * (points[j] + points[j + 1])).norm() < 1e-14))
        .count();
    assert_eq!(seam_midpoints, 4);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    /// Subdivided radii are convex combinations; inflating a bumpy sheet with random triangle
    /// orientations and a small radius gives a valid template.
    #[test]
    fn bumpy_sheets_inflate(amp in 0.0..0.3f64, freq in 0.5..2.0f64, flips in proptest::collection::vec(any::<bool>(), 32), r0 in 0.05..0.2f64) {
        let base = grid_sheet(4, 4, |u, v| Vec3::new(4.0 * u, 4.0 * v, amp * (freq * 4.0 * u).sin() * (4.0 * v).cos()), |x| r0 * (1.0 + 0.1 * x.x));
        let triangles: Vec<[usize; 3]> = base.triangles().iter().zip(&flips).map(|(&[a, b, c], &f)| if f { [a, c, b] } else { [a, b, c] }).collect();
        let sheet = MedialSheet::new(base.points().to_vec(), triangles, base.radius().to_vec()).unwrap();
        let fine = sheet.loop_subdivide().unwrap();
        let (lo, hi) = sheet.radius().iter().fold((f64::MAX, f64::MIN), |(l, h), &r| (l.min(r), h.max(r)));
        prop_assert!(fine.radius().iter().all(|&r| r >= lo - 1e-12 && r <= hi + 1e-12));
        let inflated = inflate(&fine).unwrap();
        assert_valid(&inflated);
        let h = spoke_histogram(&spoke_counts(&inflated.medial_index, fine.points().len()));
        prop_assert_eq!(h, [32, 49, 0]);
    }
}

// ---------------------------------------------------------------------------------------------
// (4) Errors

fn message(e: Error) -> String {
    e.to_string()
}

#[test]
fn sheet_validation_errors() {
    let p = vec![
        Vec3::zeros(),
        Vec3::x(),
        Vec3::y(),
        Vec3::new(1.0, 1.0, 0.0),
    ];
    let t = vec![[0, 1, 3], [0, 3, 2]];
    let e = MedialSheet::new(p.clone(), t.clone(), vec![1.0, 1.0, 0.0, 1.0]).unwrap_err();
    assert!(matches!(e, Error::InvalidTemplate(_)) && message(e).contains("medial point 2"));
    let e = MedialSheet::new(p.clone(), t.clone(), vec![1.0, -1.0, 1.0, 1.0]).unwrap_err();
    assert!(message(e).contains("medial point 1 is -1"));
    let e = MedialSheet::new(p.clone(), t.clone(), vec![1.0, f64::NAN, 1.0, 1.0]).unwrap_err();
    assert!(matches!(e, Error::NonFinite(_)));
    let e = MedialSheet::new(p.clone(), t.clone(), vec![1.0; 3]).unwrap_err();
    assert!(matches!(
        e,
        Error::ShapeMismatch {
            expected: 4,
            found: 3,
            ..
        }
    ));
    let e = MedialSheet::new(p.clone(), vec![[0, 1, 3]], vec![1.0; 4]).unwrap_err();
    assert!(message(e).contains("medial point 2 is in no triangle"));
    let e = MedialSheet::new(
        p.clone(),
        vec![[0, 1, 3], [0, 3, 2], [3, 1, 0]],
        vec![1.0; 4],
    )
    .unwrap_err();
    assert!(message(e).contains("medial triangles 0 and 2"));
    let line = vec![Vec3::zeros(), Vec3::x(), 2.0 * Vec3::x()];
    let e = MedialSheet::new(line, vec![[0, 1, 2]], vec![1.0; 3]).unwrap_err();
    assert!(message(e).contains("medial triangle 0 [0, 1, 2] is degenerate"));
    let e = MedialSheet::new(p, vec![[0, 1, 4]], vec![1.0; 4]).unwrap_err();
    assert!(matches!(
        e,
        Error::Mesh(MeshDefect::IndexOutOfRange { point: 4, .. })
    ));
}

#[test]
fn an_edge_in_four_triangles_is_refused() {
    let mut points = vec![Vec3::zeros(), Vec3::z()];
    let triangles: Vec<[usize; 3]> = (0..4)
        .map(|k| {
            let a = k as f64 * PI / 2.0;
            points.push(Vec3::new(a.cos(), a.sin(), 0.5));
            [0, 1, k + 2]
        })
        .collect();
    let e = MedialSheet::new(points, triangles, vec![0.1; 6]).unwrap_err();
    let m = message(e);
    assert!(
        m.contains("medial edge (0, 1) is in 4 triangles [0, 1, 2, 3]"),
        "{m}"
    );
}

#[test]
fn a_radius_too_large_for_the_curvature_is_limited() {
    // A cylindrical arc of radius 1 spanning 240°: the inside offset folds when r > 1.
    let arc = |r: f64| {
        grid_sheet(
            16,
            4,
            |u, v| {
                let a = 4.0 * PI / 3.0 * u;
                Vec3::new(a.cos(), a.sin(), 2.0 * v)
            },
            |_| r,
        )
    };
    let thin = inflate(&arc(0.3)).expect("thin arc inflates");
    assert_valid(&thin);
    assert_eq!(thin.limit, RadiusLimit::default());
    // r = 1.5, r·κ = 1.5: limited to at most 0.6 / κ = 0.6 wherever the sheet is bound (the
    // focal bound of a chord of the unit circle is 1), smoothly, and reported.
    let sheet = arc(1.5);
    let inflated = inflate(&sheet).expect("a thick arc inflates once limited");
    assert_valid(&inflated);
    assert!(self_intersections(&inflated.boundary).is_empty());
    assert!(
        inflated.volume() > 0.0 && inflated.volume() < thin.volume() * 5.0,
        "{}",
        inflated.volume()
    );
    let limit = &inflated.limit;
    println!(
        "thick arc: {} of {} vertices lowered ({} bound), by up to {:.1} % (mean {:.1} %), {} \
         shrink rounds",
        limit.vertices.len(),
        sheet.points().len(),
        limit.bound.len(),
        limit.max_pct(),
        limit.mean_pct(),
        limit.shrink_rounds
    );
    assert_eq!(
        limit.vertices.len(),
        sheet.points().len(),
        "every vertex is lowered"
    );
    // Away from the two straight free edges (columns 0 and 16 of the grid, whose in-plane
    // spokes see the far end of the arc instead), the bound is the focal distance 1.
    for &m in &limit.bound {
        let r = inflated.radius[m];
        let interior = m % 17 != 0 && m % 17 != 16;
        assert!(
            r <= if interior { 0.6 + 1e-9 } else { 0.61 },
            "vertex {m}: {r}"
        );
    }
    assert!(
        limit.max_pct() >= 60.0 - 1e-9 && limit.mean_pct() > 50.0,
        "{limit:?}"
    );
    // The spokes are as long as the lowered radii.
    for (b, spoke) in spokes(&inflated).iter().enumerate() {
        let r = inflated.radius[inflated.medial_index[b]];
        assert!((spoke.norm() - r).abs() < 1e-9 * r, "boundary point {b}");
    }
}

#[test]
fn steep_radius_and_ears_are_refused() {
    let m = message(inflate(&square(4, 1.0, |x| 0.1 + 1.5 * x.x)).unwrap_err());
    assert!(
        m.contains("|∇r| ≥ 1") && m.contains("medial vertices"),
        "{m}"
    );
    let single = MedialSheet::new(
        vec![Vec3::zeros(), Vec3::x(), Vec3::y()],
        vec![[0, 1, 2]],
        vec![0.1; 3],
    )
    .unwrap();
    let m = message(inflate(&single).unwrap_err());
    assert!(
        m.contains("medial triangle 0 [0, 1, 2] has 3 free edges"),
        "{m}"
    );
}

#[test]
fn a_closed_sheet_is_refused() {
    // The inner side of a closed sheet is a second shell facing inward.
    let (points, triangles) = octahedron();
    let sheet = MedialSheet::new(points, triangles, vec![0.1; 6]).unwrap();
    let m = message(inflate(&sheet).unwrap_err());
    assert!(
        m.contains("faces inward") && m.contains("medial vertices 0, 1, 2, 3, 4, 5"),
        "{m}"
    );
}

#[test]
fn inflated_templates_are_accepted_by_medial_template() {
    let medial = read_vtk("placenta_template_anterioralign3.vtk");
    let placenta = MedialSheet::new(
        medial.points.clone(),
        medial.triangles().unwrap(),
        point_array(&medial, "Radius"),
    )
    .unwrap()
    .loop_subdivide()
    .unwrap();
    for sheet in [placenta, y_sheet(6, 8, 3.0, 4.0, 0.4)] {
        let Inflated {
            boundary,
            medial_index,
            medial_points,
            ..
        } = inflate(&sheet).unwrap();
        let nb = boundary.points().len();
        let template =
            medial::model::template::MedialTemplate::new(boundary, medial_index, medial_points);
        assert!(
            template.is_ok(),
            "{nb} boundary points: {:?}",
            template.err()
        );
    }
}
