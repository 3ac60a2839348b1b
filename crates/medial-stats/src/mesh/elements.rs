//! A triangle mesh and the geometry of its elements.

use std::collections::{BTreeMap, HashMap};

use crate::{Result, StatsError};

/// A triangle mesh: points (mm) and triangles as point indices.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    points: Vec<[f64; 3]>,
    triangles: Vec<[usize; 3]>,
}

impl Mesh {
    /// A mesh; every index must name a point and every coordinate be finite.
    pub fn new(points: Vec<[f64; 3]>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        if let Some(k) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(StatsError::Mesh(format!("point {k} is not finite")));
        }
        if let Some(t) = triangles
            .iter()
            .position(|t| t.iter().any(|&i| i >= points.len()))
        {
            return Err(StatsError::Mesh(format!(
                "triangle {t} names a point beyond the {} points",
                points.len()
            )));
        }
        if triangles.is_empty() {
            return Err(StatsError::Mesh("has no triangles".into()));
        }
        Ok(Self { points, triangles })
    }

    /// An `n × n` grid of squares, each cut into two triangles along its diagonal, point
    /// `(i, j)` (`0 ≤ i, j ≤ n`) at `place(i, j)`: a test mesh of a sheet.
    ///
    /// ```
    /// use medial_stats::mesh::Mesh;
    /// let mesh = Mesh::grid(2, |i, j| [i as f64, j as f64, 0.0]).unwrap();
    /// assert_eq!((mesh.points().len(), mesh.triangles().len()), (9, 8));
    /// ```
    pub fn grid(n: usize, place: impl Fn(usize, usize) -> [f64; 3]) -> Result<Self> {
        let points = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| (i, j)))
            .map(|(i, j)| place(i, j))
            .collect();
        let id = |i: usize, j: usize| j * (n + 1) + i;
        let triangles = (0..n)
            .flat_map(|j| {
                (0..n).flat_map(move |i| {
                    [
                        [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                        [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                    ]
                })
            })
            .collect();
        Self::new(points, triangles)
    }

    /// The points.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// The triangles.
    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }

    /// For every point, the first point at its position: coincident points are one place of
    /// the sheet (a seam written twice).
    pub(crate) fn places(&self) -> Vec<usize> {
        let mut first_at: HashMap<[u64; 3], usize> = HashMap::new();
        self.points
            .iter()
            .enumerate()
            .map(|(i, x)| *first_at.entry(x.map(|c| (c + 0.0).to_bits())).or_insert(i))
            .collect()
    }
}

/// Which elements carry the data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Support {
    /// The mesh's points; a point's area is a third of the areas of its triangles.
    Points,
    /// The mesh's triangles.
    Cells,
}

/// The elements of a mesh: their areas, their neighbours, and the heat-diffusion operator on
/// them.
#[derive(Clone, Debug)]
pub struct Elements {
    areas: Vec<f64>,
    offsets: Vec<usize>,
    neighbours: Vec<usize>,
    /// The node of the diffusion operator of each element (coincident points share one).
    pub(crate) node: Vec<usize>,
    /// The mass (area) of each node.
    pub(crate) mass: Vec<f64>,
    /// The operator's edges (node, node, weight): u̇ₐ = Σ_b w (u_b − uₐ) / mₐ.
    pub(crate) couplings: Vec<(usize, usize, f64)>,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

impl Elements {
    /// The elements of `mesh` on `support`.
    ///
    /// ```
    /// use medial_stats::{Elements, Mesh, Support};
    ///
    /// // A unit square of two triangles.
    /// let mesh = Mesh::new(
    ///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ///     vec![[0, 1, 2], [0, 2, 3]],
    /// )?;
    /// let cells = Elements::new(&mesh, Support::Cells);
    /// assert_eq!(cells.areas(), [0.5, 0.5]);
    /// assert_eq!(cells.neighbours(0), [1]);
    /// let points = Elements::new(&mesh, Support::Points);
    /// assert_eq!(points.neighbours(0), [1, 2, 3]);
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn new(mesh: &Mesh, support: Support) -> Self {
        let p = &mesh.points;
        let place = mesh.places();
        let triangle_area: Vec<f64> = mesh
            .triangles
            .iter()
            .map(|&[a, b, c]| 0.5 * norm(cross(sub(p[b], p[a]), sub(p[c], p[a]))))
            .collect();
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let mut couplings: HashMap<(usize, usize), f64> = HashMap::new();
        let (areas, node, mass) = match support {
            Support::Points => {
                let mut areas = vec![0.0; p.len()];
                for (t, &[a, b, c]) in mesh.triangles.iter().enumerate() {
                    for (i, j, k) in [(a, b, c), (b, c, a), (c, a, b)] {
                        areas[i] += triangle_area[t] / 3.0;
                        pairs.push((i, j));
                        // Cotangent weight of edge (i, j): half the cotangent at k.
                        let (u, v) = (sub(p[i], p[k]), sub(p[j], p[k]));
                        let sine = norm(cross(u, v));
                        if sine > 0.0 && place[i] != place[j] {
                            *couplings.entry(ordered(place[i], place[j])).or_default() +=
                                0.5 * dot(u, v) / sine;
                        }
                    }
                }
                for (i, &q) in place.iter().enumerate() {
                    if q != i {
                        pairs.push((i, q));
                    }
                }
                let mut mass = vec![0.0; p.len()];
                for (i, &q) in place.iter().enumerate() {
                    mass[q] += areas[i];
                }
                (areas, place, mass)
            }
            Support::Cells => {
                let mut by_edge: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
                for (t, tri) in mesh.triangles.iter().enumerate() {
                    for (i, j) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
                        if place[i] != place[j] {
                            by_edge
                                .entry(ordered(place[i], place[j]))
                                .or_default()
                                .push(t);
                        }
                    }
                }
                let centroid = |t: usize| {
                    let [a, b, c] = mesh.triangles[t];
                    [0, 1, 2].map(|d| (p[a][d] + p[b][d] + p[c][d]) / 3.0)
                };
                for (&(i, j), cells) in &by_edge {
                    for (k, &s) in cells.iter().enumerate() {
                        for &t in &cells[k + 1..] {
                            if s == t {
                                continue;
                            }
                            pairs.push((s, t));
                            // Finite volumes: flux through the shared edge over the distance of
                            // the centroids.
                            let distance = norm(sub(centroid(s), centroid(t)));
                            if distance > 0.0 {
                                *couplings.entry(ordered(s, t)).or_default() +=
                                    norm(sub(p[i], p[j])) / distance;
                            }
                        }
                    }
                }
                let node = (0..mesh.triangles.len()).collect();
                (triangle_area.clone(), node, triangle_area)
            }
        };
        let count = areas.len();
        let mut lists: Vec<Vec<usize>> = vec![Vec::new(); count];
        for (a, b) in pairs {
            if a != b {
                lists[a].push(b);
                lists[b].push(a);
            }
        }
        let mut offsets = vec![0];
        let mut neighbours = Vec::new();
        for mut list in lists {
            list.sort_unstable();
            list.dedup();
            neighbours.extend(list);
            offsets.push(neighbours.len());
        }
        let mut couplings: Vec<(usize, usize, f64)> =
            couplings.into_iter().map(|((a, b), w)| (a, b, w)).collect();
        couplings.sort_by_key(|&(a, b, _)| (a, b));
        Self {
            areas,
            offsets,
            neighbours,
            node,
            mass,
            couplings,
        }
    }

    /// Elements.
    pub fn len(&self) -> usize {
        self.areas.len()
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.areas.is_empty()
    }

    /// The area of every element (mm²).
    pub fn areas(&self) -> &[f64] {
        &self.areas
    }

    /// The neighbours of element `e`, increasing.
    pub fn neighbours(&self, e: usize) -> &[usize] {
        &self.neighbours[self.offsets[e]..self.offsets[e + 1]]
    }
}

fn ordered(a: usize, b: usize) -> (usize, usize) {
    (a.min(b), a.max(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of a square whose diagonal is written twice (a seam).
    fn seamed_square() -> Mesh {
        Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [3, 4, 5]],
        )
        .unwrap()
    }

    #[test]
    fn seams_connect_points_and_cells() {
        let mesh = seamed_square();
        let cells = Elements::new(&mesh, Support::Cells);
        assert_eq!(cells.neighbours(0), [1]);
        let points = Elements::new(&mesh, Support::Points);
        assert_eq!(points.neighbours(3), [0, 4, 5]);
        assert_eq!(points.neighbours(0), [1, 2, 3]);
        let total: f64 = points.areas().iter().sum();
        assert!((total - 1.0).abs() < 1e-15);
        // The diffusion operator sees one node where the seam's points coincide.
        assert_eq!(points.node, [0, 1, 2, 0, 2, 5]);
        assert!((points.mass[0] - 1.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn bad_meshes_are_refused() {
        assert!(Mesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 3]]).is_err());
        assert!(Mesh::new(vec![[f64::NAN, 0.0, 0.0]; 3], vec![[0, 1, 2]]).is_err());
        assert!(Mesh::new(vec![[0.0; 3]; 3], vec![]).is_err());
    }
}
