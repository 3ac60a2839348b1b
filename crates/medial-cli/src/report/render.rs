//! A 3-D view of triangle meshes for the report: an orthographic camera, a z-buffer and flat
//! shading, drawn into an RGB image in plain Rust (no GPU, no system library) and written as
//! PNG ([`super::png`]).

use medial_core::mesh::PrincipalAxes;
use medial_core::{TriMesh, Vec3};

/// An orthographic camera: world points project to `(right · p, up · p)`, and `toward · p`
/// (towards the viewer) is the depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The screen's x direction.
    pub right: Vec3,
    /// The screen's y direction.
    pub up: Vec3,
    /// From the scene towards the viewer.
    pub toward: Vec3,
    /// The world point at the image's centre.
    pub centre: Vec3,
    /// World mm per pixel.
    pub scale: f64,
}

impl Camera {
    /// A camera that shows `points` whole in `width × height` pixels: it looks at a sheet-like
    /// shape mostly across it (along its thinnest principal axis, turned 50° towards the middle
    /// axis and 30° towards the long one), the long axis across the screen; `None` without
    /// points of extent.
    pub fn framing(points: &[Vec3], width: usize, height: usize) -> Option<Self> {
        let axes = PrincipalAxes::of(points).ok()?;
        let f = axes.frame.matrix();
        let (thin, middle, long) = (
            f.column(0).into_owned(),
            f.column(1).into_owned(),
            f.column(2).into_owned(),
        );
        let (a, b) = (50f64.to_radians(), 30f64.to_radians());
        let toward = (b.cos() * (a.cos() * thin + a.sin() * middle) + b.sin() * long).normalize();
        let right = (long - long.dot(&toward) * toward).normalize();
        let up = toward.cross(&right);
        let mut camera = Self {
            right,
            up,
            toward,
            centre: Vec3::zeros(),
            scale: 1.0,
        };
        let (lo, hi) = points.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                let s = [right.dot(p), up.dot(p)];
                (
                    [lo[0].min(s[0]), lo[1].min(s[1])],
                    [hi[0].max(s[0]), hi[1].max(s[1])],
                )
            },
        );
        let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
        let span = w.max(h);
        if span.is_nan() || span <= 0.0 {
            return None;
        }
        // 6 % free on each side.
        camera.scale = (w / width as f64).max(h / height as f64) * 1.12;
        camera.centre = right * (lo[0] + hi[0]) / 2.0 + up * (lo[1] + hi[1]) / 2.0;
        Some(camera)
    }

    /// The pixel coordinates (x right, y down, continuous) and depth of `p` in an image of
    /// `width × height`.
    fn project(&self, p: &Vec3, width: usize, height: usize) -> [f64; 3] {
        let d = p - self.centre;
        [
            width as f64 / 2.0 + self.right.dot(&d) / self.scale,
            height as f64 / 2.0 - self.up.dot(&d) / self.scale,
            self.toward.dot(p),
        ]
    }
}

/// Pixels from a triangle's edge drawn darker (at the canvas's size).
const EDGE: f64 = 2.0;

/// The brightness of a triangle near its edges, against its inside.
const EDGE_SHADE: f64 = 0.8;

/// An RGB image with a depth per pixel.
pub struct Canvas {
    /// Pixels across.
    pub width: usize,
    /// Pixels down.
    pub height: usize,
    /// The pixels, row by row, 3 bytes each.
    pub rgb: Vec<u8>,
    depth: Vec<f64>,
}

impl Canvas {
    /// A white canvas at infinite depth.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            rgb: vec![255; 3 * width * height],
            depth: vec![f64::NEG_INFINITY; width * height],
        }
    }

    /// Draws the triangles of `mesh` seen by `camera`, triangle `t` in `colour(t)` shaded by
    /// the angle of its normal with the light (above and left of the viewer, both sides lit),
    /// darker within [`EDGE`] pixels of its edges (the mesh's lines): only the nearest surface
    /// shows at each pixel.
    pub fn draw(&mut self, mesh: &TriMesh, camera: &Camera, colour: impl Fn(usize) -> [f64; 3]) {
        let light = (camera.toward + 0.6 * camera.up - 0.5 * camera.right).normalize();
        let points = mesh.points();
        for (t, corners) in mesh.triangles().iter().enumerate() {
            let [a, b, c] = corners.map(|i| points[i]);
            let normal = (b - a).cross(&(c - a));
            let norm = normal.norm();
            if norm.is_nan() || norm <= 0.0 {
                continue;
            }
            let shade = 0.2 + 0.8 * (normal.dot(&light) / norm).abs();
            let rgb = colour(t).map(|c| (255.0 * (c * shade).clamp(0.0, 1.0)).round() as u8);
            let q = corners.map(|i| camera.project(&points[i], self.width, self.height));
            self.fill(q, rgb);
        }
    }

    /// Fills the projected triangle `q` (pixel x, y and depth of each corner) where it is
    /// nearer than what is drawn, testing pixel centres; within [`EDGE`] pixels of an edge,
    /// [`EDGE_SHADE`] as bright.
    fn fill(&mut self, q: [[f64; 3]; 3], rgb: [u8; 3]) {
        let edge_rgb = rgb.map(|c| (f64::from(c) * EDGE_SHADE).round() as u8);
        let area =
            (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let lo = |k: usize| q.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
        let hi = |k: usize| q.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
        let clip = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
        let (x0, x1) = (
            clip(lo(0).floor(), self.width),
            clip(hi(0).ceil(), self.width),
        );
        let (y0, y1) = (
            clip(lo(1).floor(), self.height),
            clip(hi(1).ceil(), self.height),
        );
        let side = |i: usize, j: usize| (q[j][0] - q[i][0]).hypot(q[j][1] - q[i][1]);
        // The height of the triangle over the edge opposite each corner, pixels.
        let heights = [side(1, 2), side(2, 0), side(0, 1)].map(|s| area.abs() / s);
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let edge = |i: usize, j: usize| {
                    ((q[j][0] - q[i][0]) * (py - q[i][1]) - (q[j][1] - q[i][1]) * (px - q[i][0]))
                        / area
                };
                let w = [edge(1, 2), edge(2, 0), edge(0, 1)];
                if w.iter().any(|&w| w < 0.0) {
                    continue;
                }
                let depth = w[0] * q[0][2] + w[1] * q[1][2] + w[2] * q[2][2];
                let n = x + self.width * y;
                if depth > self.depth[n] {
                    self.depth[n] = depth;
                    let near = (0..3).any(|k| w[k] * heights[k] < EDGE);
                    let colour = if near { &edge_rgb } else { &rgb };
                    self.rgb[3 * n..3 * n + 3].copy_from_slice(colour);
                }
            }
        }
    }

    /// The image shrunk `factor` times by averaging blocks of `factor × factor` pixels (smooth
    /// edges from a canvas drawn larger).
    pub fn shrunk(&self, factor: usize) -> (usize, usize, Vec<u8>) {
        let (w, h) = (self.width / factor, self.height / factor);
        let mut rgb = Vec::with_capacity(3 * w * h);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let mut sum = 0usize;
                    for dy in 0..factor {
                        for dx in 0..factor {
                            let n = (x * factor + dx) + self.width * (y * factor + dy);
                            sum += usize::from(self.rgb[3 * n + c]);
                        }
                    }
                    rgb.push(((sum as f64) / (factor * factor) as f64).round() as u8);
                }
            }
        }
        (w, h, rgb)
    }
}

/// The viridis colormap at `s ∈ [0, 1]` (clamped; NaN as 0), sRGB in `[0, 1]`: dark purple to
/// yellow, interpolated between nine of its colours.
pub fn viridis(s: f64) -> [f64; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [0.267, 0.005, 0.329],
        [0.283, 0.141, 0.458],
        [0.254, 0.265, 0.530],
        [0.207, 0.372, 0.553],
        [0.164, 0.471, 0.558],
        [0.128, 0.567, 0.551],
        [0.135, 0.659, 0.518],
        [0.478, 0.821, 0.3182],
        [0.993, 0.906, 0.144],
    ];
    let s = if s.is_nan() { 0.0 } else { s.clamp(0.0, 1.0) } * 8.0;
    let k = (s.floor() as usize).min(7);
    let f = s - k as f64;
    std::array::from_fn(|c| STOPS[k][c] + f * (STOPS[k + 1][c] - STOPS[k][c]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two squares facing the viewer, the red one 1 mm nearer, overlapping in the middle.
    fn scene() -> (TriMesh, Camera) {
        let square = |x: f64, z: f64| {
            [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)].map(|(a, b)| Vec3::new(x + a, b, z))
        };
        let points: Vec<Vec3> = square(0.0, 0.0)
            .into_iter()
            .chain(square(1.0, 1.0))
            .collect();
        let triangles = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let camera = Camera {
            right: Vec3::x(),
            up: Vec3::y(),
            toward: Vec3::z(),
            centre: Vec3::new(1.5, 1.0, 0.0),
            scale: 0.1,
        };
        (TriMesh::new(points, triangles).unwrap(), camera)
    }

    #[test]
    fn the_nearer_surface_hides_the_farther() {
        let (mesh, camera) = scene();
        // 40 × 30 pixels of 0.1 mm: x from −0.5 to 3.5, y from −0.5 to 2.5.
        let mut canvas = Canvas::new(40, 30);
        canvas.draw(&mesh, &camera, |t| {
            if t < 2 {
                [0.0, 0.0, 1.0]
            } else {
                [1.0, 0.0, 0.0]
            }
        });
        let pixel = |x: f64, y: f64| {
            let (i, j) = ((x + 0.5) / 0.1, (2.5 - y) / 0.1);
            let n = 3 * (i as usize + 40 * j as usize);
            [canvas.rgb[n], canvas.rgb[n + 1], canvas.rgb[n + 2]]
        };
        let lit = (255.0 * (0.2 + 0.8 * (1.0 / (1.0f64 + 0.36 + 0.25).sqrt()))).round();
        assert_eq!(pixel(0.5, 1.0), [0, 0, lit as u8]); // the blue square alone
        assert_eq!(pixel(1.5, 1.0), [lit as u8, 0, 0]); // both: the red one in front
        assert_eq!(pixel(2.5, 1.0), [lit as u8, 0, 0]);
        assert_eq!(pixel(3.3, 1.0), [255, 255, 255]); // outside both
                                                      // Drawn in the other order, the same image.
        let (points, triangles) = mesh.clone().into_parts();
        let reversed: Vec<[usize; 3]> = triangles.into_iter().rev().collect();
        let mut again = Canvas::new(40, 30);
        again.draw(&TriMesh::new(points, reversed).unwrap(), &camera, |t| {
            if t >= 2 {
                [0.0, 0.0, 1.0]
            } else {
                [1.0, 0.0, 0.0]
            }
        });
        assert!(again.rgb == canvas.rgb);
        let (w, h, small) = canvas.shrunk(2);
        assert_eq!((w, h, small.len()), (20, 15, 900));
    }

    #[test]
    fn framing_shows_the_whole_shape() {
        let (mesh, _) = scene();
        let mut points = mesh.points().to_vec();
        points.push(Vec3::new(1.0, 1.0, 0.3));
        let camera = Camera::framing(&points, 200, 100).unwrap();
        for p in &points {
            let [x, y, _] = camera.project(p, 200, 100);
            assert!(
                (0.0..200.0).contains(&x) && (0.0..100.0).contains(&y),
                "{x} {y}"
            );
        }
        assert!(Camera::framing(&[Vec3::zeros()], 10, 10).is_none());
        assert_eq!(viridis(0.0), [0.267, 0.005, 0.329]);
        assert_eq!(viridis(2.0), [0.993, 0.906, 0.144]);
    }
}
