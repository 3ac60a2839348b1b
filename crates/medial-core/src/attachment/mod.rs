//! Data attachments `g(q^N)`: how far the flowed model is from the subject.

pub mod dice;
pub mod ssd;
pub mod varifold;

use crate::{Result, Vec3};

/// The value of an attachment at a configuration.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AttachmentValue {
    /// `g(q)` (unweighted).
    pub value: f64,
    /// The Dice coefficient, for attachments that estimate one.
    pub dice: Option<f64>,
}

/// A data term `g(q)` of the landmark configuration `q` (all `k` landmarks).
pub trait Attachment: Sync {
    /// `g(q)`; if `grad` is given (length `k`), it is overwritten with `∇g(q)`.
    fn evaluate(&self, q: &[Vec3], grad: Option<&mut [Vec3]>) -> Result<AttachmentValue>;
}

/// `g = 1 − DSC`, `∇g = −∇DSC`, from [`dice::DiceAttachment::dice`].
impl Attachment for dice::DiceAttachment {
    fn evaluate(&self, q: &[Vec3], mut grad: Option<&mut [Vec3]>) -> Result<AttachmentValue> {
        let value = self.dice(q, grad.as_deref_mut())?;
        if let Some(grad) = grad {
            grad.iter_mut().for_each(|g| *g = -*g);
        }
        Ok(AttachmentValue {
            value: 1.0 - value.dice,
            dice: Some(value.dice),
        })
    }
}
