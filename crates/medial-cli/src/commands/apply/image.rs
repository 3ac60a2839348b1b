//! Images carried by a fitted map: pulled back through the opposite map on an output grid, and
//! the displacement field of that pull-back as a warp.
//!
//! The pull-back runs slab by slab of the output grid: the flow's displacement on a control
//! grid interpolated to the voxels ([`GridMap`], within a tolerance of the exact map), or with
//! `exact` every voxel mapped by the whole flow; the alignment `A` is applied to every voxel
//! exactly. Only the control grid, one slab, the output values (and the warp, when asked for)
//! are held.

use super::fitted::FittedMap;
use crate::error::CliError;
use medial_core::flow::ambient::grid::{GridMap, GridOptions, Lattice};
use medial_core::image::Volume;
use medial_core::memory::Estimate;
use medial_core::Vec3;
use serde::Serialize;

/// How the values of an image are sampled at the pulled-back points.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Nearest for integer images (label maps), linear for real ones.
    Auto,
    /// The nearest voxel: labels stay labels.
    Nearest,
    /// Trilinear.
    Linear,
}

/// Slices per slab, at least (rounded up to whole control cells).
const SLAB: usize = 16;

/// How the pull-back was computed.
#[derive(Serialize, Clone, Debug)]
pub struct ControlGrid {
    /// Voxels between control nodes.
    pub stride: usize,
    /// Control nodes mapped by the flow.
    pub nodes: usize,
    /// Fraction of the control cells whose voxels were mapped one by one.
    pub mapped_fraction: f64,
    /// The tolerance, in voxels (of the largest spacing) and mm.
    pub tolerance_voxels: f64,
    pub tolerance_mm: f64,
    /// The kernel tolerance of the truncated maps.
    pub kernel_epsilon: f64,
    /// The largest estimated interpolation error of an interpolated cell, mm.
    pub interpolation_estimate_mm: f64,
}

/// What a pull-back leaves: the displacement of each voxel (kept only when asked for) and the
/// statistics of their lengths.
pub struct Pulled {
    /// The resampled values, `x` fastest, when an image was sampled.
    pub values: Option<Vec<f64>>,
    /// `d(y) = source − y` of every voxel, when asked for.
    pub displacements: Option<Vec<Vec3>>,
    /// Voxels.
    pub voxels: usize,
    /// Mean and largest `|d(y)|`, mm.
    pub mean_mm: f64,
    pub max_mm: f64,
    /// The control grid, unless `exact`.
    pub grid: Option<ControlGrid>,
}

/// The pull-back on `grid` of carrying by `map` (by its inverse with `inverse`): each voxel
/// centre `y` goes to its source, `F⁻¹(y)` (`F(y)` with `inverse`), where `sample` (if any) is
/// read; `keep` keeps the displacements. `tolerance_voxels` bounds the distance to the exact
/// map's source (in voxels of the grid's largest spacing), unless `exact`.
pub fn pull_back(
    grid: &Volume,
    map: &FittedMap,
    inverse: bool,
    exact: bool,
    tolerance_voxels: f64,
    sample: Option<&(dyn Fn(&Vec3) -> f64 + Sync)>,
    keep: bool,
) -> Result<Pulled, CliError> {
    let [nx, ny, nz] = grid.dims();
    crate::memory::check(&Estimate::pull_back(nx * ny * nz), || {
        format!("a pull-back on {nx}×{ny}×{nz} voxels")
    })?;
    let lattice = Lattice {
        dims: grid.dims(),
        voxel_to_world: *grid.voxel_to_world(),
    };
    // Carrying forward samples at A⁻¹(φ⁻¹(y)); carrying back at φ(A y), the flow then on the
    // lattice moved by A.
    let flow_lattice = match (inverse, map.alignment()) {
        (true, Some(a)) => Lattice {
            dims: lattice.dims,
            voxel_to_world: a * lattice.voxel_to_world,
        },
        _ => lattice.clone(),
    };
    let mut options = GridOptions::voxels(&lattice, tolerance_voxels);
    let tolerance_mm = options.tolerance_mm;
    if let (false, Some(a_inv)) = (inverse, map.alignment_inverse()) {
        // A⁻¹ after the flow stretches its error by at most its largest singular value.
        let linear = a_inv.fixed_view::<3, 3>(0, 0).into_owned();
        options.tolerance_mm /= linear.singular_values().max().max(1.0);
    }
    let control = if exact {
        None
    } else {
        Some(GridMap::new(map.flow(), &flow_lattice, !inverse, &options)?)
    };
    let slab = control
        .as_ref()
        .map_or(SLAB, |c| SLAB.div_ceil(c.stride()) * c.stride());
    let mut values = sample.map(|_| Vec::with_capacity(nx * ny * nz));
    let mut displacements = keep.then(|| Vec::with_capacity(nx * ny * nz));
    let (mut sum, mut max) = (0.0, 0.0f64);
    for z0 in (0..nz).step_by(slab) {
        let z = z0..(z0 + slab).min(nz);
        let centres = lattice.centres(z.clone());
        let sources: Vec<Vec3> = match &control {
            None => map.carry(&centres, !inverse)?,
            Some(control) => {
                let d = control.displacements(z.clone())?;
                let moved = flow_lattice.centres(z);
                let flowed = moved.iter().zip(&d).map(|(y, d)| y + d);
                match (inverse, map.alignment_inverse()) {
                    (false, Some(a_inv)) => flowed
                        .map(|x| a_inv.transform_point(&x.into()).coords)
                        .collect(),
                    _ => flowed.collect(),
                }
            }
        };
        for (s, y) in sources.iter().zip(&centres) {
            let d = s - y;
            sum += d.norm();
            max = max.max(d.norm());
            if let Some(kept) = &mut displacements {
                kept.push(d);
            }
        }
        if let (Some(values), Some(sample)) = (&mut values, sample) {
            use rayon::prelude::*;
            let sampled: Vec<f64> = sources.par_iter().map(sample).collect();
            values.extend(sampled);
        }
    }
    let voxels = nx * ny * nz;
    Ok(Pulled {
        values,
        displacements,
        voxels,
        mean_mm: sum / voxels.max(1) as f64,
        max_mm: max,
        grid: control.map(|c| ControlGrid {
            stride: c.stride(),
            nodes: c.node_count(),
            mapped_fraction: c.mapped_fraction(),
            tolerance_voxels,
            tolerance_mm,
            kernel_epsilon: c.epsilon(),
            interpolation_estimate_mm: c.interpolation_estimate(),
        }),
    })
}
