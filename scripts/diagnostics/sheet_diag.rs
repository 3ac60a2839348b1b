//! Diagnostic (issue 30, docs/decisions/0401-heart-sheet-is-one-folded-sheet.md): the medial
//! sheet `medial template` builds for a segmentation, before inflation: written out (sheet.vtk,
//! sheet_sub.vtk, shape_mask.nii.gz), tested for its own self-intersections and folds, and
//! inflated at scaled radii; the steps of `branching` replicated with their counts (set
//! `BALLS=4:0.1,12:0.1` for a scan of ball radii in voxels : flatness, then it stops there).
//!
//! Not built by cargo here; to run it, copy it into `crates/medial-cli/examples/` and
//! `cargo run --release -p medial-cli --example sheet_diag -- SHAPE.nii.gz OUTDIR [VOXEL]`.

use medial_core::construction::from_shape::Shape;
use medial_core::construction::inflate::{inflate, self_intersections, MedialSheet};
use medial_core::construction::skeleton::{
    medial_points, sheet_of_mask, Sampling, MIN_FEATURE_ANGLE_DEG,
};
use medial_core::memory::MemoryLimit;
use medial_core::{TriMesh, Vec3};
use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let shape_path = PathBuf::from(&args[1]);
    let out = PathBuf::from(&args[2]);
    std::fs::create_dir_all(&out).unwrap();
    let image = medial_io::volume::read_volume(&shape_path).unwrap();
    let shape = Shape::of_segmentation(&image, None);
    let memory = MemoryLimit::none();
    let voxel = match args.get(3) {
        Some(v) => v.parse::<f64>().unwrap(),
        None => {
            let h0 = image.spacing().min() / 2.0;
            let coarse = shape.on_grid(h0, memory).unwrap();
            let points = medial_points(&coarse, MIN_FEATURE_ANGLE_DEG).unwrap();
            let mut radii: Vec<f64> = points.iter().map(|p| p.radius).collect();
            radii.sort_by(f64::total_cmp);
            let thin = radii[(0.1 * (radii.len() - 1) as f64) as usize];
            let wanted = (thin / 3.0).min(h0);
            let b = shape.bounds().unwrap();
            let mut h = wanted;
            loop {
                let dims = (b.extent() / h).map(|e| e.ceil() + 7.0);
                let v = dims.x * dims.y * dims.z;
                if v <= 32e6 {
                    break;
                }
                h *= 1.01 * (v / 32e6).cbrt();
            }
            println!("voxel wanted {wanted:.4}, chosen {h:.4}");
            h
        }
    };
    let t = std::time::Instant::now();
    let mask = shape.on_grid(voxel, memory).unwrap();
    let points = medial_points(&mask, MIN_FEATURE_ANGLE_DEG).unwrap();
    if let Ok(list) = std::env::var("BALLS") {
        for spec in list.split(',') {
            let (b, f) = spec.split_once(':').unwrap();
            println!("\n--- ball {b} voxels, flatness {f} ---");
            branching_diag(
                &points,
                mask.spacing().mean(),
                b.parse().unwrap(),
                f.parse().unwrap(),
            );
        }
        return;
    }
    branching_diag(&points, mask.spacing().mean(), 4.0, 0.1);
    let junction = branching_diag(&points, mask.spacing().mean(), 12.0, 0.1);
    let found = sheet_of_mask(&mask, Sampling::Atoms(300)).unwrap();
    println!("sheet built in {:.1} s", t.elapsed().as_secs_f64());
    println!("branching {:?}", found.branching);
    for (k, l) in found.lattices.iter().enumerate() {
        println!("lattice {k}: rings {} stretch {}", l.rings, l.stretch);
    }
    let mut seam_first = 0;
    for (s, seam) in found.seams.iter().enumerate() {
        println!(
            "seam {s}: vertices {}..{} length {:.1} mm, mean radius {:.2} (min {:.2} max {:.2})",
            seam_first,
            seam_first + seam.points.len(),
            seam.length(),
            seam.mean_radius(),
            seam.radius.iter().copied().fold(f64::INFINITY, f64::min),
            seam.radius.iter().copied().fold(0.0, f64::max)
        );
        seam_first += seam.points.len();
    }
    let opts = medial_io::vtk::WriteOptions::default();
    medial_io::sheet::write_sheet(&out.join("sheet.vtk"), &found.sheet, opts).unwrap();
    let sub = found.sheet.loop_subdivide().unwrap();
    medial_io::sheet::write_sheet(&out.join("sheet_sub.vtk"), &sub, opts).unwrap();
    medial_io::nifti_volume::write_nifti(
        &out.join("shape_mask.nii.gz"),
        &mask,
        medial_io::nifti_volume::NiftiType::U8,
    )
    .unwrap();
    println!("\n== coarse sheet ==");
    analyse(&found.sheet, &found.seams, &junction);
    println!("\n== subdivided sheet ==");
    analyse(&sub, &found.seams, &junction);
    println!("\n== inflation of the subdivided sheet at scaled radii ==");
    for scale in [1.0, 0.5, 0.25, 0.1, 0.05] {
        let scaled = MedialSheet::new(
            sub.points().to_vec(),
            sub.triangles().to_vec(),
            sub.radius().iter().map(|r| r * scale).collect(),
        )
        .unwrap();
        match inflate(&scaled) {
            Ok(inf) => println!(
                "scale {scale}: ok, lowered {} (max {:.0} %), shrink rounds {}",
                inf.limit.vertices.len(),
                inf.limit.max_pct(),
                inf.limit.shrink_rounds
            ),
            Err(e) => println!("scale {scale}: {e}"),
        }
    }
}

fn normal(p: &[Vec3], t: &[usize; 3]) -> Vec3 {
    (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]])).normalize()
}

/// The piece (sheet) of each triangle: triangles joined across edges in exactly two triangles.
fn pieces(tris: &[[usize; 3]]) -> (Vec<usize>, HashMap<(usize, usize), Vec<usize>>) {
    let mut by_edge: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            by_edge.entry((u.min(v), u.max(v))).or_default().push(i);
        }
    }
    let mut parent: Vec<usize> = (0..tris.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for ts in by_edge.values() {
        if let [a, b] = ts[..] {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            parent[ra] = rb;
        }
    }
    let roots: Vec<usize> = (0..tris.len()).map(|i| find(&mut parent, i)).collect();
    let mut ids: BTreeMap<usize, usize> = BTreeMap::new();
    let mut piece = vec![0; tris.len()];
    for (i, r) in roots.iter().enumerate() {
        let n = ids.len();
        piece[i] = *ids.entry(*r).or_insert(n);
    }
    (piece, by_edge)
}

fn analyse(
    sheet: &MedialSheet,
    seams: &[medial_core::construction::skeleton::seam::Seam],
    junction: &[Vec3],
) {
    let to_junction = |x: &Vec3| {
        junction
            .iter()
            .map(|j| (j - x).norm())
            .fold(f64::INFINITY, f64::min)
    };
    let mut all: Vec<f64> = sheet.points().iter().map(|x| to_junction(x)).collect();
    all.sort_by(f64::total_cmp);
    println!(
        "distance of the sheet's vertices to the nearest junction point (ball 12 voxels): median {:.1} mm, 25 % {:.1} mm",
        all[all.len() / 2],
        all[all.len() / 4]
    );
    let p = sheet.points();
    let tris = sheet.triangles();
    let (piece, by_edge) = pieces(tris);
    let npieces = piece.iter().max().map_or(0, |m| m + 1);
    let mut per = vec![0; npieces];
    piece.iter().for_each(|&k| per[k] += 1);
    println!(
        "points {}, triangles {}, pieces (sheets) {} with triangles {:?}",
        p.len(),
        tris.len(),
        npieces,
        per
    );
    let seam_dist = |x: &Vec3| {
        seams
            .iter()
            .enumerate()
            .map(|(s, seam)| (s, seam.distance(x), seam.radius_near(x)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((usize::MAX, f64::NAN, f64::NAN))
    };
    let centroid = |t: &[usize; 3]| (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0;
    // Own self-intersections of the sheet's triangles.
    let mesh = TriMesh::new(p.to_vec(), tris.to_vec()).unwrap();
    let pairs = self_intersections(&mesh);
    println!("sheet self-intersections: {} pairs", pairs.len());
    for &(f, g) in pairs.iter().take(30) {
        let (sf, df, rf) = seam_dist(&centroid(&tris[f]));
        let (_, dg, _) = seam_dist(&centroid(&tris[g]));
        println!(
            "  tri {f} {:?} (sheet {}) x tri {g} {:?} (sheet {}): seam {sf} at {df:.2} / {dg:.2} mm (seam radius {rf:.2}), angle between normals {:.0}°",
            tris[f],
            piece[f],
            tris[g],
            piece[g],
            normal(p, &tris[f]).dot(&normal(p, &tris[g])).clamp(-1.0, 1.0).acos().to_degrees()
        );
    }
    // Folds: interior edges whose two (consistently oriented) triangles' normals differ a lot.
    let mut folds = Vec::new();
    let mut seam_angles = Vec::new();
    for (&(u, v), ts) in &by_edge {
        match ts[..] {
            [a, b] => {
                let ang = normal(p, &tris[a])
                    .dot(&normal(p, &tris[b]))
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                // Consistent orientation: the edge runs opposite ways in the two.
                let runs = |t: &[usize; 3]| (0..3).any(|k| t[k] == u && t[(k + 1) % 3] == v);
                let consistent = runs(&tris[a]) != runs(&tris[b]);
                if ang > 60.0 || !consistent {
                    folds.push((ang, u, v, a, b, consistent));
                }
            }
            [a, b, c] => {
                // The angles between the three sheets about the seam edge: in the plane
                // perpendicular to the edge, the direction of each triangle's third vertex.
                let e = (p[v] - p[u]).normalize();
                let dir = |t: &[usize; 3]| {
                    let w = t.iter().copied().find(|&x| x != u && x != v).unwrap();
                    let d = p[w] - p[u];
                    (d - d.dot(&e) * e).normalize()
                };
                let ds = [dir(&tris[a]), dir(&tris[b]), dir(&tris[c])];
                let ang = |x: Vec3, y: Vec3| x.dot(&y).clamp(-1.0, 1.0).acos().to_degrees();
                let mut angs = [ang(ds[0], ds[1]), ang(ds[1], ds[2]), ang(ds[0], ds[2])];
                angs.sort_by(f64::total_cmp);
                seam_angles.push((angs[0], u, v, angs));
            }
            _ => {}
        }
    }
    folds.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!(
        "interior edges with normals > 60° apart or inconsistent orientation: {}",
        folds.len()
    );
    for (ang, u, v, a, b, consistent) in folds.iter().take(20) {
        let mid = (p[*u] + p[*v]) / 2.0;
        println!(
            "  edge {u}-{v} tris {a},{b}: {ang:.0}°{} at ({:.1}, {:.1}, {:.1}), {:.1} mm from a junction point",
            if *consistent { "" } else { " INCONSISTENT" },
            mid.x, mid.y, mid.z,
            to_junction(&mid)
        );
    }
    seam_angles.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "seam edges {}: smallest angle between two sheets at an edge:",
        seam_angles.len()
    );
    for (a, u, v, angs) in seam_angles.iter().take(12) {
        println!(
            "  edge {u}-{v}: {a:.0}° (all {:.0} {:.0} {:.0})",
            angs[0], angs[1], angs[2]
        );
    }
    if !seam_angles.is_empty() {
        let mut all: Vec<f64> = seam_angles.iter().map(|s| s.0).collect();
        all.sort_by(f64::total_cmp);
        println!(
            "  min angle quantiles: min {:.0} median {:.0} max {:.0}",
            all[0],
            all[all.len() / 2],
            all[all.len() - 1]
        );
    }
}

/// The steps of `branching` (skeleton/branching.rs), replicated with their intermediate counts.
fn branching_diag(
    points: &[medial_core::construction::skeleton::MedialPoint],
    voxel: f64,
    ball: f64,
    flatness: f64,
) -> Vec<Vec3> {
    let r = ball * voxel;
    let pos: Vec<Vec3> = points.iter().map(|p| p.position).collect();
    let n = pos.len();
    let grid = Cells::new(&pos, r);
    let on_seam: Vec<bool> = (0..n)
        .map(|i| {
            let near = grid.within(&pos, pos[i], r);
            near.len() >= 10 && !flat(&pos, &near, flatness)
        })
        .collect();
    let seam_idx: Vec<usize> = (0..n).filter(|&i| on_seam[i]).collect();
    let seam_pos: Vec<Vec3> = seam_idx.iter().map(|&i| pos[i]).collect();
    let seam_piece = cell_pieces(&seam_pos, r);
    let seam_grid = Cells::new(&seam_pos, 2.0 * r);
    let sheet_idx: Vec<usize> = (0..n)
        .filter(|&i| seam_grid.within(&seam_pos, pos[i], r).is_empty())
        .collect();
    let sheet_pos: Vec<Vec3> = sheet_idx.iter().map(|&i| pos[i]).collect();
    let sheet_piece = cell_pieces(&sheet_pos, 1.5 * voxel);
    let radii: Vec<f64> = points.iter().map(|p| p.radius).collect();
    println!(
        "medial points {n}, voxel {voxel:.4}, ball {r:.2} mm; seam points {}; sheet points (off seams by r) {}",
        seam_idx.len(),
        sheet_idx.len()
    );
    let mut rs = radii.clone();
    rs.sort_by(f64::total_cmp);
    println!(
        "radius quantiles 10/50/90 %: {:.2} {:.2} {:.2}",
        rs[n / 10],
        rs[n / 2],
        rs[9 * n / 10]
    );
    let summarize = |label: &str, piece: &[usize], members: &[Vec3]| {
        let mut size: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (k, &p) in piece.iter().enumerate() {
            size.entry(p).or_default().push(k);
        }
        let mut list: Vec<(usize, Vec<usize>)> = size.into_iter().collect();
        list.sort_by_key(|(_, v)| std::cmp::Reverse(v.len()));
        println!("{label}: {} pieces", list.len());
        for (p, ks) in list.iter().take(8) {
            let c = ks.iter().map(|&k| members[k]).sum::<Vec3>() / ks.len() as f64;
            let lo = ks
                .iter()
                .map(|&k| members[k])
                .fold(Vec3::repeat(f64::INFINITY), |a, b| a.inf(&b));
            let hi = ks
                .iter()
                .map(|&k| members[k])
                .fold(Vec3::repeat(f64::NEG_INFINITY), |a, b| a.sup(&b));
            println!(
                "  piece {p}: {} points, centre ({:.1}, {:.1}, {:.1}), box ({:.0}..{:.0}, {:.0}..{:.0}, {:.0}..{:.0})",
                ks.len(), c.x, c.y, c.z, lo.x, hi.x, lo.y, hi.y, lo.z, hi.z
            );
        }
        list
    };
    let seam_list = summarize("seam pieces", &seam_piece, &seam_pos);
    let sheet_list = summarize("sheet pieces", &sheet_piece, &sheet_pos);
    let least = 0.05 * n as f64;
    let kept: Vec<usize> = sheet_list
        .iter()
        .filter(|(_, v)| v.len() as f64 >= least)
        .map(|(p, _)| *p)
        .collect();
    println!("kept sheet pieces (>= {least:.0} points): {kept:?}");
    let mut reach: BTreeMap<usize, std::collections::BTreeSet<usize>> = BTreeMap::new();
    for (k, &p) in sheet_piece.iter().enumerate() {
        if !kept.contains(&p) {
            continue;
        }
        if let Some(&s) = seam_grid.within(&seam_pos, sheet_pos[k], 2.0 * r).first() {
            reach.entry(seam_piece[s]).or_default().insert(p);
        }
    }
    for (s, ps) in &reach {
        let size = seam_list
            .iter()
            .find(|(p, _)| p == s)
            .map_or(0, |(_, v)| v.len());
        println!("  seam piece {s} ({size} points) reached by kept sheet pieces {ps:?}");
    }
    let _ = seam_list;
    seam_pos
}

fn flat(pos: &[Vec3], near: &[usize], flatness: f64) -> bool {
    let n = near.len() as f64;
    let mean = near.iter().map(|&k| pos[k]).sum::<Vec3>() / n;
    let cov = near
        .iter()
        .map(|&k| {
            let d = pos[k] - mean;
            d * d.transpose()
        })
        .sum::<nalgebra::Matrix3<f64>>()
        / n;
    let e = cov.symmetric_eigenvalues();
    e.min() < flatness * e.sum()
}

fn cell_pieces(pos: &[Vec3], cell: f64) -> Vec<usize> {
    let key = |p: &Vec3| p.map(|c| (c / cell).floor() as i64);
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let cell_of: Vec<usize> = pos
        .iter()
        .map(|p| {
            let k = key(p);
            let next = cells.len();
            *cells.entry([k.x, k.y, k.z]).or_insert(next)
        })
        .collect();
    let mut parent: Vec<usize> = (0..cells.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for (k, &c) in &cells {
        for d in 0..27 {
            let o = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
            if let Some(&other) = cells.get(&[k[0] + o[0], k[1] + o[1], k[2] + o[2]]) {
                let (a, b) = (find(&mut parent, c), find(&mut parent, other));
                parent[a] = b;
            }
        }
    }
    cell_of.iter().map(|&c| find(&mut parent, c)).collect()
}

struct Cells {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl Cells {
    fn new(pos: &[Vec3], cell: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in pos.iter().enumerate() {
            cells.entry(Self::key(p, cell)).or_default().push(i);
        }
        Self { cell, cells }
    }
    fn key(p: &Vec3, cell: f64) -> [i64; 3] {
        [p.x, p.y, p.z].map(|c| (c / cell).floor() as i64)
    }
    fn within(&self, pos: &[Vec3], q: Vec3, radius: f64) -> Vec<usize> {
        let k = Self::key(&q, self.cell);
        let mut found: Vec<usize> = (0..27)
            .filter_map(|d| {
                let o = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
                self.cells.get(&[k[0] + o[0], k[1] + o[1], k[2] + o[2]])
            })
            .flatten()
            .copied()
            .filter(|&i| (pos[i] - q).norm() <= radius)
            .collect();
        found.sort_unstable();
        found
    }
}
