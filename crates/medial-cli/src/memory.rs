//! The memory limit of a run: `--max-memory GIB` (default: the machine's total memory,
//! `MemTotal` of `/proc/meminfo`, or [`FALLBACK_GIB`] where that cannot be read), set once by
//! `main` ([`set_limit`]). The estimates themselves are the engine's
//! ([`medial_core::memory::Estimate`]).

use crate::error::CliError;
use medial_core::memory::{Estimate, MemoryLimit, GIB};
use std::sync::OnceLock;

/// The limit when the machine's memory cannot be read, GiB.
pub const FALLBACK_GIB: f64 = 16.0;

static LIMIT: OnceLock<f64> = OnceLock::new();

/// Sets the limit of this run: `gib` GiB, or the machine's memory when `None`. Only the first
/// call counts.
pub fn set_limit(gib: Option<f64>) {
    LIMIT.get_or_init(|| gib.map_or_else(machine_memory, |g| g * GIB));
}

/// The limit (the machine's memory when [`set_limit`] was not called).
pub fn limit() -> MemoryLimit {
    MemoryLimit::bytes(*LIMIT.get_or_init(machine_memory))
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

/// Refuses to rasterize on a grid of `dims` voxels past the memory limit ([`Estimate::grid`]).
pub fn check_grid(dims: [usize; 3]) -> Result<(), CliError> {
    check(&Estimate::grid(dims), || {
        let voxels: f64 = dims.map(|n| n as f64).iter().product();
        format!(
            "a {}×{}×{} grid ({voxels:.2e} voxels)",
            dims[0], dims[1], dims[2]
        )
    })
}

/// Refuses `estimate` of `what` past the memory limit.
pub fn check(estimate: &Estimate, what: impl FnOnce() -> String) -> Result<(), CliError> {
    Ok(limit().check(estimate, what)?)
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
