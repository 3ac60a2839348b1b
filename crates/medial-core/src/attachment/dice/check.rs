//! What the Dice attachment refuses: a boundary that is not closed and consistently oriented,
//! medial indices out of range, medial caps that would not cancel, sampling parameters out of
//! range.

use std::collections::HashMap;

use super::{DiceParams, MAX_PRISMS};
use crate::mesh::topology::{check_corners, check_edges, Orientation};
use crate::{Error, Result};

/// Checks indices, the closed oriented boundary and the pairing of medial caps.
pub(super) fn check_model(triangles: &[[usize; 3]], medial_of: &[usize], k: usize) -> Result<()> {
    let nb = medial_of.len();
    if triangles.is_empty() {
        return Err(Error::InvalidTemplate(
            "the boundary mesh has no triangles".into(),
        ));
    }
    if let Some((b, &m)) = medial_of
        .iter()
        .enumerate()
        .find(|&(_, &m)| m < nb || m >= k)
    {
        return Err(Error::InvalidTemplate(format!(
            "boundary point {b} has medial point {m}, outside the medial landmarks {nb}..{k}"
        )));
    }
    check_corners(nb, triangles)?;
    check_edges(triangles, Orientation::Consistent)?;
    check_medial_caps(triangles, medial_of)
}

/// Every non-degenerate medial triangle must occur as often with one orientation as with the
/// other, so that the medial caps of the prisms cancel.
fn check_medial_caps(triangles: &[[usize; 3]], medial_of: &[usize]) -> Result<()> {
    let canonical = |m: [usize; 3]| {
        let r = (0..3).min_by_key(|&r| m[r]).unwrap_or(0);
        [m[r], m[(r + 1) % 3], m[(r + 2) % 3]]
    };
    let mut balance: HashMap<[usize; 3], (i64, usize)> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        let m = tri.map(|b| medial_of[b]);
        if m[0] == m[1] || m[1] == m[2] || m[0] == m[2] {
            continue;
        }
        balance.entry(canonical(m)).or_insert((0, t)).0 += 1;
        balance
            .entry(canonical([m[0], m[2], m[1]]))
            .or_insert((0, t))
            .0 -= 1;
    }
    let mut unmatched: Vec<_> = balance.into_iter().filter(|(_, (n, _))| *n > 0).collect();
    unmatched.sort_unstable();
    match unmatched.first() {
        None => Ok(()),
        Some((m, (_, t))) => Err(Error::InvalidTemplate(format!(
            "medial triangle {m:?} (of boundary triangle {t}) is not covered by an opposite \
             boundary triangle, so the Dice prisms would not tile the model ({} such triangles)",
            unmatched.len()
        ))),
    }
}

pub(super) fn check_params(triangle_count: usize, params: DiceParams) -> Result<()> {
    if params.layers == 0 {
        return Err(Error::InvalidParameter(
            "Dice layers must be at least 1".into(),
        ));
    }
    let prisms = 4usize
        .checked_pow(params.subdivision as u32)
        .and_then(|s| s.checked_mul(triangle_count))
        .and_then(|n| n.checked_mul(params.layers));
    match prisms {
        Some(n) if n <= MAX_PRISMS => Ok(()),
        _ => Err(Error::InvalidParameter(format!(
            "Dice sampling with subdivision {} and {} layers over {triangle_count} triangles \
             would exceed {MAX_PRISMS} prisms",
            params.subdivision, params.layers
        ))),
    }
}
