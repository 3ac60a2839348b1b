//! cmrep boundary medial templates ("bcm-rep" legacy VTK polydata, docs/method.md §2.3) ⇄
//! [`MedialTemplate`].
//!
//! The file holds the closed boundary triangle mesh and point arrays:
//!
//! * `MedialIndex` (integer, required): the medial atom `M[b]` of each boundary point;
//! * `MedialPoint` (3 components, optional): the medial point of the point's atom;
//! * `Radius` and `normals`/`Normals` (unit, outward): used when `MedialPoint` is absent, the
//!   medial point of atom `m` being `p_{b0} − Radius(b0)·normal(b0)` for its lowest-index
//!   boundary point `b0`;
//! * `Tangency` (integer, optional): the spoke count of the point's atom, checked if present.
//!
//! Array names are matched ignoring case; arrays may be `FIELD` data or attributes.

use std::path::Path;

use medial_core::mesh::Bounds;
use medial_core::model::metrics::SpokeMetrics;
use medial_core::model::template::MedialTemplate;
use medial_core::Vec3;

use crate::vtk::{
    read_polydata, write_polydata, ArrayKind, DataArray, PolyData, ValueType, WriteOptions,
};
use crate::{Error, Result};

/// Largest relative disagreement (to the bounding-box diagonal) tolerated between the
/// `MedialPoint` values of the spokes of one atom; files store `float` (7 digits).
const MEDIAL_POINT_TOLERANCE: f64 = 1e-5;

/// Largest tolerated `| |normal| − 1 |` of a normal used to place a medial point.
const UNIT_NORMAL_TOLERANCE: f64 = 1e-3;

/// Largest magnitude of a coordinate accepted, mm (a thousand kilometres): past it the volumes,
/// spoke lengths and kernel distances computed from the points lose their precision or
/// overflow, and the template's checks would report a wrong cause (an inward orientation).
const MAX_COORDINATE: f64 = 1e9;

/// Reads a cmrep template file (any legacy VTK polydata encoding and layout).
///
/// Errors: as [`read_polydata`] and [`template_from_polydata`].
pub fn read_template(path: &Path) -> Result<MedialTemplate> {
    template_from_polydata(&read_polydata(path)?, path)
}

/// Writes `template` as a cmrep template file (see [`template_to_polydata`]), atomically.
///
/// Errors: as [`write_polydata`].
pub fn write_template(path: &Path, template: &MedialTemplate, options: WriteOptions) -> Result<()> {
    write_polydata(path, &template_to_polydata(template), options)
}

/// The template held by cmrep polydata (`path` is only used in error messages).
///
/// Errors: as [`PolyData::to_trimesh`] for the boundary mesh (non-triangle cells, a mesh
/// [`TriMesh`](medial_core::TriMesh) refuses); [`Error::Format`] for a missing or malformed
/// array (naming it and listing the arrays the file has), for a file from which medial points
/// cannot be placed (neither `MedialPoint` nor `Radius` with normals), for inconsistent
/// `MedialPoint` values of one atom, a non-unit normal, a `Radius` that is not positive, a
/// coordinate beyond ±10⁹ mm, and for a `Tangency` that disagrees with the spoke counts (naming
/// the atom); [`Error::Model`] when the engine refuses the template (open or inward mesh, atom
/// with no or more than 3 spokes, …).
pub fn template_from_polydata(data: &PolyData, path: &Path) -> Result<MedialTemplate> {
    let mesh = data.to_trimesh(path)?;
    let arrays = Arrays { data, path };
    arrays.check_coordinates(&data.points, "boundary point")?;
    let medial_index = arrays.integers(arrays.required("MedialIndex", 1)?)?;
    arrays.check_radius()?;
    let medial_points = arrays.medial_points(&medial_index)?;
    arrays.check_coordinates(&medial_points, "the medial point of atom")?;
    let template = MedialTemplate::new(mesh, medial_index, medial_points)
        .map_err(|e| Error::model(path, e))?;
    arrays.check_tangency(&template)?;
    Ok(template)
}

/// The cmrep polydata of `template` at its landmarks: the boundary points and triangles, and
/// point arrays `MedialIndex` (int), `Radius` (spoke length), `Normals` (`NORMALS`, the unit
/// Loop normal `normalize(W¹q × W²q)`), `MedialPoint` (the point's atom, 3 components) and
/// `Tangency` (int, the atom's spoke count). Real values are stored as `double`, so that
/// reading the file back reproduces the landmarks exactly.
pub fn template_to_polydata(template: &MedialTemplate) -> PolyData {
    let q = template.landmarks();
    let nb = template.boundary_count();
    let atoms = template.medial_index();
    let medial = |b: usize| q[template.atom_landmark(atoms[b])];
    let metrics = SpokeMetrics::compute(template, q);
    let normals = template.tangents().normals(q);
    let mut data =
        PolyData::from_triangles(template.boundary_points(), template.boundary_triangles());
    let spoke_counts = atoms.iter().map(|&m| template.spokes(m).len() as f64);
    data.point_data = vec![
        array(
            "MedialIndex",
            1,
            atoms.iter().map(|&m| m as f64).collect(),
            ValueType::Int,
        ),
        array("Radius", 1, metrics.spoke_length, ValueType::Double),
        DataArray {
            kind: ArrayKind::Normals,
            ..array("Normals", 3, flat(&normals), ValueType::Double)
        },
        array(
            "MedialPoint",
            3,
            flat(&(0..nb).map(medial).collect::<Vec<_>>()),
            ValueType::Double,
        ),
        array("Tangency", 1, spoke_counts.collect(), ValueType::Int),
    ];
    data
}

/// A `FIELD` point array.
fn array(name: &str, components: usize, values: Vec<f64>, value_type: ValueType) -> DataArray {
    DataArray {
        name: name.into(),
        components,
        values,
        kind: ArrayKind::Field,
        value_type,
    }
}

/// `[x0, y0, z0, x1, …]`.
fn flat(points: &[Vec3]) -> Vec<f64> {
    points.iter().flat_map(|p| p.iter().copied()).collect()
}

/// Where the medial points of a file come from.
#[derive(Clone, Copy)]
enum MedialSource<'a> {
    /// The `MedialPoint` array.
    Points(&'a DataArray),
    /// `p_b − Radius(b)·normal(b)`.
    RadiusNormals {
        radius: &'a DataArray,
        normals: &'a DataArray,
    },
}

/// The point arrays of a file, with errors naming the file.
struct Arrays<'a> {
    data: &'a PolyData,
    path: &'a Path,
}

impl<'a> Arrays<'a> {
    fn error(&self, message: String) -> Error {
        Error::format(self.path, message)
    }

    /// "MedialIndex, Radius, normals", or "none".
    fn names(&self) -> String {
        let names: Vec<&str> = self
            .data
            .point_data
            .iter()
            .map(|a| a.name.as_str())
            .collect();
        if names.is_empty() {
            "none".into()
        } else {
            names.join(", ")
        }
    }

    /// The point array `name` (any case), checked to have `components` components, one tuple
    /// per point and finite values; `None` if absent.
    fn optional(&self, name: &str, components: usize) -> Result<Option<&'a DataArray>> {
        let Some(a) = self.data.point_array_ci(name) else {
            return Ok(None);
        };
        if a.components != components {
            return Err(self.error(format!(
                "point array '{}' has {} components, a cmrep template needs {components}",
                a.name, a.components
            )));
        }
        if a.values.len() != components * self.data.points.len() {
            return Err(self.error(format!(
                "point array '{}' has {} values for {} points × {components} components",
                a.name,
                a.values.len(),
                self.data.points.len()
            )));
        }
        if let Some(i) = a.values.iter().position(|v| !v.is_finite()) {
            return Err(self.error(format!(
                "point array '{}' has the non-finite value {} at point {}",
                a.name,
                a.values[i],
                i / components
            )));
        }
        Ok(Some(a))
    }

    /// Like [`Self::optional`], but a missing array is an error naming it and listing the
    /// arrays the file has.
    fn required(&self, name: &str, components: usize) -> Result<&'a DataArray> {
        self.optional(name, components)?.ok_or_else(|| {
            self.error(format!(
                "a cmrep template needs the point array '{name}' (the medial atom of each \
                 boundary point); the file's point arrays are: {}",
                self.names()
            ))
        })
    }

    /// The values of a 1-component array as non-negative integers.
    fn integers(&self, a: &DataArray) -> Result<Vec<usize>> {
        a.values
            .iter()
            .enumerate()
            .map(|(b, &v)| {
                if v >= 0.0 && v.fract() == 0.0 && v < 2f64.powi(53) {
                    Ok(v as usize)
                } else {
                    Err(self.error(format!(
                        "point array '{}' has value {v} at point {b}: a non-negative integer is \
                         required",
                        a.name
                    )))
                }
            })
            .collect()
    }

    /// The lowest-index boundary point `b0` of every atom `0 ..= max(MedialIndex)`; refuses
    /// an atom number that no point has.
    fn first_spokes(&self, medial_index: &[usize]) -> Result<Vec<usize>> {
        let Some((b_max, &m_max)) = medial_index.iter().enumerate().max_by_key(|(_, &m)| m) else {
            return Ok(Vec::new());
        };
        // n points number at most n atoms: when m_max ≥ n, an atom below n is missing, so the
        // table never needs more than n slots (a MedialIndex of 1e15 allocates nothing more).
        let mut first = vec![None; (m_max + 1).min(medial_index.len())];
        for (b, &m) in medial_index.iter().enumerate() {
            if let Some(slot) = first.get_mut(m) {
                slot.get_or_insert(b);
            }
        }
        first
            .iter()
            .enumerate()
            .map(|(m, b)| {
                b.ok_or_else(|| {
                    self.error(format!(
                        "point array 'MedialIndex' skips atom {m}: the atoms must be numbered \
                         from 0 to the largest index, {m_max} (at boundary point {b_max}), \
                         without gaps"
                    ))
                })
            })
            .collect()
    }

    /// The medial point of every atom, from `MedialPoint` if present, else from `Radius` and
    /// the normals, at the atom's lowest-index boundary point.
    fn medial_points(&self, medial_index: &[usize]) -> Result<Vec<Vec3>> {
        let first = self.first_spokes(medial_index)?;
        let source = match self.optional("MedialPoint", 3)? {
            Some(points) => {
                self.check_medial_point_agreement(points, medial_index, &first)?;
                MedialSource::Points(points)
            }
            None => self.radius_and_normals()?,
        };
        first
            .iter()
            .map(|&b| match source {
                MedialSource::Points(points) => Ok(tuple3(points, b)),
                MedialSource::RadiusNormals { radius, normals } => {
                    self.medial_point_from_radius(radius, normals, b)
                }
            })
            .collect()
    }

    /// `Radius` and `normals`/`Normals`, or an error saying the medial points cannot be placed.
    fn radius_and_normals(&self) -> Result<MedialSource<'a>> {
        match (self.optional("Radius", 1)?, self.optional("Normals", 3)?) {
            (Some(radius), Some(normals)) => Ok(MedialSource::RadiusNormals { radius, normals }),
            _ => Err(self.error(format!(
                "cannot place the medial points: a cmrep template needs either the point array \
                 'MedialPoint' (3 components) or both 'Radius' and 'normals'/'Normals'; the \
                 file's point arrays are: {}. Export the template with its medial points, or \
                 with radii and normals, or inflate it from its medial sheet",
                self.names()
            ))),
        }
    }

    /// `p_b − Radius(b)·normal(b)` (the radius checked by [`Self::check_radius`]), refusing a
    /// non-unit normal.
    fn medial_point_from_radius(
        &self,
        radius: &DataArray,
        normals: &DataArray,
        b: usize,
    ) -> Result<Vec3> {
        let r = radius.values[b];
        let n = tuple3(normals, b);
        if (n.norm() - 1.0).abs() > UNIT_NORMAL_TOLERANCE {
            return Err(self.error(format!(
                "point array '{}' at point {b} is ({}, {}, {}), of length {}: cmrep normals \
                 must be unit vectors",
                normals.name,
                n.x,
                n.y,
                n.z,
                n.norm()
            )));
        }
        Ok(self.data.points[b] - r * n)
    }

    /// `Radius`, when present (whether or not it places the medial points), must be positive:
    /// it is the spoke length.
    fn check_radius(&self) -> Result<()> {
        let Some(radius) = self.optional("Radius", 1)? else {
            return Ok(());
        };
        match radius.values.iter().position(|&r| r <= 0.0) {
            Some(b) => Err(self.error(format!(
                "point array '{}' has value {} at point {b}: a radius (the spoke length) must be \
                 positive",
                radius.name, radius.values[b]
            ))),
            None => Ok(()),
        }
    }

    /// Refuses a coordinate beyond ±[`MAX_COORDINATE`]; `what` and the index name the point.
    fn check_coordinates(&self, points: &[Vec3], what: &str) -> Result<()> {
        match points
            .iter()
            .enumerate()
            .find_map(|(i, p)| p.iter().find(|c| c.abs() > MAX_COORDINATE).map(|c| (i, *c)))
        {
            Some((i, c)) => Err(self.error(format!(
                "{what} {i} has the coordinate {c:e}, beyond ±{MAX_COORDINATE:e} (mm): volumes, \
                 spoke lengths and distances computed from it overflow or lose their precision"
            ))),
            None => Ok(()),
        }
    }

    /// All spokes of an atom must carry the same `MedialPoint` (within float precision).
    fn check_medial_point_agreement(
        &self,
        points: &DataArray,
        medial_index: &[usize],
        first: &[usize],
    ) -> Result<()> {
        let tolerance = MEDIAL_POINT_TOLERANCE
            * Bounds::of(&self.data.points)
                .map_or(0.0, |b| b.diagonal())
                .max(1.0);
        for (b, &m) in medial_index.iter().enumerate() {
            let b0 = first[m];
            let gap = (tuple3(points, b) - tuple3(points, b0)).norm();
            if gap > tolerance {
                return Err(self.error(format!(
                    "point array '{}' gives atom {m} two different medial points: at boundary \
                     points {b0} and {b} (distance {gap:.3e})",
                    points.name
                )));
            }
        }
        Ok(())
    }

    /// `Tangency`, if present, must equal the spoke count of every point's atom.
    fn check_tangency(&self, template: &MedialTemplate) -> Result<()> {
        let Some(tangency) = self.optional("Tangency", 1)? else {
            return Ok(());
        };
        for (b, (&m, &t)) in template
            .medial_index()
            .iter()
            .zip(&tangency.values)
            .enumerate()
        {
            let spokes = template.spokes(m);
            if t != spokes.len() as f64 {
                return Err(self.error(format!(
                    "point array '{}' says atom {m} has {t} spokes (at boundary point {b}), but \
                     MedialIndex gives it {} (boundary points {spokes:?})",
                    tangency.name,
                    spokes.len()
                )));
            }
        }
        Ok(())
    }
}

/// Tuple `i` of a 3-component array.
fn tuple3(a: &DataArray, i: usize) -> Vec3 {
    Vec3::new(a.values[3 * i], a.values[3 * i + 1], a.values[3 * i + 2])
}
