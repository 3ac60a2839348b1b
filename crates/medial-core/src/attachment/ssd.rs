//! Sum of squared distances to corresponding target points:
//! `g(q) = Σ_{i∈Υ} |q_i − t_i|²`, `∇_i g = 2 (q_i − t_i)` for `i ∈ Υ`, 0 elsewhere.

use super::{Attachment, AttachmentValue};
use crate::{Error, Result, Vec3};

/// SSD to targets of the first `targets.len()` landmarks (the boundary points of a template).
#[derive(Clone, Debug, PartialEq)]
pub struct Ssd {
    targets: Vec<Vec3>,
}

impl Ssd {
    /// Targets for landmarks `0 … targets.len()−1`; refuses non-finite targets.
    pub fn new(targets: Vec<Vec3>) -> Result<Self> {
        if let Some(i) = targets
            .iter()
            .position(|t| !t.iter().all(|c| c.is_finite()))
        {
            return Err(Error::NonFinite(format!(
                "SSD target point {i} is {:?}",
                targets[i].as_slice()
            )));
        }
        Ok(Self { targets })
    }

    /// The target points.
    pub fn targets(&self) -> &[Vec3] {
        &self.targets
    }

    /// Mean distance `(1/|Υ|) Σ |q_i − t_i|` (mm), the figure users compare.
    pub fn mean_distance(&self, q: &[Vec3]) -> f64 {
        let sum: f64 = self
            .targets
            .iter()
            .zip(q)
            .map(|(t, p)| (p - t).norm())
            .sum();
        sum / self.targets.len().max(1) as f64
    }
}

impl Attachment for Ssd {
    fn evaluate(&self, q: &[Vec3], grad: Option<&mut [Vec3]>) -> Result<AttachmentValue> {
        let value = self
            .targets
            .iter()
            .zip(q)
            .map(|(t, p)| (p - t).norm_squared())
            .sum();
        if let Some(grad) = grad {
            grad.fill(Vec3::zeros());
            for ((g, t), p) in grad.iter_mut().zip(&self.targets).zip(q) {
                *g = 2.0 * (p - t);
            }
        }
        Ok(AttachmentValue { value, dice: None })
    }
}
