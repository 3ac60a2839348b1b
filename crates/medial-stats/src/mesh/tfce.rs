//! Threshold-free cluster enhancement (Smith & Nichols 2009) on the mesh:
//! TFCE(e) = Σₖ ext(e, hₖ)^E hₖ^H dh over the heights hₖ = k·dh ≤ s(e), k = 1, 2, …, where
//! ext(e, h) is the area of the cluster of {s ≥ h} that holds e. A two-sided map is
//! TFCE(s) − TFCE(−s).
//!
//! Heights are visited from the top down while elements are switched on in decreasing order of
//! their statistic and joined to their neighbours (union–find); at each height every
//! component's contribution is added to its root's potential, so that an element's value is the
//! sum of the potentials on its path to its root. The cost is a sort and, per height, the
//! number of components.

use super::{Elements, Forest};
use crate::{Result, StatsError, Tail};

/// The parameters of TFCE.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TfceParameters {
    /// E, the power of the extent (0.5, meshglm's default; PALM uses 1 on surfaces).
    pub extent_power: f64,
    /// H, the power of the height (2).
    pub height_power: f64,
    /// dh, the step between heights.
    pub step: f64,
}

impl Default for TfceParameters {
    fn default() -> Self {
        Self {
            extent_power: 0.5,
            height_power: 2.0,
            step: 0.1,
        }
    }
}

impl TfceParameters {
    /// Checks that the powers are finite and not negative and the step positive.
    pub fn validate(&self) -> Result<()> {
        if !(self.extent_power >= 0.0 && self.extent_power.is_finite()) {
            return Err(StatsError::parameter(
                "tfce E",
                self.extent_power,
                "must be finite and ≥ 0",
            ));
        }
        if !(self.height_power >= 0.0 && self.height_power.is_finite()) {
            return Err(StatsError::parameter(
                "tfce H",
                self.height_power,
                "must be finite and ≥ 0",
            ));
        }
        if !(self.step > 0.0 && self.step.is_finite()) {
            return Err(StatsError::parameter(
                "tfce dh",
                self.step,
                "must be finite and > 0",
            ));
        }
        Ok(())
    }
}

/// One side: the TFCE of max(sign × s, 0), added into `out` times `sign`.
fn one_side(
    statistic: &[f64],
    sign: f64,
    parameters: &TfceParameters,
    elements: &Elements,
    forest: &mut Forest,
    order: &mut Vec<usize>,
    out: &mut [f64],
) {
    let dh = parameters.step;
    order.clear();
    order.extend((0..statistic.len()).filter(|&e| sign * statistic[e] >= dh));
    if order.is_empty() {
        return;
    }
    order.sort_by(|&a, &b| {
        (sign * statistic[b])
            .total_cmp(&(sign * statistic[a]))
            .then(a.cmp(&b))
    });
    // One height more than the quotient says, in case it rounds down: the heights above the
    // largest statistic switch nothing on and add nothing.
    let top = (sign * statistic[order[0]] / dh).floor() as usize + 1;
    forest.clear();
    let mut roots: Vec<usize> = Vec::new();
    let mut next = 0;
    for k in (1..=top).rev() {
        let h = k as f64 * dh;
        while next < order.len() && sign * statistic[order[next]] >= h {
            let e = order[next];
            forest.switch_on(e, elements.areas()[e], 0.0);
            roots.push(e);
            for &nb in elements.neighbours(e) {
                if forest.is_on(nb) {
                    forest.union(e, nb);
                }
            }
            next += 1;
        }
        roots.retain(|&r| forest.is_root(r));
        let weight = h.powf(parameters.height_power) * dh;
        for &r in &roots {
            let (extent, _) = forest.totals(r);
            forest.raise(r, extent.powf(parameters.extent_power) * weight);
        }
    }
    for &e in order.iter() {
        out[e] += sign * forest.value(e);
    }
}

/// Scratch space for [`tfce_into`], reused across permutations.
#[derive(Clone, Debug)]
pub(crate) struct TfceScratch {
    forest: Forest,
    order: Vec<usize>,
}

impl TfceScratch {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            forest: Forest::new(n),
            order: Vec::with_capacity(n),
        }
    }
}

/// TFCE of `statistic` into `out` (NaN counts as 0).
pub(crate) fn tfce_into(
    statistic: &[f64],
    parameters: &TfceParameters,
    tail: Tail,
    elements: &Elements,
    scratch: &mut TfceScratch,
    out: &mut [f64],
) {
    out.fill(0.0);
    let signs: &[f64] = match tail {
        Tail::Positive => &[1.0],
        Tail::Both => &[1.0, -1.0],
    };
    for &sign in signs {
        one_side(
            statistic,
            sign,
            parameters,
            elements,
            &mut scratch.forest,
            &mut scratch.order,
            out,
        );
    }
}

/// The TFCE map of `statistic` (one-sided: its positive part; two-sided: signed).
///
/// ```
/// use medial_stats::{tfce, Elements, Mesh, Support, Tail, TfceParameters};
///
/// let mesh = Mesh::new(
///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
///     vec![[0, 1, 2], [1, 3, 2]],
/// )?;
/// let cells = Elements::new(&mesh, Support::Cells);
/// let p = TfceParameters { extent_power: 1.0, height_power: 0.0, step: 1.0 };
/// // Heights 1 and 2: cell 0 is in a cluster of area 1, then 0.5.
/// assert_eq!(tfce(&[2.0, 1.5], &p, Tail::Positive, &cells), [1.5, 1.0]);
/// # Ok::<(), medial_stats::StatsError>(())
/// ```
pub fn tfce(
    statistic: &[f64],
    parameters: &TfceParameters,
    tail: Tail,
    elements: &Elements,
) -> Vec<f64> {
    let mut out = vec![0.0; statistic.len()];
    let mut scratch = TfceScratch::new(statistic.len());
    tfce_into(
        statistic,
        parameters,
        tail,
        elements,
        &mut scratch,
        &mut out,
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::tests::{brute_force_components, grid};
    use crate::mesh::Support;
    use proptest::prelude::*;

    /// The definition, height by height, with components by breadth-first search.
    fn brute_force(
        statistic: &[f64],
        p: &TfceParameters,
        tail: Tail,
        elements: &Elements,
    ) -> Vec<f64> {
        let mut out = vec![0.0; statistic.len()];
        let signs: &[f64] = if tail == Tail::Both {
            &[1.0, -1.0]
        } else {
            &[1.0]
        };
        for &sign in signs {
            let mut k = 1;
            loop {
                let h = k as f64 * p.step;
                let active: Vec<bool> = statistic.iter().map(|s| sign * s >= h).collect();
                if !active.contains(&true) {
                    break;
                }
                for members in brute_force_components(&active, elements) {
                    let area: f64 = members.iter().map(|&e| elements.areas()[e]).sum();
                    for e in members {
                        out[e] +=
                            sign * area.powf(p.extent_power) * h.powf(p.height_power) * p.step;
                    }
                }
                k += 1;
            }
        }
        out
    }

    proptest! {
        #[test]
        fn tfce_equals_its_definition(
            values in proptest::collection::vec(-4.0..4.0f64, 50),
            cells in any::<bool>(),
            two_sided in any::<bool>(),
            step in 0.05..0.5f64,
            extent_power in 0.2..1.5f64,
        ) {
            let support = if cells { Support::Cells } else { Support::Points };
            let elements = Elements::new(&grid(5), support);
            let values = &values[..elements.len()];
            let tail = if two_sided { Tail::Both } else { Tail::Positive };
            let p = TfceParameters { extent_power, height_power: 2.0, step };
            let fast = tfce(values, &p, tail, &elements);
            let slow = brute_force(values, &p, tail, &elements);
            for (a, b) in fast.iter().zip(&slow) {
                prop_assert!((a - b).abs() <= 1e-10 * (1.0 + b.abs()), "{} vs {}", a, b);
            }
        }
    }

    #[test]
    fn bad_parameters_are_refused() {
        let p = TfceParameters {
            step: 0.0,
            ..TfceParameters::default()
        };
        assert_eq!(
            p.validate().unwrap_err().to_string(),
            "tfce dh = 0: must be finite and > 0"
        );
        assert!(TfceParameters {
            extent_power: -1.0,
            ..TfceParameters::default()
        }
        .validate()
        .is_err());
        assert!(TfceParameters::default().validate().is_ok());
    }
}
