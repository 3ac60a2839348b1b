//! A fit described as data: the flow's settings and the stages run one after the other, each
//! with its attachment (one variant per data term, holding only that term's settings), the
//! medial constraints, the augmented-Lagrangian schedule and the L-BFGS options
//! (docs/method.md §5–§7). The data the stages are fitted to is not part of it: a
//! [`crate::fit::Target`] in memory goes with each stage when it is prepared
//! ([`crate::fit::PreparedStage::new`]).
//!
//! A [`FitSpec`] is what `medial fit`'s TOML config describes, and what
//! [`crate::fit::plan::automatic`] chooses from the data.
//!
//! ```
//! use medial_core::fit::{AttachmentSpec, FitSpec, FlowSettings, StageSpec};
//! let spec = FitSpec {
//!     flow: FlowSettings { sigma: 3.0, time_steps: 10, ..FlowSettings::default() },
//!     stages: vec![StageSpec::new("points", AttachmentSpec::Ssd)],
//! };
//! spec.check().unwrap();
//! assert_eq!(spec.stages[0].data_weight(), 1.0);
//! ```

use crate::attachment::varifold::{Kind, DEFAULT_NORMAL_WIDTH};
use crate::fit::augmented_lagrangian::AlSchedule;
use crate::fit::optimize::LbfgsOptions;
use crate::flow::kernel::MAX_TOLERANCE;
use crate::flow::{Flow, FlowParams};
use crate::model::constraints::ConstraintUnits;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// The flow of a fit (docs/method.md §2).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowSettings {
    /// Kernel width σ, in the unit of the coordinates (mm).
    pub sigma: f64,
    /// Number of time steps N.
    pub time_steps: usize,
    /// Weight of the kinetic energy.
    pub kinetic_weight: f64,
    /// Kernel tolerance ε: the sums skip landmark pairs whose kernel value is below it
    /// (0: exact; at most [`MAX_TOLERANCE`]).
    pub kernel_tolerance: f64,
}

impl Default for FlowSettings {
    fn default() -> Self {
        Self {
            sigma: 2.0,
            time_steps: 40,
            kinetic_weight: 0.05,
            kernel_tolerance: 0.0,
        }
    }
}

impl FlowSettings {
    /// The flow of `landmarks` points with these settings.
    pub fn flow(&self, landmarks: usize) -> Result<Flow> {
        let params = FlowParams {
            sigma: self.sigma,
            time_steps: self.time_steps,
            kinetic_weight: self.kinetic_weight,
        };
        Flow::new(params, landmarks)?.with_kernel_tolerance(self.kernel_tolerance)
    }

    fn check(&self) -> std::result::Result<(), String> {
        positive("flow.sigma", self.sigma)?;
        non_negative("flow.kinetic_weight", self.kinetic_weight)?;
        if !(0.0..=MAX_TOLERANCE).contains(&self.kernel_tolerance) {
            return Err(format!(
                "flow.kernel_tolerance must be in [0, {MAX_TOLERANCE}], got {}",
                self.kernel_tolerance
            ));
        }
        if self.time_steps == 0 {
            return Err("flow.time_steps must be at least 1".into());
        }
        Ok(())
    }
}

/// The settings of a Dice stage (docs/method.md §6.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiceSpec {
    /// Gaussian smoothing of the foreground, mm.
    pub image_sigma: f64,
    /// Every voxel split `image_refine³` times, the image interpolated trilinearly, before its
    /// foreground is taken (1: off): for graded signed images (a level set whose foreground is
    /// `v > 0`), whose boundary follows the zero crossing between voxel centres. It interpolates
    /// intensities: an image read by a label cannot be refined.
    pub image_refine: usize,
    /// Midpoint subdivisions of the boundary.
    pub subdivision: usize,
    /// Layers between boundary and medial sheet.
    pub layers: usize,
}

/// Largest [`DiceSpec::image_refine`]: each voxel becomes `image_refine³`.
pub const MAX_IMAGE_REFINE: usize = 8;

impl Default for DiceSpec {
    fn default() -> Self {
        Self {
            image_sigma: 0.2,
            image_refine: 1,
            subdivision: 2,
            layers: 5,
        }
    }
}

/// The settings of a varifold stage (docs/method.md §6.3).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VarifoldSpec {
    /// The distance: varifold, oriented varifold or current.
    pub kind: Kind,
    /// The spatial kernel width σ_w, mm (none: chosen from the target surface,
    /// [`crate::attachment::varifold::default_width`]).
    pub width: Option<f64>,
}

/// The data term of a stage, with its own settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AttachmentSpec {
    /// Sum of squared distances to corresponding points (docs/method.md §6.1).
    Ssd,
    /// `1 − Dice` against a binary image.
    Dice(DiceSpec),
    /// Varifold (or current) distance to a surface without correspondence.
    Varifold(VarifoldSpec),
}

impl AttachmentSpec {
    /// The attachment's name in a config: `ssd`, `dice` or `varifold`.
    pub fn name(&self) -> &'static str {
        match self {
            AttachmentSpec::Ssd => "ssd",
            AttachmentSpec::Dice(_) => "dice",
            AttachmentSpec::Varifold(_) => "varifold",
        }
    }
}

/// The largest deviations from medial geometry at the end of a constrained stage that count
/// as medial (docs/method.md §4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MedialTolerance {
    /// Largest spoke–normal angle, degrees.
    pub angle_deg: f64,
    /// Largest spoke-length mismatch, %.
    pub mismatch_pct: f64,
}

impl Default for MedialTolerance {
    fn default() -> Self {
        Self {
            angle_deg: 1.0,
            mismatch_pct: 1.0,
        }
    }
}

/// One stage of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct StageSpec {
    /// Name used in logs and outputs.
    pub name: String,
    /// The data term.
    pub attachment: AttachmentSpec,
    /// Weight of the data term (none: [`StageSpec::data_weight`]'s default).
    pub weight: Option<f64>,
    /// Medial constraints (none: on for medial templates).
    pub constraints: Option<bool>,
    /// Unit of the medial constraints in the penalty.
    pub constraint_units: ConstraintUnits,
    /// The μ schedule.
    pub schedule: AlSchedule,
    /// L-BFGS options of each minimisation.
    pub lbfgs: LbfgsOptions,
    /// What counts as medial at the end.
    pub tolerance: MedialTolerance,
}

impl StageSpec {
    /// A stage named `name` fitting by `attachment`, every other setting at its default: one
    /// AL iteration at μ = 1 (growing tenfold, at most 10⁶), up to 1,000 L-BFGS iterations of
    /// memory 10, constraints in relative units, 1° and 1 % tolerances.
    pub fn new(name: &str, attachment: AttachmentSpec) -> Self {
        Self {
            name: name.into(),
            attachment,
            weight: None,
            constraints: None,
            constraint_units: ConstraintUnits::Relative,
            schedule: AlSchedule::default(),
            lbfgs: LbfgsOptions::default(),
            tolerance: MedialTolerance::default(),
        }
    }

    /// The data weight: given, or 1 for SSD and 100 for Dice and varifold (for a varifold it
    /// multiplies `g / ‖T‖²`).
    pub fn data_weight(&self) -> f64 {
        self.weight.unwrap_or(match self.attachment {
            AttachmentSpec::Ssd => 1.0,
            AttachmentSpec::Dice(_) | AttachmentSpec::Varifold(_) => 100.0,
        })
    }

    /// Checks the values (positive μ, a coarse schedule that divides the flow's `time_steps`,
    /// …): the message names the setting as a config names it.
    fn check(&self, time_steps: usize) -> std::result::Result<(), String> {
        match &self.attachment {
            AttachmentSpec::Ssd => {}
            AttachmentSpec::Dice(d) => {
                non_negative("image_sigma", d.image_sigma)?;
                if d.layers == 0 {
                    return Err("layers must be at least 1".into());
                }
                if !(1..=MAX_IMAGE_REFINE).contains(&d.image_refine) {
                    return Err(format!(
                        "image_refine must be 1 … {MAX_IMAGE_REFINE}, got {}",
                        d.image_refine
                    ));
                }
            }
            AttachmentSpec::Varifold(v) => {
                if let Some(w) = v.width {
                    positive("varifold_width", w)?;
                }
                if let Kind::OrientedVarifold { normal_width } = v.kind {
                    positive("normal width", normal_width)?;
                }
            }
        }
        non_negative("weight", self.data_weight())?;
        let s = &self.schedule;
        positive("mu", s.mu)?;
        if !(s.mu_factor >= 1.0 && s.mu_factor.is_finite()) {
            return Err(format!("mu_factor must be ≥ 1, got {}", s.mu_factor));
        }
        if s.mu_max < s.mu {
            return Err(format!("mu_max ({}) is below mu ({})", s.mu_max, s.mu));
        }
        if s.iterations == 0 || self.lbfgs.memory == 0 {
            return Err("al_iterations and lbfgs_memory must be at least 1".into());
        }
        positive("tolerance_deg", self.tolerance.angle_deg)?;
        positive("tolerance_pct", self.tolerance.mismatch_pct)?;
        non_negative("gradient_tolerance", self.lbfgs.gradient_tolerance)?;
        non_negative("relative_decrease", self.lbfgs.relative_decrease)?;
        if let Some(settle) = s.settle {
            non_negative("settle_constraint", settle.max_abs_constraint)?;
            non_negative("settle_data_change", settle.data_change)?;
        }
        if let Some(e) = s.extend {
            positive("extend_beyond", e.above)?;
        }
        if let Some(p) = self.lbfgs.progress {
            non_negative("progress_decrease", p.decrease)?;
        }
        if let Some(c) = s.coarse {
            if c.time_steps == 0 || c.time_steps >= time_steps || time_steps % c.time_steps != 0 {
                return Err(format!(
                    "coarse_time_steps ({}) must divide flow.time_steps ({time_steps}) and be below it",
                    c.time_steps
                ));
            }
            if c.al_iterations == 0 || c.al_iterations >= s.iterations {
                return Err(format!(
                    "coarse_al_iterations ({}) must be at least 1 and below al_iterations ({}): the last AL iteration runs in flow.time_steps",
                    c.al_iterations, s.iterations
                ));
            }
        }
        Ok(())
    }
}

/// A whole fit: the flow and the stages, run in order.
#[derive(Clone, Debug, PartialEq)]
pub struct FitSpec {
    /// The flow all stages share.
    pub flow: FlowSettings,
    /// The stages, run in order, each from the momenta the one before ended at.
    pub stages: Vec<StageSpec>,
}

impl FitSpec {
    /// Checks every value that types cannot (positive σ, distinct stage names, a coarse
    /// schedule that divides the flow's steps, …); the message names the setting as a config
    /// names it (`flow.sigma`, `stage 'dice': mu …`).
    pub fn check(&self) -> Result<()> {
        self.check_text().map_err(Error::InvalidParameter)
    }

    /// [`FitSpec::check`]'s message.
    pub fn check_text(&self) -> std::result::Result<(), String> {
        self.flow.check()?;
        if self.stages.is_empty() {
            return Err("the config has no [[stage]]".into());
        }
        let mut names = std::collections::HashSet::new();
        for s in &self.stages {
            if !names.insert(&s.name) {
                return Err(format!("two stages are named '{}'", s.name));
            }
            s.check(self.flow.time_steps)
                .map_err(|e| format!("stage '{}': {e}", s.name))?;
        }
        Ok(())
    }

    /// The memory estimate of the fit's flow for `landmarks` landmarks
    /// ([`crate::memory::Estimate::flow`]).
    pub fn flow_estimate(&self, landmarks: usize) -> crate::memory::Estimate {
        let memory = self.stages.iter().map(|s| s.lbfgs.memory).max();
        crate::memory::Estimate::flow(
            self.flow.time_steps,
            landmarks,
            self.stages.len(),
            memory.unwrap_or(0),
        )
    }
}

/// The name of a varifold [`Kind`] in a config: `varifold`, `oriented` (normal width
/// [`DEFAULT_NORMAL_WIDTH`]) or `current`; `None` for an oriented varifold of another width.
pub fn kind_name(kind: Kind) -> Option<&'static str> {
    match kind {
        Kind::Varifold => Some("varifold"),
        Kind::OrientedVarifold { normal_width } if normal_width == DEFAULT_NORMAL_WIDTH => {
            Some("oriented")
        }
        Kind::OrientedVarifold { .. } => None,
        Kind::Current => Some("current"),
    }
}

/// The varifold [`Kind`] of a config name ([`kind_name`]).
pub fn kind_of_name(name: &str) -> Option<Kind> {
    match name {
        "varifold" => Some(Kind::Varifold),
        "oriented" => Some(Kind::OrientedVarifold {
            normal_width: DEFAULT_NORMAL_WIDTH,
        }),
        "current" => Some(Kind::Current),
        _ => None,
    }
}

fn positive(name: &str, v: f64) -> std::result::Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a positive number, got {v}"))
    }
}

fn non_negative(name: &str, v: f64) -> std::result::Result<(), String> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a non-negative number, got {v}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::augmented_lagrangian::CoarseTime;

    fn spec(stage: StageSpec) -> FitSpec {
        FitSpec {
            flow: FlowSettings::default(),
            stages: vec![stage],
        }
    }

    #[test]
    fn a_default_stage_is_valid_and_bad_values_are_named() {
        spec(StageSpec::new("a", AttachmentSpec::Ssd))
            .check()
            .unwrap();
        let mut s = StageSpec::new("a", AttachmentSpec::Ssd);
        s.schedule.mu = -1.0;
        assert!(spec(s).check_text().unwrap_err().contains("stage 'a': mu"));
        let dice = |d: DiceSpec| spec(StageSpec::new("d", AttachmentSpec::Dice(d))).check_text();
        dice(DiceSpec::default()).unwrap();
        for (bad, named) in [
            (
                DiceSpec {
                    image_refine: 0,
                    ..DiceSpec::default()
                },
                "image_refine must be 1",
            ),
            (
                DiceSpec {
                    image_refine: 9,
                    ..DiceSpec::default()
                },
                "image_refine must be 1",
            ),
            (
                DiceSpec {
                    layers: 0,
                    ..DiceSpec::default()
                },
                "layers",
            ),
        ] {
            assert!(dice(bad).unwrap_err().contains(named), "{bad:?}");
        }
    }

    #[test]
    fn coarse_time_steps_must_divide_the_flows_steps() {
        let check = |time_steps: usize, iterations: usize, al: usize| {
            let mut s = StageSpec::new("a", AttachmentSpec::Ssd);
            s.schedule.iterations = iterations;
            s.schedule.coarse = Some(CoarseTime {
                time_steps,
                al_iterations: al,
            });
            spec(s).check_text()
        };
        check(20, 2, 1).unwrap();
        check(8, 2, 1).unwrap();
        for steps in [0, 3, 40, 80] {
            assert!(check(steps, 2, 1)
                .unwrap_err()
                .contains("coarse_time_steps"));
        }
        for (iterations, al) in [(1, 1), (3, 3), (3, 0)] {
            assert!(check(20, iterations, al)
                .unwrap_err()
                .contains("coarse_al_iterations"));
        }
    }

    #[test]
    fn varifold_kinds_have_config_names() {
        for name in ["varifold", "oriented", "current"] {
            assert_eq!(kind_name(kind_of_name(name).unwrap()), Some(name));
        }
        assert_eq!(kind_of_name("curent"), None);
        assert_eq!(
            kind_name(Kind::OrientedVarifold { normal_width: 0.3 }),
            None
        );
    }
}
