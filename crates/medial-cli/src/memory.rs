//! Memory estimates of a run, refused past a limit before the large buffers are allocated:
//! without them a config of 10¹¹ time steps or a grid of 0.1 µm voxels aborts the process on a
//! failed allocation.
//!
//! The limit is `--max-memory GIB` (default: the machine's total memory, `MemTotal` of
//! `/proc/meminfo`, or [`FALLBACK_GIB`] where that cannot be read), set once by `main`
//! ([`set_limit`]). Each estimate counts the large buffers of one part of a run, in bytes (an
//! `f64` is 8 B, a point 24 B):
//!
//! * **the flow of a fit** ([`Estimate::flow`]), for `N` time steps, `k` landmarks, `S` stages
//!   and `m` their largest `lbfgs_memory`: `8·N·k·3·(2m + 20 + S)` for the L-BFGS correction
//!   pairs (`2m` vectors of `N·k·3`), the momenta, gradients and iterates held by the fit,
//!   L-BFGS, its line search and back-off and the trajectory (about 20 such vectors) and the
//!   result of each stage; plus `8·N·L·(3 + S)` for the multipliers, constraint values and
//!   penalty weights of `L ≤ 3k` constraints per time point (two orthogonality constraints and
//!   at most one equal-spoke constraint per boundary point);
//! * **a Dice stage** ([`Estimate::dice`]), over `T` boundary triangles midpoint-subdivided `s`
//!   times (`T_s = T·4^s`), `layers` layers, `k` landmarks and `V` image voxels:
//!   `232·T_s` (subdivided triangles, their prism faces and vertex stencils, about `T_s/2`
//!   vertices) + `16·T_s·layers` (the image samples of an evaluation) + `48·k·⌈T_s/128⌉` (the
//!   gradient sums of each chunk of 128 triangles) + `32·V` (the image read, its mask, its
//!   smoothed copy and the working copy of the smoothing or of the final rasterization);
//! * **a grid to rasterize** ([`Estimate::grid`]), `V` voxels: `24·V` (the `f64` volume, the
//!   buffer its slices are collected in, the 8-bit copy written);
//! * **a pull-back of `medial apply`** ([`Estimate::pull_back`]), `V` voxels of the output grid:
//!   `128·V` (the voxel centres and the points they map to, their displacements and the warp's
//!   values, 24 B each; the resampled values and the bytes written, 8 B each).

use crate::config::{Config, StageConfig};
use crate::error::CliError;
use std::sync::OnceLock;

/// Bytes in a GiB.
const GIB: f64 = (1u64 << 30) as f64;

/// The limit when the machine's memory cannot be read, GiB.
pub const FALLBACK_GIB: f64 = 16.0;

/// Vectors of `N·k·3` numbers a fit holds besides the L-BFGS pairs and the stages' results.
const FLOW_VECTORS: f64 = 20.0;

/// Constraints per landmark, at most (see the module doc).
const CONSTRAINTS_PER_LANDMARK: f64 = 3.0;

/// Bytes per voxel of a pull-back (see the module doc).
const PULL_BACK_BYTES: f64 = 128.0;

/// Triangles per chunk of the Dice sums (`medial_core::attachment::dice`).
const DICE_CHUNK: f64 = 128.0;

/// The limit of this run, bytes.
static LIMIT: OnceLock<f64> = OnceLock::new();

/// Sets the limit of this run: `gib` GiB, or the machine's memory when `None`. Only the first
/// call counts.
pub fn set_limit(gib: Option<f64>) {
    LIMIT.get_or_init(|| gib.map_or_else(machine_memory, |g| g * GIB));
}

/// The limit, bytes (the machine's memory when [`set_limit`] was not called).
fn limit() -> f64 {
    *LIMIT.get_or_init(machine_memory)
}

/// `MemTotal` of `/proc/meminfo` in bytes, or [`FALLBACK_GIB`].
fn machine_memory() -> f64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_total(&text))
        .unwrap_or(FALLBACK_GIB * GIB)
}

/// The `MemTotal:  N kB` line of a `/proc/meminfo` text, in bytes.
fn mem_total(meminfo: &str) -> Option<f64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut words = line["MemTotal:".len()..].split_whitespace();
    let kib: f64 = words.next()?.parse().ok()?;
    (words.next() == Some("kB") && kib > 0.0).then_some(kib * 1024.0)
}

/// Parses `--max-memory`: a positive number of GiB.
pub fn parse_gib(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(g) if g.is_finite() && g > 0.0 => Ok(g),
        _ => Err(format!("expected a positive number of GiB, got '{text}'")),
    }
}

/// A size in bytes as a short text: MiB below 0.1 GiB, GiB above, powers of ten past 10⁴ GiB.
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

/// Refuses to rasterize on a grid of `dims` voxels past the memory limit ([`Estimate::grid`]).
pub fn check_grid(dims: [usize; 3]) -> Result<(), CliError> {
    Estimate::grid(dims).check(|| {
        let voxels: f64 = dims.map(|n| n as f64).iter().product();
        format!(
            "a {}×{}×{} grid ({voxels:.2e} voxels)",
            dims[0], dims[1], dims[2]
        )
    })
}

/// The estimated memory of a part of a run: named parts, bytes (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    parts: Vec<(&'static str, f64)>,
}

impl Estimate {
    /// The flow of a fit of `config` over `landmarks` points (every stage).
    pub fn flow(config: &Config, landmarks: usize) -> Self {
        let n = config.flow.time_steps as f64;
        let stages = config.stages.len() as f64;
        let memory = config
            .stages
            .iter()
            .map(|s| s.lbfgs_memory)
            .max()
            .unwrap_or(0) as f64;
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

    /// A Dice `stage` over `triangles` boundary triangles and `landmarks` points, against an
    /// image of `voxels` voxels.
    pub fn dice(stage: &StageConfig, triangles: usize, landmarks: usize, voxels: usize) -> Self {
        let subdivided = triangles as f64 * 4f64.powf(stage.subdivision as f64);
        let chunks = (subdivided / DICE_CHUNK).ceil();
        Self {
            parts: vec![
                (
                    "Dice samples and prisms",
                    subdivided * (232.0 + 16.0 * stage.layers as f64)
                        + 48.0 * landmarks as f64 * chunks,
                ),
                ("image copies", 32.0 * voxels as f64),
            ],
        }
    }

    /// Rasterizing on a grid of `dims` voxels.
    pub fn grid(dims: [usize; 3]) -> Self {
        Self {
            parts: vec![(
                "voxels",
                24.0 * dims.map(|n| n as f64).iter().product::<f64>(),
            )],
        }
    }

    /// Pulling an image back on a grid of `voxels` voxels (and its warp).
    pub fn pull_back(voxels: usize) -> Self {
        Self {
            parts: vec![("voxels", PULL_BACK_BYTES * voxels as f64)],
        }
    }

    /// The total, bytes.
    pub fn total(&self) -> f64 {
        self.parts.iter().map(|(_, b)| b).sum()
    }

    /// Refuses when the total passes the limit of this run; `what` says what would need it.
    pub fn check(self, what: impl FnOnce() -> String) -> Result<(), CliError> {
        let limit = limit();
        if self.total() <= limit {
            return Ok(());
        }
        Err(CliError::Memory {
            what: what(),
            estimate: self,
            limit,
        })
    }
}

/// `about 3.0 GiB (flow 2.0 GiB, image 1.0 GiB)`; the parts only when there are several.
impl std::fmt::Display for Estimate {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::AttachmentKind;

    #[test]
    fn mem_total_is_read_in_kib() {
        let text = "MemFree:  100 kB\nMemTotal:       24536916 kB\nSwapTotal: 0 kB\n";
        assert_eq!(mem_total(text), Some(24536916.0 * 1024.0));
        assert_eq!(mem_total("MemTotal: many kB"), None);
        assert_eq!(mem_total("MemTotal: 12 MB"), None);
        assert_eq!(mem_total(""), None);
    }

    #[test]
    fn max_memory_must_be_positive() {
        assert_eq!(parse_gib("0.5"), Ok(0.5));
        for bad in ["0", "-1", "NaN", "inf", "lots"] {
            assert!(parse_gib(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn sizes_read_in_the_right_unit() {
        assert_eq!(human(3.0 * GIB), "3.0 GiB");
        assert_eq!(human(5.0 * (1 << 20) as f64), "5.0 MiB");
        assert_eq!(human(2.5e5 * GIB), "2.5e5 GiB");
    }

    #[test]
    fn estimates_follow_the_formulas() {
        let config: Config = toml::from_str(
            "[model]\ntemplate = \"t.vtk\"\n[flow]\ntime_steps = 10\n[[stage]]\nname = \"a\"\n\
             attachment = \"ssd\"\ntarget = \"s.vtk\"\nlbfgs_memory = 5\n",
        )
        .unwrap();
        // N·k·3 = 3000 numbers in 2·5 + 20 + 1 vectors; N·3k = 3000 multipliers, 3 + 1 times.
        let flow = Estimate::flow(&config, 100);
        assert_eq!(flow.total(), 8.0 * 3000.0 * 31.0 + 8.0 * 3000.0 * 4.0);
        let grid = Estimate::grid([10, 20, 30]);
        assert_eq!(grid.total(), 24.0 * 6000.0);
        assert_eq!(Estimate::pull_back(1000).total(), 128_000.0);
        let mut stage = StageConfig::new("dice", AttachmentKind::Dice);
        stage.subdivision = 1;
        stage.layers = 2;
        // 100 triangles → 400 subdivided, 4 chunks; 1000 voxels.
        let dice = Estimate::dice(&stage, 100, 50, 1000);
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
}
