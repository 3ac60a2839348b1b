//! The paper's LV experiment on public data, the two steps `run.sh` needs besides the `medial`
//! commands:
//!
//! - `cargo run --release --example lv -- walls DATA OUT`: the ED and ES walls of the mean LV
//!   (`DATA/mean_shape.csv`: 3,364 points = ED-endo, ED-epi, ES-endo, ES-epi, 841 each;
//!   `DATA/surface_face.csv`: the 1-based triangles of one 841-point surface, open at the base)
//!   as closed outward meshes `OUT/ed_wall.vtk`, `OUT/es_wall.vtk`: the epicardium, the
//!   endocardium reversed (facing the cavity) and a rim of two triangles per base edge.
//! - `cargo run --release --example lv -- thickening ED_TEMPLATE.vtk ES_MEDIAL.vtk OUT.vtk`: the
//!   wall thickening per atom between the template itself (ED: its thickness, 2 × mean spoke,
//!   as the template file has it) and the medial sheet at the fit's last time point (ES, its
//!   `Thickness` point array, mm): writes `OUT.vtk` (the ES sheet with `ThicknessED`,
//!   `ThicknessES`, `ThickeningRatio` = ES/ED) and prints the mean, min and max ratio as JSON.
//!   Not the fit's first time point: the fit's initial alignment scales the template to the
//!   subject's size and its spokes to the subject's wall thickness before the flow starts, so
//!   the flow's own change is only part of the thickening.

use medial::io::cmrep::read_template;
use medial::io::vtk::{read_polydata, write_polydata, DataArray, PolyData, ValueType};
use medial::mesh::topology::signed_volume;
use medial::model::SpokeMetrics;
use medial::{TriMesh, Vec3};
use std::collections::HashMap;
use std::error::Error;
use std::path::Path;

/// Points of one surface.
const SURFACE_POINTS: usize = 841;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["walls", data, out] => walls(Path::new(data), Path::new(out)),
        ["thickening", ed, es, out] => thickening(Path::new(ed), Path::new(es), Path::new(out)),
        _ => Err("usage: lv walls DATA OUT | lv thickening ED_TEMPLATE.vtk ES.vtk OUT.vtk".into()),
    }
}

fn read_numbers(path: &Path) -> Result<Vec<f64>, Box<dyn Error>> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    text.split([',', '\n', '\r'])
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<f64>()
                .map_err(|e| format!("{}: '{s}': {e}", path.display()).into())
        })
        .collect()
}

/// Writes the ED and ES walls.
fn walls(data: &Path, out: &Path) -> Result<(), Box<dyn Error>> {
    let values = read_numbers(&data.join("mean_shape.csv"))?;
    if values.len() != 4 * 3 * SURFACE_POINTS {
        return Err(format!("mean_shape.csv: {} numbers, expected 10092", values.len()).into());
    }
    let points: Vec<Vec3> = values
        .chunks(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect();
    let faces = read_numbers(&data.join("surface_face.csv"))?;
    let triangles: Vec<[usize; 3]> = faces
        .chunks(3)
        .map(|c| [c[0] as usize - 1, c[1] as usize - 1, c[2] as usize - 1])
        .collect();
    std::fs::create_dir_all(out)?;
    for (name, first) in [("ed_wall.vtk", 0), ("es_wall.vtk", 2 * SURFACE_POINTS)] {
        let endo = &points[first..first + SURFACE_POINTS];
        let epi = &points[first + SURFACE_POINTS..first + 2 * SURFACE_POINTS];
        let wall = wall(endo, epi, &triangles)?;
        write_polydata(
            &out.join(name),
            &PolyData::from_trimesh(&wall),
            Default::default(),
        )?;
        eprintln!(
            "{name}: {} points, {} triangles, {:.0} mm³",
            wall.points().len(),
            wall.triangles().len(),
            signed_volume(wall.points(), wall.triangles())
        );
    }
    Ok(())
}

/// The closed wall between `endo` and `epi` (same triangles): epicardium (points `n..2n`),
/// endocardium reversed (points `0..n`), and the rim along the base (the edges in one triangle),
/// oriented outward.
fn wall(endo: &[Vec3], epi: &[Vec3], triangles: &[[usize; 3]]) -> Result<TriMesh, Box<dyn Error>> {
    let n = endo.len();
    let mut count: HashMap<(usize, usize), usize> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut all: Vec<[usize; 3]> = triangles.iter().map(|t| t.map(|v| v + n)).collect();
    all.extend(triangles.iter().map(|&[a, b, c]| [a, c, b]));
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if count[&(a.min(b), a.max(b))] == 1 {
                // The epicardium runs a → b along this base edge: the rim runs b → a on it.
                all.push([b + n, a + n, a]);
                all.push([b + n, a, b]);
            }
        }
    }
    let points: Vec<Vec3> = endo.iter().chain(epi).copied().collect();
    if signed_volume(&points, &all) < 0.0 {
        all.iter_mut().for_each(|t| t.swap(1, 2));
    }
    Ok(TriMesh::new(points, all)?)
}

/// Writes the thickening per atom and prints its mean, min and max.
fn thickening(ed: &Path, es: &Path, out: &Path) -> Result<(), Box<dyn Error>> {
    let thickness = |data: &PolyData, path: &Path| -> Result<Vec<f64>, Box<dyn Error>> {
        Ok(data
            .point_array("Thickness")
            .ok_or_else(|| format!("{}: no Thickness point array", path.display()))?
            .values
            .clone())
    };
    let template = read_template(ed)?;
    let before = SpokeMetrics::compute(&template, template.landmarks()).thickness;
    let mut es_data = read_polydata(es)?;
    let after = thickness(&es_data, es)?;
    if before.len() != after.len() {
        return Err("the two medial sheets have different atom counts".into());
    }
    let ratio: Vec<f64> = after.iter().zip(&before).map(|(a, b)| a / b).collect();
    let mean = ratio.iter().sum::<f64>() / ratio.len() as f64;
    let (lo, hi) = ratio.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
        (lo.min(r), hi.max(r))
    });
    let mean_of = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    es_data.point_data = vec![
        DataArray::scalars("ThicknessED", before.clone(), ValueType::Double),
        DataArray::scalars("ThicknessES", after.clone(), ValueType::Double),
        DataArray::scalars("ThickeningRatio", ratio, ValueType::Double),
    ];
    write_polydata(out, &es_data, Default::default())?;
    println!(
        "{{\"atoms\": {}, \"mean_thickness_ed_mm\": {:.3}, \"mean_thickness_es_mm\": {:.3}, \
         \"mean_ratio\": {mean:.4}, \"min_ratio\": {lo:.4}, \"max_ratio\": {hi:.4}}}",
        before.len(),
        mean_of(&before),
        mean_of(&after)
    );
    Ok(())
}
