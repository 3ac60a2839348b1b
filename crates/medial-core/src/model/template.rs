//! The medial template (docs/method.md §2.1–§2.2): a closed, outward-oriented boundary mesh whose every point `b`
//! is the end of a spoke of medial atom `M[b]`, and the medial points of the atoms.
//!
//! Landmarks `q` (`k = nb + nm` points): the `nb` boundary points first, then the `nm` medial
//! points; atom `m` is landmark `nb + m`. Atom `m` has spokes to `B[m] = (b_0 < b_1 < …)`:
//! 1 spoke on a free edge, 2 on a sheet interior, 3 on a seam.

use crate::mesh::topology::{check_closed_oriented_manifold, check_outward};
use crate::model::loop_tangent::LoopTangents;
use crate::{Error, Result, TriMesh, Vec3};
use std::collections::HashSet;

/// Most spokes an atom may have (a seam where three sheets meet).
pub const MAX_SPOKES: usize = 3;

/// A validated medial template: structure (boundary triangles, atoms, spokes, medial triangles,
/// Loop tangent operators) and landmark positions.
#[derive(Clone, Debug)]
pub struct MedialTemplate {
    /// Boundary points then medial points.
    landmarks: Vec<Vec3>,
    nb: usize,
    triangles: Vec<[usize; 3]>,
    medial_index: Vec<usize>,
    /// Spokes of atom `m`: `spoke_list[spoke_offsets[m]..spoke_offsets[m + 1]]`, ascending.
    spoke_offsets: Vec<usize>,
    spoke_list: Vec<usize>,
    medial_triangles: Vec<[usize; 3]>,
    tangents: LoopTangents,
}

impl MedialTemplate {
    /// Builds a template from its boundary mesh (closed, manifold, consistently and outwardly
    /// oriented), the atom `medial_index[b]` of every boundary point `b`, and the medial point
    /// `medial_points[m]` of every atom.
    ///
    /// Refused, with a message saying what and where: a boundary that is open, non-manifold,
    /// pinched, inconsistently oriented or inward oriented, or has a vertex of valence below 3
    /// (`Mesh`); a `medial_index` of
    /// the wrong length (`ShapeMismatch`); a medial index out of range, an atom with no spoke or
    /// more than [`MAX_SPOKES`] spokes (`InvalidTemplate`); a non-finite medial point
    /// (`NonFinite`).
    pub fn new(
        boundary: TriMesh,
        medial_index: Vec<usize>,
        medial_points: Vec<Vec3>,
    ) -> Result<Self> {
        let rings = check_closed_oriented_manifold(&boundary)?;
        check_outward(&boundary)?;
        let (mut landmarks, triangles) = boundary.into_parts();
        let nb = landmarks.len();
        if medial_index.len() != nb {
            return Err(Error::ShapeMismatch {
                what: "medial indices (one per boundary point)".into(),
                expected: nb,
                found: medial_index.len(),
            });
        }
        check_finite("medial point", &medial_points)?;
        let (spoke_offsets, spoke_list) = spokes_of_atoms(&medial_index, medial_points.len())?;
        let tangents = LoopTangents::new(&rings)?;
        let medial_triangles = medial_triangles(&triangles, &medial_index);
        landmarks.extend(medial_points);
        Ok(Self {
            landmarks,
            nb,
            triangles,
            medial_index,
            spoke_offsets,
            spoke_list,
            medial_triangles,
            tangents,
        })
    }

    /// Number of boundary points `nb`.
    pub fn boundary_count(&self) -> usize {
        self.nb
    }

    /// Number of medial atoms `nm`.
    pub fn medial_count(&self) -> usize {
        self.landmarks.len() - self.nb
    }

    /// Number of landmarks `k = nb + nm`.
    pub fn landmark_count(&self) -> usize {
        self.landmarks.len()
    }

    /// The landmarks `q⁰`: boundary points, then medial points.
    pub fn landmarks(&self) -> &[Vec3] {
        &self.landmarks
    }

    /// The boundary points (the first `nb` landmarks).
    pub fn boundary_points(&self) -> &[Vec3] {
        &self.landmarks[..self.nb]
    }

    /// The boundary as a triangle mesh (its boundary points and triangles).
    pub fn boundary_mesh(&self) -> crate::Result<crate::TriMesh> {
        crate::TriMesh::new(
            self.boundary_points().to_vec(),
            self.boundary_triangles().to_vec(),
        )
    }

    /// The medial points (the last `nm` landmarks).
    pub fn medial_points(&self) -> &[Vec3] {
        &self.landmarks[self.nb..]
    }

    /// The boundary triangles, counter-clockwise seen from outside.
    pub fn boundary_triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }

    /// `M[b]`: the atom of every boundary point.
    pub fn medial_index(&self) -> &[usize] {
        &self.medial_index
    }

    /// Landmark index of atom `m`: `nb + m`.
    pub fn atom_landmark(&self, atom: usize) -> usize {
        self.nb + atom
    }

    /// `B[m]`: the boundary points of atom `atom` (its spoke ends), ascending. Panics if
    /// `atom ≥ nm`.
    pub fn spokes(&self, atom: usize) -> &[usize] {
        &self.spoke_list[self.spoke_offsets[atom]..self.spoke_offsets[atom + 1]]
    }

    /// The medial triangles: the distinct triples of distinct atoms `{M[a], M[b], M[c]}` over
    /// boundary triangles `[a, b, c]`, in order of first appearance, each oriented as the
    /// boundary triangle it first came from (docs/method.md §2.1–§2.2).
    pub fn medial_triangles(&self) -> &[[usize; 3]] {
        &self.medial_triangles
    }

    /// The Loop tangent operators of the boundary mesh.
    pub fn tangents(&self) -> &LoopTangents {
        &self.tangents
    }

    /// The same template structure with new landmark positions `q` (`k` points, boundary then
    /// medial): a fitted or deformed model. The topology is not re-checked (it does not depend
    /// on positions), nor is the orientation (a fit may fold; the metrics report it).
    pub fn with_landmarks(&self, q: &[Vec3]) -> Result<Self> {
        if q.len() != self.landmarks.len() {
            return Err(Error::ShapeMismatch {
                what: "landmarks of the template (boundary then medial points)".into(),
                expected: self.landmarks.len(),
                found: q.len(),
            });
        }
        check_finite("landmark", q)?;
        Ok(Self {
            landmarks: q.to_vec(),
            ..self.clone()
        })
    }
}

/// Refuses the first non-finite point, naming it.
fn check_finite(what: &str, points: &[Vec3]) -> Result<()> {
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(i) => Err(Error::NonFinite(format!(
            "{what} {i} is {:?}",
            points[i].as_slice()
        ))),
        None => Ok(()),
    }
}

/// `B[m]` for every atom, as offsets and a list; checks every index is below `nm` and every atom
/// has 1 ..= [`MAX_SPOKES`] spokes.
fn spokes_of_atoms(medial_index: &[usize], nm: usize) -> Result<(Vec<usize>, Vec<usize>)> {
    let mut by_atom = vec![Vec::new(); nm];
    for (b, &m) in medial_index.iter().enumerate() {
        let Some(spokes) = by_atom.get_mut(m) else {
            return Err(Error::InvalidTemplate(format!(
                "boundary point {b} has medial index {m}, but there are only {nm} medial atoms \
                 (indices 0 to {})",
                nm.saturating_sub(1)
            )));
        };
        spokes.push(b);
    }
    let mut offsets = Vec::with_capacity(nm + 1);
    offsets.push(0);
    for (m, spokes) in by_atom.iter().enumerate() {
        if spokes.is_empty() {
            return Err(Error::InvalidTemplate(format!(
                "medial atom {m} has no spoke: no boundary point has medial index {m} (atoms \
                 must be numbered 0 to {} without gaps)",
                nm - 1
            )));
        }
        if spokes.len() > MAX_SPOKES {
            return Err(Error::InvalidTemplate(format!(
                "medial atom {m} has {} spokes (boundary points {spokes:?}); an atom has 1 \
                 (free edge), 2 (sheet) or 3 (seam)",
                spokes.len()
            )));
        }
        offsets.push(offsets[m] + spokes.len());
    }
    Ok((offsets, by_atom.concat()))
}

/// Distinct non-degenerate atom triples over the boundary triangles (see
/// [`MedialTemplate::medial_triangles`]).
fn medial_triangles(triangles: &[[usize; 3]], medial_index: &[usize]) -> Vec<[usize; 3]> {
    let mut seen = HashSet::new();
    triangles
        .iter()
        .map(|t| t.map(|b| medial_index[b]))
        .filter(|&[a, b, c]| a != b && b != c && a != c)
        .filter(|atoms| {
            let mut key = *atoms;
            key.sort_unstable();
            seen.insert(key)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::meshes::bipyramid;

    fn template_error(mesh: TriMesh, index: Vec<usize>, medial: Vec<Vec3>) -> String {
        MedialTemplate::new(mesh, index, medial)
            .expect_err("must be refused")
            .to_string()
    }

    #[test]
    fn bipyramid_structure() {
        let t = bipyramid(0.5);
        assert_eq!(
            (t.boundary_count(), t.medial_count(), t.landmark_count()),
            (8, 7, 15)
        );
        assert_eq!(t.spokes(0), &[0, 1]);
        assert_eq!(t.spokes(3), &[4]);
        assert_eq!(t.atom_landmark(3), 11);
        // Top triangle [0, 2, 3] → atoms [0, 1, 2]; its bottom twin gives the same set.
        assert_eq!(t.medial_triangles().len(), 6);
        assert_eq!(t.medial_triangles()[0], [0, 1, 2]);
        assert_eq!(t.medial_points()[0], Vec3::zeros());
        let moved: Vec<Vec3> = t.landmarks().iter().map(|p| p * 2.0).collect();
        let t2 = t.with_landmarks(&moved).expect("same size");
        assert_eq!(t2.landmarks()[9], moved[9]);
        assert!(t.with_landmarks(&moved[1..]).is_err());
    }

    #[test]
    fn inconsistent_indices_are_refused() {
        let t = bipyramid(0.5);
        let mesh = || {
            TriMesh::new(
                t.boundary_points().to_vec(),
                t.boundary_triangles().to_vec(),
            )
            .expect("valid")
        };
        let medial = t.medial_points().to_vec();
        let m = template_error(mesh(), vec![0, 0, 1, 2, 3, 4, 5, 9], medial.clone());
        assert!(
            m.contains("boundary point 7 has medial index 9") && m.contains("only 7"),
            "{m}"
        );
        let m = template_error(mesh(), vec![0, 0, 0, 0, 3, 4, 5, 6], medial.clone());
        assert!(m.contains("medial atom 0 has 4 spokes"), "{m}");
        let m = template_error(mesh(), vec![0, 0, 0, 2, 3, 4, 5, 6], medial.clone());
        assert!(m.contains("medial atom 1 has no spoke"), "{m}");
        let m = template_error(mesh(), vec![0; 7], medial.clone());
        assert!(m.contains("expected 8, found 7"), "{m}");
        let mut bad = medial;
        bad[2].y = f64::NAN;
        let m = template_error(mesh(), t.medial_index().to_vec(), bad);
        assert!(m.contains("medial point 2"), "{m}");
    }
}
