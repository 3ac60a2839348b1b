//! Memory estimates of a run, checked against a limit before the large buffers are allocated:
//! without them a fit of 10¹¹ time steps or a grid of 0.1 µm voxels would abort the process on
//! a failed allocation (docs/method.md §9).
//!
//! Each estimate counts the large buffers of one part of a run, in bytes (an `f64` is 8 B, a
//! point 24 B):
//!
//! * **the flow of a fit** ([`Estimate::flow`]), for `N` time steps, `k` landmarks, `S` stages
//!   and `m` their largest L-BFGS memory: `8·N·k·3·(2m + 20 + S)` for the L-BFGS correction
//!   pairs (`2m` vectors of `N·k·3`), the momenta, gradients and iterates held by the fit,
//!   L-BFGS, its line search and back-off and the trajectory (about 20 such vectors) and the
//!   result of each stage; plus `8·N·L·(3 + S)` for the multipliers, constraint values and
//!   penalty weights of `L ≤ 3k` constraints per time point (two orthogonality constraints and
//!   at most one equal-spoke constraint per boundary point);
//! * **a Dice stage** ([`Estimate::dice`]), over `T` boundary triangles midpoint-subdivided `s`
//!   times (`T_s = T·4^s`), `layers` layers, `k` landmarks and `V` image voxels:
//!   `232·T_s` (subdivided triangles, their prism faces and vertex stencils, about `T_s/2`
//!   vertices) + `16·T_s·layers` (the image samples of an evaluation) + `48·k·⌈T_s/c⌉` (the
//!   gradient sums of each chunk of `c` triangles, [`crate::attachment::dice::MIN_CHUNK`]) +
//!   `32·V` (the image read, its mask, its smoothed copy and the working copy of the smoothing
//!   or of the final rasterization);
//! * **a grid to rasterize** ([`Estimate::grid`]), `V` voxels: `24·V` (the `f64` volume, the
//!   buffer its slices are collected in, the 8-bit copy written);
//! * **an initial alignment** ([`Estimate::alignment`]): the template rasterized on a grid of
//!   `V_g` voxels (`24·V_g`, as above) and, for an image of `V` voxels, `40·V`: the image read
//!   and its foreground (8 B each) and the template rasterized on the image's grid for the
//!   voxel Dice (24 B, as a grid);
//! * **a pull-back of an image through a fitted map** ([`Estimate::pull_back`]), `V` voxels of
//!   the output grid: `128·V` (the voxel centres and the points they map to, their
//!   displacements and the warp's values, 24 B each; the resampled values and the bytes
//!   written, 8 B each).
//!
//! ```
//! use medial_core::memory::{Estimate, MemoryLimit};
//! let grid = Estimate::grid([100, 100, 100]);
//! assert_eq!(grid.total(), 24.0e6);
//! assert!(MemoryLimit::bytes(1e9).check(&grid, || "a grid".into()).is_ok());
//! assert!(MemoryLimit::bytes(1e6).check(&grid, || "a grid".into()).is_err());
//! ```

use crate::{Error, Result};

/// Bytes in a GiB.
pub const GIB: f64 = (1u64 << 30) as f64;

/// Vectors of `N·k·3` numbers a fit holds besides the L-BFGS pairs and the stages' results.
const FLOW_VECTORS: f64 = 20.0;

/// Constraints per landmark and time point, at most (see the module documentation).
const CONSTRAINTS_PER_LANDMARK: f64 = 3.0;

/// Bytes per image voxel of an initial alignment (see the module documentation).
const ALIGNMENT_IMAGE_BYTES: f64 = 40.0;

/// Bytes per output voxel of a pull-back.
const PULL_BACK_BYTES: f64 = 128.0;

/// An estimate of the large buffers of a part of a run, by named part, in bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    parts: Vec<(&'static str, f64)>,
}

impl Estimate {
    /// The flow of a fit of `time_steps` steps × `landmarks` landmarks through `stages` stages
    /// whose largest L-BFGS memory is `lbfgs_memory` pairs.
    pub fn flow(time_steps: usize, landmarks: usize, stages: usize, lbfgs_memory: usize) -> Self {
        let n = time_steps as f64;
        let stages = stages as f64;
        let memory = lbfgs_memory as f64;
        let controls = n * landmarks as f64 * 3.0;
        let multipliers = n * CONSTRAINTS_PER_LANDMARK * landmarks as f64;
        Self {
            parts: vec![
                (
                    "momenta, gradients and L-BFGS pairs",
                    8.0 * controls * (2.0 * memory + FLOW_VECTORS + stages),
                ),
                ("multipliers", 8.0 * multipliers * (3.0 + stages)),
            ],
        }
    }

    /// A Dice stage of `triangles` boundary triangles subdivided `subdivision` times and
    /// sampled in `layers` layers, `landmarks` landmarks, against an image of `voxels` voxels
    /// (with its refined copy, if any).
    pub fn dice(
        subdivision: usize,
        layers: usize,
        triangles: usize,
        landmarks: usize,
        voxels: usize,
    ) -> Self {
        let subdivided = triangles as f64 * 4f64.powf(subdivision as f64);
        let chunks = (subdivided / crate::attachment::dice::MIN_CHUNK as f64).ceil();
        Self {
            parts: vec![
                (
                    "Dice samples and prisms",
                    subdivided * (232.0 + 16.0 * layers as f64) + 48.0 * landmarks as f64 * chunks,
                ),
                ("image copies", 32.0 * voxels as f64),
            ],
        }
    }

    /// An initial alignment against an image (or a rasterized surface) of `image_voxels`
    /// voxels that rasterizes the template on a grid of `grid` voxels for its moments.
    pub fn alignment(grid: [usize; 3], image_voxels: usize) -> Self {
        let mut estimate = Self::grid(grid);
        estimate.parts[0].0 = "the template's grid";
        estimate.parts.push((
            "the image, its foreground and the template rasterized on it",
            ALIGNMENT_IMAGE_BYTES * image_voxels as f64,
        ));
        estimate
    }

    /// A grid of `dims` voxels to rasterize.
    pub fn grid(dims: [usize; 3]) -> Self {
        Self {
            parts: vec![(
                "voxels",
                24.0 * dims.map(|n| n as f64).iter().product::<f64>(),
            )],
        }
    }

    /// A pull-back of an image of `voxels` output voxels through a fitted map.
    pub fn pull_back(voxels: usize) -> Self {
        Self {
            parts: vec![("voxels", PULL_BACK_BYTES * voxels as f64)],
        }
    }

    /// The whole estimate, bytes.
    pub fn total(&self) -> f64 {
        self.parts.iter().map(|(_, b)| b).sum()
    }
}

impl std::fmt::Display for Estimate {
    /// `about 1.2 GiB (part 1.0 GiB, part 0.2 GiB)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "about {}", human(self.total()))?;
        if self.parts.len() > 1 {
            let parts: Vec<String> = self
                .parts
                .iter()
                .map(|(name, bytes)| format!("{name} {}", human(*bytes)))
                .collect();
            write!(f, " ({})", parts.join(", "))?;
        }
        Ok(())
    }
}

/// The memory a run may use, bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryLimit(f64);

impl MemoryLimit {
    /// A limit of `bytes` (not a positive number: no limit).
    pub fn bytes(bytes: f64) -> Self {
        Self(if bytes > 0.0 { bytes } else { f64::INFINITY })
    }

    /// No limit.
    pub fn none() -> Self {
        Self(f64::INFINITY)
    }

    /// The limit, bytes.
    pub fn get(self) -> f64 {
        self.0
    }

    /// `Ok` when `estimate` is within the limit; else [`Error::Memory`] naming `what`.
    pub fn check(self, estimate: &Estimate, what: impl FnOnce() -> String) -> Result<()> {
        if estimate.total() <= self.0 {
            return Ok(());
        }
        Err(Error::Memory {
            what: what(),
            estimate: estimate.to_string(),
            limit: self.0,
        })
    }
}

/// Bytes in words: `3.0 GiB`, `5.0 MiB`, `2.5e5 GiB`.
pub fn human(bytes: f64) -> String {
    let gib = bytes / GIB;
    if gib >= 1e4 {
        format!("{gib:.1e} GiB")
    } else if gib >= 0.1 {
        format!("{gib:.1} GiB")
    } else {
        format!("{:.1} MiB", bytes / (1u64 << 20) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_read_in_the_right_unit() {
        assert_eq!(human(3.0 * GIB), "3.0 GiB");
        assert_eq!(human(5.0 * (1 << 20) as f64), "5.0 MiB");
        assert_eq!(human(2.5e5 * GIB), "2.5e5 GiB");
    }

    #[test]
    fn estimates_follow_the_formulas() {
        // N·k·3 = 3000 numbers in 2·5 + 20 + 1 vectors; N·3k = 3000 multipliers, 3 + 1 times.
        let flow = Estimate::flow(10, 100, 1, 5);
        assert_eq!(flow.total(), 8.0 * 3000.0 * 31.0 + 8.0 * 3000.0 * 4.0);
        let grid = Estimate::grid([10, 20, 30]);
        assert_eq!(grid.total(), 24.0 * 6000.0);
        assert_eq!(Estimate::pull_back(1000).total(), 128_000.0);
        // 100 triangles → 400 subdivided, 4 chunks of 128; 1000 voxels.
        let dice = Estimate::dice(1, 2, 100, 50, 1000);
        assert_eq!(
            dice.total(),
            400.0 * (232.0 + 32.0) + 48.0 * 50.0 * 4.0 + 32_000.0
        );
        assert!(
            dice.to_string().contains("(Dice samples and prisms "),
            "{dice}"
        );
        assert_eq!(grid.to_string(), "about 0.1 MiB");
    }

    #[test]
    fn a_limit_refuses_what_passes_it() {
        let grid = Estimate::grid([10, 20, 30]);
        let limit = MemoryLimit::bytes(1000.0);
        let e = limit.check(&grid, || "a grid".into()).unwrap_err();
        assert!(matches!(e, Error::Memory { limit: 1000.0, .. }), "{e}");
        assert!(MemoryLimit::none().check(&grid, || unreachable!()).is_ok());
        assert_eq!(MemoryLimit::bytes(0.0), MemoryLimit::none());
    }
}
