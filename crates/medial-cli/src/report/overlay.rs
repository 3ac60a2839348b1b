//! The model on the data: slices of the fit's target at three orthogonal planes with the model's
//! boundary and medial sheet cut by the same planes, at the start of the flow (t = 0, the
//! aligned template) and at its end (the fitted model), and a rendered 3-D view of the model.
//!
//! The target is the one of the fit's last stage that has one, as its `config.toml` names it:
//! an image (`image`, its foreground as the Dice stage takes it: `label` or `> 0`), else a
//! surface (`surface`), else points (`target`, drawn as their mesh's section where the file has
//! triangles). Each plane is normal to a world axis, where it cuts the most of the target (the
//! largest cross-section). A target that cannot be read leaves the slices without it, with a
//! note; the report never fails for it.

use super::figures::{self, Curves, PlanePanel};
use super::folder::{FitFolder, FlowKind};
use super::label::number;
use super::png;
use super::render::{viridis, Camera, Canvas};
use crate::error::CliError;
use maud::{html, Markup, PreEscaped};
use medial_core::image::slice::{largest_section, sample_plane, PlaneGrid};
use medial_core::image::Volume;
use medial_core::mesh::section::{length, section, Plane};
use medial_core::mesh::Bounds;
use medial_core::{TriMesh, Vec3};
use std::path::{Path, PathBuf};

/// Most pixels along a side of a slice of the image (coarser pixels than the voxels beyond).
const MAX_PIXELS: usize = 300;

/// Planes tried across a surface or point target for its largest section.
const CANDIDATES: usize = 48;

/// Side of one rendered view, pixels (drawn at [`SUPERSAMPLE`] times this and shrunk).
const VIEW: (usize, usize) = (300, 250);

/// Supersampling of the rendered views.
const SUPERSAMPLE: usize = 3;

/// The three planes: the axis they are normal to, their name, and their in-plane axes
/// (horizontal, vertical).
const PLANES: [(usize, &str, usize, usize); 3] = [
    (0, "sagittal", 1, 2),
    (1, "coronal", 0, 2),
    (2, "axial", 0, 1),
];

/// World axis names with the direction they point to (RAS).
const AXES: [&str; 3] = ["x (mm, → R)", "y (mm, → A)", "z (mm, → S)"];

/// What the fit was fitted to.
enum Target {
    /// The foreground of an image.
    Image(Box<Volume>),
    /// A triangle mesh (a surface, or points with triangles).
    Mesh(TriMesh),
    /// Points without triangles.
    Points(Vec<Vec3>),
}

impl Target {
    /// The bounding box of what is drawn of it.
    fn bounds(&self) -> Option<Bounds> {
        match self {
            Target::Image(mask) => mask.support_bounds(),
            Target::Mesh(mesh) => Bounds::of(mesh.points()),
            Target::Points(points) => Bounds::of(points),
        }
    }

    /// The offset along world axis `axis` of the plane of its largest cross-section.
    fn largest_section(&self, axis: usize) -> Option<f64> {
        let normal = Vec3::ith(axis, 1.0);
        match self {
            Target::Image(mask) => {
                let bin = mask.spacing().min();
                largest_section(mask, &normal, bin).ok().flatten()
            }
            Target::Mesh(mesh) => {
                let b = Bounds::of(mesh.points())?;
                let (lo, hi) = (b.min[axis], b.max[axis]);
                (1..CANDIDATES)
                    .map(|k| lo + (hi - lo) * k as f64 / CANDIDATES as f64)
                    .map(|s| {
                        let lines = section(mesh, &Plane::axis(axis, normal * s));
                        (s, length(&lines))
                    })
                    .fold(None, |best: Option<(f64, f64)>, c| match best {
                        Some(b) if b.1 >= c.1 => Some(b),
                        _ => Some(c),
                    })
                    .filter(|b| b.1 > 0.0)
                    .map(|b| b.0)
            }
            Target::Points(points) => {
                let b = Bounds::of(points)?;
                let bin = b.extent()[axis] / CANDIDATES as f64;
                if bin.is_nan() || bin <= 0.0 {
                    return Some(b.min[axis]);
                }
                let mut counts = vec![0usize; CANDIDATES + 1];
                for p in points {
                    counts[((p[axis] - b.min[axis]) / bin) as usize] += 1;
                }
                let best =
                    (0..counts.len()).fold(0, |m, k| if counts[k] > counts[m] { k } else { m });
                Some(b.min[axis] + (best as f64 + 0.5) * bin)
            }
        }
    }
}

/// The target of the fit in `folder` and the file it came from: `Ok(None)` for a fit without
/// one (a transform alone), `Err(note)` where it cannot be read.
fn target(folder: &FitFolder) -> Result<Option<(Target, PathBuf)>, String> {
    let Some(config) = &folder.config else {
        return Err("the folder has no config.toml naming the fit's target".into());
    };
    let config: toml::Value =
        toml::from_str(config).map_err(|e| format!("config.toml cannot be read: {e}"))?;
    let stages = config
        .get("stage")
        .and_then(toml::Value::as_array)
        .cloned()
        .unwrap_or_default();
    let path_of = |key: &str| -> Option<(PathBuf, &toml::Value)> {
        stages.iter().rev().find_map(|s| {
            let p = Path::new(s.get(key)?.as_str()?);
            Some((folder.dir.join(p), s))
        })
    };
    let read =
        |p: &Path, e: medial_io::Error| format!("the target {} cannot be read: {e}", p.display());
    if let Some((path, stage)) = path_of("image") {
        let volume = medial_io::volume::read_volume(&path).map_err(|e| read(&path, e))?;
        let label = stage
            .get("label")
            .and_then(|l| l.as_float().or_else(|| l.as_integer().map(|i| i as f64)));
        return Ok(Some((
            Target::Image(Box::new(volume.foreground(label))),
            path,
        )));
    }
    if let Some((path, _)) = path_of("surface") {
        let mesh = medial_io::mesh::read_mesh(&path).map_err(|e| read(&path, e))?;
        return Ok(Some((Target::Mesh(mesh), path)));
    }
    if let Some((path, _)) = path_of("target") {
        let vtk = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("vtk"));
        let target = if vtk {
            let data = medial_io::vtk::read_polydata(&path).map_err(|e| read(&path, e))?;
            match data.to_trimesh(&path) {
                Ok(mesh) if !mesh.triangles().is_empty() => Target::Mesh(mesh),
                _ => Target::Points(data.points),
            }
        } else {
            match medial_io::mesh::read_mesh(&path) {
                Ok(mesh) if !mesh.triangles().is_empty() => Target::Mesh(mesh),
                _ => {
                    Target::Points(medial_io::mesh::read_points(&path).map_err(|e| read(&path, e))?)
                }
            }
        };
        return Ok(Some((target, path)));
    }
    Ok(None)
}

/// The model at one time point: its boundary and medial sheet, with a thickness per triangle.
struct Model {
    /// `t`.
    time: f64,
    /// The boundary.
    boundary: TriMesh,
    /// `2 × Radius` of each boundary triangle (the mean of its corners'), if the file has it.
    boundary_thickness: Option<Vec<f64>>,
    /// The medial sheet, if its file is there.
    medial: Option<TriMesh>,
    /// `Thickness` of each medial triangle, if the file has it.
    medial_thickness: Option<Vec<f64>>,
}

/// The mean over each triangle of `values` at its corners.
fn per_triangle(mesh: &TriMesh, values: &[f64]) -> Option<Vec<f64>> {
    (values.len() == mesh.points().len()).then(|| {
        mesh.triangles()
            .iter()
            .map(|t| t.iter().map(|&i| values[i]).sum::<f64>() / 3.0)
            .collect()
    })
}

/// The model at the first (`last = false`) or last time point of the folder's flow; `None`
/// without its boundary file.
fn model(folder: &FitFolder, last: bool) -> Result<Option<Model>, CliError> {
    let pick = |kind| {
        let files = folder.files(kind);
        if last {
            files.last()
        } else {
            files.first()
        }
    };
    let Some(file) = pick(FlowKind::Boundary) else {
        return Ok(None);
    };
    let path = folder.dir.join("flow").join(&file.name);
    let data = folder.read_flow(file)?;
    let boundary = data.to_trimesh(&path)?;
    let boundary_thickness = data.point_array("Radius").and_then(|a| {
        let doubled: Vec<f64> = a.values.iter().map(|r| 2.0 * r).collect();
        per_triangle(&boundary, &doubled)
    });
    let (mut medial, mut medial_thickness) = (None, None);
    if let Some(m) = pick(FlowKind::Medial).filter(|m| m.index == file.index) {
        let path = folder.dir.join("flow").join(&m.name);
        let data = folder.read_flow(m)?;
        let mesh = data.to_trimesh(&path)?;
        medial_thickness = data
            .point_array("Thickness")
            .and_then(|a| per_triangle(&mesh, &a.values));
        medial = Some(mesh);
    }
    Ok(Some(Model {
        time: file.time,
        boundary,
        boundary_thickness,
        medial,
        medial_thickness,
    }))
}

/// The union of boxes.
fn union(boxes: impl Iterator<Item = Bounds>) -> Option<Bounds> {
    boxes.reduce(|a, b| Bounds {
        min: a.min.inf(&b.min),
        max: a.max.sup(&b.max),
    })
}

/// The section of `mesh` by `plane`, as polylines in the plane's coordinates `(u, v)`.
fn cut(mesh: &TriMesh, plane: &Plane, u: usize, v: usize) -> Vec<Vec<(f64, f64)>> {
    section(mesh, plane)
        .into_iter()
        .map(|line| line.iter().map(|p| (p[u], p[v])).collect())
        .collect()
}

/// The foreground of `values` on `grid` as rectangles `[u0, v0, u1, v1]` in plane coordinates
/// (runs along each row, a run repeated in the next rows merged into one rectangle).
fn mask_rectangles(values: &[f64], grid: &PlaneGrid, lo: (f64, f64)) -> Vec<[f64; 4]> {
    let (w, px) = (grid.width, grid.pixel);
    let mut done: Vec<[f64; 4]> = Vec::new();
    // Open rectangles: (first column, end column, index in `done`).
    let mut open: Vec<(usize, usize, usize)> = Vec::new();
    for (j, row) in values.chunks(w).enumerate() {
        let mut runs = Vec::new();
        let mut i = 0;
        while i < w {
            if row[i] != 0.0 {
                let start = i;
                while i < w && row[i] != 0.0 {
                    i += 1;
                }
                runs.push((start, i));
            } else {
                i += 1;
            }
        }
        let mut next = Vec::with_capacity(runs.len());
        for (a, b) in runs {
            let v1 = lo.1 + (j + 1) as f64 * px;
            match open.iter().find(|o| o.0 == a && o.1 == b) {
                Some(&(_, _, k)) => {
                    done[k][3] = v1;
                    next.push((a, b, k));
                }
                None => {
                    done.push([
                        lo.0 + a as f64 * px,
                        lo.1 + j as f64 * px,
                        lo.0 + b as f64 * px,
                        v1,
                    ]);
                    next.push((a, b, done.len() - 1));
                }
            }
        }
        open = next;
    }
    done
}

/// The section "The model on the data" of the report of `folder`.
///
/// Errors: [`CliError::File`] when a file under `flow/` cannot be read; [`CliError::Figure`]
/// when a figure cannot be drawn. A target that cannot be read is a note in the section.
pub fn section_markup(folder: &FitFolder) -> Result<Markup, CliError> {
    let (Some(start), Some(fitted)) = (model(folder, false)?, model(folder, true)?) else {
        return Ok(html! {});
    };
    let (target, note) = match target(folder) {
        Ok(Some((target, path))) => (Some(target), Some(format!("target: {}", path.display()))),
        Ok(None) => (
            None,
            Some(
                "the fit has no target image, surface or points to draw (a transform alone)"
                    .to_owned(),
            ),
        ),
        Err(note) => (None, Some(format!("{note}; the model is drawn alone"))),
    };
    let slices = slices(target.as_ref(), &start, &fitted)?;
    let view = views(&start, &fitted)?;
    let swatch = |colour: &str| {
        html! { span style={"display:inline-block;width:18px;height:3px;vertical-align:middle;background:" (colour)} {} }
    };
    Ok(html! {
        h2 { "The model on the data" }
        p.note {
            "Three planes normal to the world axes, each where it cuts the most of the target, \
             at the start of the flow (t = 0, the aligned template) and at its end (the fitted \
             model): "
            @match target {
                Some(Target::Image(_)) => { "the image's foreground (grey), " }
                Some(Target::Mesh(_)) => { "the target surface's section (" (swatch("#000")) " black), " }
                Some(Target::Points(_)) => { "the target points within 1 % of the view's width of the plane (black dots), " }
                None => {}
            }
            "the model's boundary (" (swatch("#d62728")) " red) and medial sheet (" (swatch("#1f77b4")) " blue) cut by the plane."
        }
        @if let Some(note) = &note { p.note { (note) } }
        @if let Some(svg) = &slices { (PreEscaped(svg)) }
        @if let Some(svg) = &view {
            p.note {
                "The model seen from the same place at the start and at the end of the flow, \
                 flat-shaded, coloured by the local thickness (twice the spoke length) on one \
                 scale for the three views."
            }
            (PreEscaped(svg))
        }
    })
}

/// The slice panels: three planes, at the start and at the end; `None` without anything to
/// draw.
fn slices(
    target: Option<&Target>,
    start: &Model,
    fitted: &Model,
) -> Result<Option<String>, CliError> {
    let models = [start, fitted];
    let Some(bounds) = union(
        target.and_then(Target::bounds).into_iter().chain(
            models
                .iter()
                .filter_map(|m| Bounds::of(m.boundary.points())),
        ),
    ) else {
        return Ok(None);
    };
    let centre = bounds.centre();
    let mut panels = Vec::new();
    for (model, when) in [(start, "start"), (fitted, "fitted")] {
        for (axis, name, u, v) in PLANES {
            let offset = target
                .and_then(|t| t.largest_section(axis))
                .unwrap_or(centre[axis]);
            let plane = Plane::axis(axis, Vec3::ith(axis, offset));
            let pad = 0.05 * bounds.extent()[u].max(bounds.extent()[v]).max(1.0);
            let lo = (bounds.min[u] - pad, bounds.min[v] - pad);
            let hi = (bounds.max[u] + pad, bounds.max[v] + pad);
            let mut curves = Curves::default();
            match target {
                Some(Target::Image(mask)) => {
                    let side = (hi.0 - lo.0).max(hi.1 - lo.1);
                    let pixel = mask.spacing().min().max(side / MAX_PIXELS as f64);
                    let grid = PlaneGrid {
                        origin: Vec3::ith(u, lo.0) + Vec3::ith(v, lo.1) + Vec3::ith(axis, offset),
                        u: Vec3::ith(u, 1.0),
                        v: Vec3::ith(v, 1.0),
                        pixel,
                        width: ((hi.0 - lo.0) / pixel).ceil() as usize,
                        height: ((hi.1 - lo.1) / pixel).ceil() as usize,
                    };
                    if let Ok(values) = sample_plane(mask, &grid) {
                        curves.mask = mask_rectangles(&values, &grid, lo);
                    }
                }
                Some(Target::Mesh(mesh)) => curves.target = cut(mesh, &plane, u, v),
                Some(Target::Points(points)) => {
                    let slab = (hi.0 - lo.0).max(hi.1 - lo.1) / 100.0;
                    curves.points = points
                        .iter()
                        .filter(|p| (p[axis] - offset).abs() <= slab)
                        .map(|p| (p[u], p[v]))
                        .collect();
                }
                None => {}
            }
            curves.boundary = cut(&model.boundary, &plane, u, v);
            if let Some(medial) = &model.medial {
                curves.medial = cut(medial, &plane, u, v);
            }
            panels.push(PlanePanel {
                title: format!(
                    "{name}, {} = {} mm · {when} (t = {})",
                    ["x", "y", "z"][axis],
                    number(offset),
                    number(model.time)
                ),
                u_label: AXES[u].into(),
                v_label: AXES[v].into(),
                u_range: lo.0..hi.0,
                v_range: lo.1..hi.1,
                curves,
            });
        }
    }
    figures::planes("the model on the data", &panels, 3).map(Some)
}

/// The rendered views: the boundary at the start, the fitted boundary and the fitted medial
/// sheet, coloured by thickness on one scale, in one SVG with their captions and the colour
/// scale; `None` where the model cannot be framed.
fn views(start: &Model, fitted: &Model) -> Result<Option<String>, CliError> {
    let (w, h) = (VIEW.0 * SUPERSAMPLE, VIEW.1 * SUPERSAMPLE);
    let framed: Vec<Vec3> = [start, fitted]
        .iter()
        .flat_map(|m| m.boundary.points().iter().copied())
        .collect();
    let Some(camera) = Camera::framing(&framed, w, h) else {
        return Ok(None);
    };
    let mut shown: Vec<(String, &TriMesh, Option<&Vec<f64>>)> = vec![
        (
            format!("boundary at the start (t = {})", number(start.time)),
            &start.boundary,
            start.boundary_thickness.as_ref(),
        ),
        (
            format!("fitted boundary (t = {})", number(fitted.time)),
            &fitted.boundary,
            fitted.boundary_thickness.as_ref(),
        ),
    ];
    if let Some(medial) = &fitted.medial {
        shown.push((
            format!("fitted medial sheet (t = {})", number(fitted.time)),
            medial,
            fitted.medial_thickness.as_ref(),
        ));
    }
    let (lo, hi) = shown
        .iter()
        .filter_map(|s| s.2)
        .flatten()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let coloured = lo.is_finite() && hi > lo;
    let (vw, vh) = VIEW;
    let mut strip = vec![255u8; 3 * vw * shown.len() * vh];
    for (k, (_, mesh, thickness)) in shown.iter().enumerate() {
        let mut canvas = Canvas::new(w, h);
        canvas.draw(mesh, &camera, |t| match thickness {
            Some(values) if coloured => viridis((values[t] - lo) / (hi - lo)),
            _ => [0.55, 0.65, 0.8],
        });
        let (_, _, small) = canvas.shrunk(SUPERSAMPLE);
        for y in 0..vh {
            let row = &small[3 * vw * y..3 * vw * (y + 1)];
            let at = 3 * (y * vw * shown.len() + k * vw);
            strip[at..at + 3 * vw].copy_from_slice(row);
        }
    }
    let image = png::encode(vw * shown.len(), vh, &strip);
    let captions: Vec<String> = shown.into_iter().map(|s| s.0).collect();
    let scale = coloured.then_some((lo, hi));
    Ok(Some(figures::image_strip(&image, vw, vh, &captions, scale)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_runs_merge_into_rectangles() {
        let grid = PlaneGrid {
            origin: Vec3::zeros(),
            u: Vec3::x(),
            v: Vec3::y(),
            pixel: 0.5,
            width: 4,
            height: 3,
        };
        #[rustfmt::skip]
        let values = [
            1.0, 1.0, 0.0, 1.0,
            1.0, 1.0, 0.0, 0.0,
            0.0, 1.0, 1.0, 0.0,
        ];
        let rects = mask_rectangles(&values, &grid, (10.0, 20.0));
        assert_eq!(
            rects,
            [
                [10.0, 20.0, 11.0, 21.0],
                [11.5, 20.0, 12.0, 20.5],
                [10.5, 21.0, 11.5, 21.5],
            ]
        );
    }
}
