//! Planar slices of a volume: the values on a grid of pixels in a world plane (what a slice view
//! of a segmentation shows), and the plane of a mask's largest cross-section along a direction.

use super::Volume;
use crate::{Error, Result, Vec3};

/// A grid of `width × height` square pixels of side `pixel` (mm) in a world plane: pixel
/// `(i, j)` is centred at `origin + (i + ½) pixel · u + (j + ½) pixel · v`, `u` and `v` unit
/// and orthogonal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneGrid {
    /// The corner of the grid (the outer corner of pixel `(0, 0)`), world mm.
    pub origin: Vec3,
    /// The direction of increasing `i`.
    pub u: Vec3,
    /// The direction of increasing `j`.
    pub v: Vec3,
    /// The side of a pixel, mm.
    pub pixel: f64,
    /// Pixels along `u`.
    pub width: usize,
    /// Pixels along `v`.
    pub height: usize,
}

impl PlaneGrid {
    /// The centre of pixel `(i, j)`, world mm.
    pub fn centre(&self, i: usize, j: usize) -> Vec3 {
        self.origin + ((i as f64 + 0.5) * self.u + (j as f64 + 0.5) * self.v) * self.pixel
    }

    /// Refuses a grid that is empty, has a non-positive or non-finite pixel, or axes that are
    /// not unit and orthogonal (to 1e-9).
    fn check(&self) -> Result<()> {
        let unit = |a: &Vec3| (a.norm() - 1.0).abs() <= 1e-9;
        if self.width == 0 || self.height == 0 {
            return Err(Error::InvalidParameter(format!(
                "a slice of {}×{} pixels is empty",
                self.width, self.height
            )));
        }
        if !(self.pixel.is_finite() && self.pixel > 0.0) {
            return Err(Error::InvalidParameter(format!(
                "a slice's pixel must be a positive length, got {} mm",
                self.pixel
            )));
        }
        let sound = unit(&self.u)
            && unit(&self.v)
            && self.u.dot(&self.v).abs() <= 1e-9
            && self.origin.iter().all(|c| c.is_finite());
        if !sound {
            return Err(Error::InvalidParameter(
                "a slice's axes must be unit, orthogonal and finite".into(),
            ));
        }
        Ok(())
    }
}

/// The values of `volume` at the pixel centres of `grid`, `i` fastest (index `i + width · j`),
/// each the value of the nearest voxel ([`Volume::sample_nearest`], so a label map keeps its
/// labels), 0 outside the volume.
///
/// Errors: [`Error::InvalidParameter`] for a grid that is empty, of a non-positive pixel, or
/// with axes that are not unit and orthogonal.
///
/// ```
/// use medial_core::image::slice::{sample_plane, PlaneGrid};
/// use medial_core::image::Volume;
/// use medial_core::Vec3;
/// // A 2×1×1 volume of values 1, 2 with 1 mm voxels, sliced by z = 0 at 1 mm pixels.
/// let volume = Volume::new([2, 1, 1], vec![1.0, 2.0], nalgebra::Matrix4::identity()).unwrap();
/// let grid = PlaneGrid {
///     origin: Vec3::new(-0.5, -0.5, 0.0),
///     u: Vec3::x(),
///     v: Vec3::y(),
///     pixel: 1.0,
///     width: 3,
///     height: 1,
/// };
/// assert_eq!(sample_plane(&volume, &grid).unwrap(), [1.0, 2.0, 0.0]);
/// ```
pub fn sample_plane(volume: &Volume, grid: &PlaneGrid) -> Result<Vec<f64>> {
    grid.check()?;
    let mut values = Vec::with_capacity(grid.width * grid.height);
    for j in 0..grid.height {
        for i in 0..grid.width {
            values.push(volume.sample_nearest(&grid.centre(i, j)));
        }
    }
    Ok(values)
}

/// The offset `s` along the unit direction `normal` of the plane `normal · p = s` that cuts the
/// most of the mask `volume` (the voxels of a value other than 0): the voxel centres are
/// projected onto `normal` and counted in bins of width `bin` (mm); the centre of the fullest bin
/// (the first of equals). `None` for an empty mask.
///
/// Errors: [`Error::InvalidParameter`] for a `normal` that is not unit (to 1e-9) or a `bin` that
/// is not a positive length.
pub fn largest_section(volume: &Volume, normal: &Vec3, bin: f64) -> Result<Option<f64>> {
    if (normal.norm() - 1.0).abs() > 1e-9 {
        return Err(Error::InvalidParameter(format!(
            "a section's normal must be unit, got length {}",
            normal.norm()
        )));
    }
    if !(bin.is_finite() && bin > 0.0) {
        return Err(Error::InvalidParameter(format!(
            "a section's bin must be a positive length, got {bin} mm"
        )));
    }
    let [nx, ny, _] = volume.dims();
    let offsets: Vec<f64> = volume
        .data()
        .iter()
        .enumerate()
        .filter(|(_, &v)| v != 0.0)
        .map(|(n, _)| {
            let index = [n % nx, (n / nx) % ny, n / (nx * ny)];
            normal.dot(&volume.voxel_centre(index))
        })
        .collect();
    let Some(lo) = offsets.iter().copied().reduce(f64::min) else {
        return Ok(None);
    };
    let mut counts: Vec<usize> = Vec::new();
    for s in &offsets {
        let k = ((s - lo) / bin) as usize;
        if k >= counts.len() {
            counts.resize(k + 1, 0);
        }
        counts[k] += 1;
    }
    let best = (0..counts.len()).fold(0, |b, k| if counts[k] > counts[b] { k } else { b });
    Ok(Some(lo + (best as f64 + 0.5) * bin))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    /// A 10×10×10 volume of 1 mm voxels holding a cone along z: at slice k a square of side
    /// 1 + k voxels in x, 3 in y (so the largest z section is at k = 9, and the y sections alike).
    fn cone() -> Volume {
        let mut data = vec![0.0; 1000];
        for k in 0..10 {
            for j in 0..3 {
                for i in 0..=k {
                    data[i + 10 * (j + 10 * k)] = 1.0;
                }
            }
        }
        Volume::new(
            [10, 10, 10],
            data,
            Matrix4::new_translation(&Vec3::new(5.0, 0.0, -2.0)),
        )
        .unwrap()
    }

    #[test]
    fn the_largest_section_of_a_cone() {
        let z = largest_section(&cone(), &Vec3::z(), 1.0).unwrap().unwrap();
        // Voxel centres at z = −2 … 7; the fullest bin [6.5, 7.5) about the last slice.
        assert_eq!(z, 7.5);
        let bin = largest_section(&cone(), &-Vec3::z(), 1.0).unwrap().unwrap();
        assert_eq!(bin, -6.5);
        // y: three equal rows, the first wins; its bin [0, 1) centred at 0.5.
        assert_eq!(
            largest_section(&cone(), &Vec3::y(), 1.0).unwrap(),
            Some(0.5)
        );
        let empty = Volume::new([2, 2, 2], vec![0.0; 8], Matrix4::identity()).unwrap();
        assert_eq!(largest_section(&empty, &Vec3::x(), 1.0).unwrap(), None);
        assert!(largest_section(&cone(), &Vec3::new(0.0, 0.0, 2.0), 1.0).is_err());
        assert!(largest_section(&cone(), &Vec3::z(), 0.0).is_err());
    }

    #[test]
    fn a_slice_samples_the_nearest_voxels() {
        // z = 7 (slice k = 9) at 1 mm pixels from x = 4.5: the row of 10 + 1 outside.
        let grid = PlaneGrid {
            origin: Vec3::new(4.5, -0.5, 7.0),
            u: Vec3::x(),
            v: Vec3::y(),
            pixel: 1.0,
            width: 11,
            height: 4,
        };
        let values = sample_plane(&cone(), &grid).unwrap();
        let row = |j: usize| values[11 * j..11 * (j + 1)].to_vec();
        assert_eq!(
            row(0),
            [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0]
        );
        assert_eq!(row(3), [0.0; 11]);
        let bad = PlaneGrid {
            v: Vec3::x(),
            ..grid
        };
        assert!(sample_plane(&cone(), &bad).is_err());
        let empty = PlaneGrid { width: 0, ..grid };
        assert!(sample_plane(&cone(), &empty).is_err());
    }
}
