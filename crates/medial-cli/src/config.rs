//! The TOML schedule of `medial fit`: model, flow and stages. Unknown keys are refused by name;
//! relative paths are relative to the config file.

use crate::error::CliError;
use medial_core::flow::kernel::MAX_TOLERANCE;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A whole config file.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// `[model]`.
    pub model: ModelConfig,
    /// `[flow]`.
    #[serde(default)]
    pub flow: FlowConfig,
    /// `[output]`.
    #[serde(default)]
    pub output: OutputConfig,
    /// `[[stage]]`, run in order.
    #[serde(rename = "stage")]
    pub stages: Vec<StageConfig>,
}

/// `[model]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// The template: a cmrep medial template, or a plain triangle mesh or point set (VTK).
    pub template: PathBuf,
}

/// `[flow]`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowConfig {
    /// Kernel width σ, in the unit of the coordinates (mm).
    pub sigma: f64,
    /// Number of time steps N.
    pub time_steps: usize,
    /// Weight of the kinetic energy.
    pub kinetic_weight: f64,
    /// Kernel tolerance ε: the sums skip landmark pairs whose kernel value is below it
    /// (0: exact; at most `medial_core::flow::kernel::MAX_TOLERANCE`).
    pub kernel_tolerance: f64,
}

impl Default for FlowConfig {
    fn default() -> Self {
        Self {
            sigma: 2.0,
            time_steps: 40,
            kinetic_weight: 0.05,
            kernel_tolerance: 0.0,
        }
    }
}

/// `[output]`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Write the model at every time point under `flow/` (else only the first and last).
    pub every_time_point: bool,
    /// Write VTK files in binary (smaller, faster) instead of ASCII.
    pub binary_vtk: bool,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            every_time_point: true,
            binary_vtk: false,
        }
    }
}

/// The data term of a stage.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum AttachmentKind {
    /// Sum of squared distances to corresponding points.
    Ssd,
    /// `1 − Dice` against a binary image.
    Dice,
    /// Varifold (or current) distance to a surface without correspondence.
    Varifold,
}

impl AttachmentKind {
    /// The name used in a config.
    pub fn name(self) -> &'static str {
        match self {
            AttachmentKind::Ssd => "ssd",
            AttachmentKind::Dice => "dice",
            AttachmentKind::Varifold => "varifold",
        }
    }
}

/// When μ grows between augmented-Lagrangian iterations.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum MuUpdateConfig {
    /// After every AL iteration.
    #[default]
    Always,
    /// Only when max |C| did not halve.
    IfNotHalved,
}

/// The unit of the medial constraints (see `medial_core::model::constraints::ConstraintUnits`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum ConstraintUnitsConfig {
    /// mm², as SPEC §3 and the reference implementation (the paper's μ values carry over).
    Absolute,
    /// Divided by the template's spoke and tangent lengths: dimensionless, every spoke weighs
    /// alike (the default; on cmrep's t001 μ needs about 20× its value in mm²).
    #[default]
    Relative,
}

/// The coordinates of a plain matrix file (see `medial_io::affine::Convention`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TransformConventionConfig {
    /// RAS+ (NIfTI, greedy).
    Ras,
    /// LPS+ (ITK, ANTs).
    Lps,
}

/// The kind of a varifold stage's surface distance (see
/// `medial_core::attachment::varifold::Kind`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum VarifoldKindConfig {
    /// Unoriented varifold: blind to the orientation of the triangles.
    #[default]
    Varifold,
    /// Oriented varifold (normal kernel width 1).
    Oriented,
    /// Current: oriented, linear in the normals.
    Current,
}

/// `[[stage]]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StageConfig {
    /// Name used in logs and outputs.
    pub name: String,
    /// `"ssd"`, `"dice"` or `"varifold"`.
    pub attachment: AttachmentKind,
    /// SSD: a mesh with the same points, in the same order, as the template boundary.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<PathBuf>,
    /// SSD: a 4×4 affine matrix (text, row by row, RAS mm, about the origin, template →
    /// subject) or an ITK transform file (LPS); the targets are the template's boundary points
    /// moved by it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transform: Option<PathBuf>,
    /// SSD with `transform`: the coordinates of a plain matrix file, `"ras"` (default; NIfTI,
    /// greedy) or `"lps"` (ITK, ANTs). ITK transform files are always read as LPS.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transform_convention: Option<TransformConventionConfig>,
    /// SSD with `transform`: the file maps subject → template (ITK's and greedy's fixed →
    /// moving, with the template registered as the moving image): invert it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transform_invert: Option<bool>,
    /// Dice: a binary (or labelled) image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image: Option<PathBuf>,
    /// Varifold: the target surface, any triangle mesh (.vtk, .obj, .gltf, .glb; any vertex
    /// count and order).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface: Option<PathBuf>,
    /// Varifold: `"varifold"` (unoriented), `"oriented"` or `"current"`.
    #[serde(default)]
    pub varifold_kind: VarifoldKindConfig,
    /// Varifold: the spatial kernel width σ_w, mm (default: from the target surface).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub varifold_width: Option<f64>,
    /// Dice: the foreground label (default: every voxel > 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<f64>,
    /// Weight of the data term (default 1 for SSD, 100 for Dice; for a varifold it multiplies
    /// g / ‖T‖², default 100).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
    /// Dice: Gaussian smoothing of the image, mm.
    #[serde(default = "defaults::image_sigma")]
    pub image_sigma: f64,
    /// Dice: split every voxel `image_refine³` times, the image interpolated trilinearly,
    /// before taking its foreground (1: off). For graded signed images (a level set whose
    /// foreground is `v > 0`): the boundary follows the zero crossing between voxel centres.
    #[serde(default = "defaults::image_refine")]
    pub image_refine: usize,
    /// Dice: midpoint subdivisions of the boundary.
    #[serde(default = "defaults::subdivision")]
    pub subdivision: usize,
    /// Dice: layers between boundary and medial sheet.
    #[serde(default = "defaults::layers")]
    pub layers: usize,
    /// Medial constraints (default: on for medial templates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraints: Option<bool>,
    /// Initial penalty weight μ.
    #[serde(default = "defaults::mu")]
    pub mu: f64,
    /// Growth of μ between AL iterations.
    #[serde(default = "defaults::mu_factor")]
    pub mu_factor: f64,
    /// Upper bound of μ.
    #[serde(default = "defaults::mu_max")]
    pub mu_max: f64,
    /// When μ grows.
    #[serde(default)]
    pub mu_update: MuUpdateConfig,
    /// Unit of the medial constraints in the penalty.
    #[serde(default)]
    pub constraint_units: ConstraintUnitsConfig,
    /// Augmented-Lagrangian iterations.
    #[serde(default = "defaults::al_iterations")]
    pub al_iterations: usize,
    /// L-BFGS iterations per AL iteration.
    #[serde(default = "defaults::max_iterations")]
    pub max_iterations: usize,
    /// L-BFGS iterations of the first AL iteration (default: `max_iterations`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_iterations: Option<usize>,
    /// End the AL iterations early, after one past the first whose end has every `|C|` at most
    /// this (the constraints' unit; in relative units about the angle in radians and the
    /// relative mismatch) and whose attachment changed by at most `settle_data_change` of it
    /// (default: off, every AL iteration runs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub settle_constraint: Option<f64>,
    /// Coarse to fine in time: the first `coarse_al_iterations` AL iterations run the flow in
    /// this many time steps, a divisor of `flow.time_steps` below it, while it strains space by
    /// at most 0.5 per step; the momenta are then carried to the flow's steps, each repeated
    /// (default: off, every AL iteration in `flow.time_steps`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse_time_steps: Option<usize>,
    /// AL iterations in `coarse_time_steps` steps (default: all but the last).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse_al_iterations: Option<usize>,
    /// The attachment's relative change over an AL iteration at most which it has settled.
    #[serde(default = "defaults::settle_data_change")]
    pub settle_data_change: f64,
    /// Stop when ‖∇E‖ falls below this fraction of its initial value.
    #[serde(default = "defaults::gradient_tolerance")]
    pub gradient_tolerance: f64,
    /// Stop when an iteration decreases E by less than this fraction.
    #[serde(default = "defaults::relative_decrease")]
    pub relative_decrease: f64,
    /// Stop an AL iteration's L-BFGS when the last `progress_window` iterations decreased E
    /// by less than `progress_decrease` of it, iterations (0: off; `max_iterations` still
    /// caps it).
    #[serde(default)]
    pub progress_window: usize,
    /// The least relative decrease of E over `progress_window` iterations that goes on.
    #[serde(default = "defaults::progress_decrease")]
    pub progress_decrease: f64,
    /// L-BFGS memory (correction pairs).
    #[serde(default = "defaults::lbfgs_memory")]
    pub lbfgs_memory: usize,
    /// Constrained stages: the largest spoke–normal angle at the end that counts as medial,
    /// degrees.
    #[serde(default = "defaults::tolerance_deg")]
    pub tolerance_deg: f64,
    /// Constrained stages: the largest spoke-length mismatch at the end that counts as
    /// medial, %.
    #[serde(default = "defaults::tolerance_pct")]
    pub tolerance_pct: f64,
}

/// Largest `image_refine`: each voxel becomes `image_refine³`.
const MAX_IMAGE_REFINE: usize = 8;

mod defaults {
    pub fn image_sigma() -> f64 {
        0.2
    }
    pub fn image_refine() -> usize {
        1
    }
    pub fn subdivision() -> usize {
        2
    }
    pub fn layers() -> usize {
        5
    }
    pub fn mu() -> f64 {
        1.0
    }
    pub fn mu_factor() -> f64 {
        10.0
    }
    pub fn mu_max() -> f64 {
        1e6
    }
    pub fn al_iterations() -> usize {
        1
    }
    pub fn max_iterations() -> usize {
        1000
    }
    pub fn gradient_tolerance() -> f64 {
        1e-6
    }
    pub fn relative_decrease() -> f64 {
        1e-9
    }
    pub fn progress_decrease() -> f64 {
        0.01
    }
    pub fn settle_data_change() -> f64 {
        1e-3
    }
    pub fn lbfgs_memory() -> usize {
        10
    }
    pub fn tolerance_deg() -> f64 {
        1.0
    }
    pub fn tolerance_pct() -> f64 {
        1.0
    }
}

impl StageConfig {
    /// A stage named `name` with `attachment` and every other setting at its default (no
    /// target, transform or image yet).
    pub fn new(name: &str, attachment: AttachmentKind) -> Self {
        Self {
            name: name.into(),
            attachment,
            target: None,
            transform: None,
            transform_convention: None,
            transform_invert: None,
            image: None,
            surface: None,
            varifold_kind: VarifoldKindConfig::default(),
            varifold_width: None,
            label: None,
            weight: None,
            image_sigma: defaults::image_sigma(),
            image_refine: defaults::image_refine(),
            subdivision: defaults::subdivision(),
            layers: defaults::layers(),
            constraints: None,
            mu: defaults::mu(),
            mu_factor: defaults::mu_factor(),
            mu_max: defaults::mu_max(),
            mu_update: MuUpdateConfig::default(),
            constraint_units: ConstraintUnitsConfig::default(),
            al_iterations: defaults::al_iterations(),
            max_iterations: defaults::max_iterations(),
            first_iterations: None,
            settle_constraint: None,
            coarse_time_steps: None,
            coarse_al_iterations: None,
            settle_data_change: defaults::settle_data_change(),
            gradient_tolerance: defaults::gradient_tolerance(),
            relative_decrease: defaults::relative_decrease(),
            progress_window: 0,
            progress_decrease: defaults::progress_decrease(),
            lbfgs_memory: defaults::lbfgs_memory(),
            tolerance_deg: defaults::tolerance_deg(),
            tolerance_pct: defaults::tolerance_pct(),
        }
    }

    /// The AL iterations in coarse time steps, when the stage has them: `coarse_al_iterations`,
    /// by default all but the last.
    pub fn coarse_al_iterations(&self) -> Option<usize> {
        self.coarse_time_steps?;
        Some(
            self.coarse_al_iterations
                .unwrap_or(self.al_iterations.saturating_sub(1)),
        )
    }

    /// The data weight, with the default of the attachment.
    pub fn data_weight(&self) -> f64 {
        self.weight.unwrap_or(match self.attachment {
            AttachmentKind::Ssd => 1.0,
            AttachmentKind::Dice | AttachmentKind::Varifold => 100.0,
        })
    }
}

impl Config {
    /// Reads, parses, resolves paths against the file's folder and checks the config.
    pub fn load(path: &Path) -> Result<Self, CliError> {
        let text = std::fs::read_to_string(path).map_err(|e| CliError::io(path, e))?;
        let mut config = Self::parse(&text, path)?;
        // Absolute, so that the resolved config a fit writes names the same files anywhere.
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
        let base = std::path::absolute(folder.unwrap_or(Path::new(".")))
            .map_err(|e| CliError::io(path, e))?;
        config.resolve(&base);
        config.check().map_err(|message| CliError::Config {
            path: path.into(),
            message,
        })?;
        Ok(config)
    }

    /// Parses the TOML `text` of the file `path` (named in errors), without resolving paths or
    /// checking values: what [`Config::load`] does first.
    pub fn parse(text: &str, path: &Path) -> Result<Self, CliError> {
        toml::from_str(text).map_err(|e| CliError::Config {
            path: path.into(),
            message: toml_error(text, &e),
        })
    }

    fn resolve(&mut self, base: &Path) {
        let join = |p: &mut PathBuf| *p = base.join(&*p);
        join(&mut self.model.template);
        for s in &mut self.stages {
            [
                &mut s.target,
                &mut s.transform,
                &mut s.image,
                &mut s.surface,
            ]
            .into_iter()
            .flatten()
            .for_each(join);
        }
    }

    /// Checks the values that TOML types cannot (positive σ, known stage names, …): the
    /// message names the key.
    pub fn check(&self) -> Result<(), String> {
        let f = &self.flow;
        positive("flow.sigma", f.sigma)?;
        non_negative("flow.kinetic_weight", f.kinetic_weight)?;
        if !(0.0..=MAX_TOLERANCE).contains(&f.kernel_tolerance) {
            return Err(format!(
                "flow.kernel_tolerance must be in [0, {MAX_TOLERANCE}], got {}",
                f.kernel_tolerance
            ));
        }
        if f.time_steps == 0 {
            return Err("flow.time_steps must be at least 1".into());
        }
        if self.stages.is_empty() {
            return Err("the config has no [[stage]]".into());
        }
        let mut names = std::collections::HashSet::new();
        for s in &self.stages {
            if !names.insert(&s.name) {
                return Err(format!("two stages are named '{}'", s.name));
            }
            s.check().map_err(|e| format!("stage '{}': {e}", s.name))?;
            if let Some(c) = s.coarse_time_steps {
                if c == 0 || c >= f.time_steps || f.time_steps % c != 0 {
                    return Err(format!(
                        "stage '{}': coarse_time_steps ({c}) must divide flow.time_steps ({}) and be below it",
                        s.name, f.time_steps
                    ));
                }
            }
            if let Some(a) = s.coarse_al_iterations() {
                if a == 0 || a >= s.al_iterations {
                    return Err(format!(
                        "stage '{}': coarse_al_iterations ({a}) must be at least 1 and below al_iterations ({}): the last AL iteration runs in flow.time_steps",
                        s.name, s.al_iterations
                    ));
                }
            }
        }
        Ok(())
    }

    /// The config as TOML text after the comment lines `header`, every setting written out (paths
    /// as they are held: relative paths stay relative to the file's folder).
    pub fn to_toml(&self, header: &str) -> Result<String, CliError> {
        let body = toml::to_string(self).map_err(|e| CliError::Input(format!("config: {e}")))?;
        Ok(format!("{header}\n{body}"))
    }

    /// The stage called `name`.
    pub fn stage(&self, name: &str) -> Option<&StageConfig> {
        self.stages.iter().find(|s| s.name == name)
    }
}

impl StageConfig {
    fn check(&self) -> Result<(), String> {
        use AttachmentKind::{Dice, Ssd, Varifold};
        let keys = [
            ("target", self.target.is_some(), Ssd),
            ("transform", self.transform.is_some(), Ssd),
            ("image", self.image.is_some(), Dice),
            ("label", self.label.is_some(), Dice),
            ("surface", self.surface.is_some(), Varifold),
            ("varifold_width", self.varifold_width.is_some(), Varifold),
        ];
        if let Some((key, _, _)) = keys
            .iter()
            .find(|(_, given, owner)| *given && *owner != self.attachment)
        {
            return Err(format!(
                "{key} does not apply to attachment = \"{}\"",
                self.attachment.name()
            ));
        }
        let transform_keys = [
            ("transform_convention", self.transform_convention.is_some()),
            ("transform_invert", self.transform_invert.is_some()),
        ];
        if let Some((key, _)) = transform_keys
            .iter()
            .find(|(_, given)| *given && self.transform.is_none())
        {
            return Err(format!("{key} needs transform"));
        }
        match self.attachment {
            AttachmentKind::Ssd => match (&self.target, &self.transform) {
                (Some(_), Some(_)) => {
                    return Err("give either target or transform, not both".into())
                }
                (None, None) => {
                    return Err(
                        "an ssd stage needs target (a mesh) or transform (a 4×4 matrix file)"
                            .into(),
                    )
                }
                _ => {}
            },
            AttachmentKind::Dice => {
                if self.image.is_none() {
                    return Err("a dice stage needs image".into());
                }
                non_negative("image_sigma", self.image_sigma)?;
                if self.layers == 0 {
                    return Err("layers must be at least 1".into());
                }
                if !(1..=MAX_IMAGE_REFINE).contains(&self.image_refine) {
                    return Err(format!(
                        "image_refine must be 1 … {MAX_IMAGE_REFINE}, got {}",
                        self.image_refine
                    ));
                }
                if self.image_refine > 1 && self.label.is_some() {
                    return Err(
                        "image_refine interpolates intensities: it does not apply to a label"
                            .into(),
                    );
                }
            }
            AttachmentKind::Varifold => {
                if self.surface.is_none() {
                    return Err("a varifold stage needs surface (a triangle mesh)".into());
                }
                if let Some(w) = self.varifold_width {
                    positive("varifold_width", w)?;
                }
            }
        }
        non_negative("weight", self.data_weight())?;
        positive("mu", self.mu)?;
        if !(self.mu_factor >= 1.0 && self.mu_factor.is_finite()) {
            return Err(format!("mu_factor must be ≥ 1, got {}", self.mu_factor));
        }
        if self.mu_max < self.mu {
            return Err(format!(
                "mu_max ({}) is below mu ({})",
                self.mu_max, self.mu
            ));
        }
        if self.al_iterations == 0 || self.lbfgs_memory == 0 {
            return Err("al_iterations and lbfgs_memory must be at least 1".into());
        }
        positive("tolerance_deg", self.tolerance_deg)?;
        positive("tolerance_pct", self.tolerance_pct)?;
        non_negative("gradient_tolerance", self.gradient_tolerance)?;
        non_negative("relative_decrease", self.relative_decrease)?;
        if let Some(c) = self.settle_constraint {
            non_negative("settle_constraint", c)?;
        }
        non_negative("settle_data_change", self.settle_data_change)?;
        non_negative("progress_decrease", self.progress_decrease)
    }
}

/// A TOML error on one line: `line L, column C: message` (the `Display` of `toml` quotes the
/// line with a caret under it, over several lines).
fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let message = e.message().trim().replace('\n', "; ");
    match e.span() {
        Some(span) => {
            // Spans are byte offsets; step back to a character boundary before slicing.
            let start = (0..=span.start.min(text.len()))
                .rev()
                .find(|&i| text.is_char_boundary(i))
                .unwrap_or(0);
            let before = &text[..start];
            let line = before.matches('\n').count() + 1;
            let column = before[before.rfind('\n').map_or(0, |n| n + 1)..]
                .chars()
                .count()
                + 1;
            format!("line {line}, column {column}: {message}")
        }
        None => message,
    }
}

fn positive(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a positive number, got {v}"))
    }
}

fn non_negative(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a non-negative number, got {v}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
[model]
template = "t.vtk"
[[stage]]
name = "ssd"
attachment = "ssd"
target = "s.vtk"
"#;

    #[test]
    fn minimal_config_gets_defaults() {
        let c: Config = toml::from_str(MINIMAL).unwrap();
        assert_eq!(c.flow.time_steps, 40);
        assert_eq!(c.stages[0].data_weight(), 1.0);
        assert_eq!(c.stages[0].max_iterations, 1000);
        c.check().unwrap();
    }

    #[test]
    fn unknown_keys_are_named() {
        let text = MINIMAL.replace("[model]", "[flow]\nsigam = 3.0\n[model]");
        let err = toml::from_str::<Config>(&text).unwrap_err().to_string();
        assert!(err.contains("sigam"), "{err}");
        let text = MINIMAL.replace("target =", "targte =");
        let err = toml::from_str::<Config>(&text).unwrap_err().to_string();
        assert!(err.contains("targte"), "{err}");
    }

    #[test]
    fn toml_errors_take_one_line() {
        let text = MINIMAL.replace("[model]", "[flow]\nsigam = 3.0\n[model]");
        let e = toml::from_str::<Config>(&text).unwrap_err();
        let m = toml_error(&text, &e);
        assert!(
            m.starts_with("line 3, column 1: unknown field `sigam`"),
            "{m}"
        );
        assert!(!m.contains('\n'), "{m}");
    }

    #[test]
    fn inconsistent_stages_are_refused() {
        let both = MINIMAL.replace(
            "target = \"s.vtk\"",
            "target = \"s.vtk\"\ntransform = \"m.txt\"",
        );
        assert!(toml::from_str::<Config>(&both).unwrap().check().is_err());
        let dice = MINIMAL.replace("\"ssd\"\ntarget = \"s.vtk\"", "\"dice\"");
        assert!(toml::from_str::<Config>(&dice)
            .unwrap()
            .check()
            .unwrap_err()
            .contains("image"));
        let bad_mu = MINIMAL.replace("target = \"s.vtk\"", "target = \"s.vtk\"\nmu = -1");
        assert!(toml::from_str::<Config>(&bad_mu)
            .unwrap()
            .check()
            .unwrap_err()
            .contains("mu"));
    }

    #[test]
    fn image_refinement_needs_a_dice_stage_without_a_label() {
        let dice = MINIMAL.replace("\"ssd\"\ntarget = \"s.vtk\"", "\"dice\"\nimage = \"i.nii\"");
        let check = |extra: &str| {
            let text = format!("{dice}{extra}\n");
            toml::from_str::<Config>(&text).unwrap().check()
        };
        check("image_refine = 3").unwrap();
        for (extra, named) in [
            ("image_refine = 0", "image_refine must be 1"),
            ("image_refine = 9", "image_refine must be 1"),
            ("image_refine = 3\nlabel = 2", "does not apply to a label"),
            ("progress_decrease = -1", "progress_decrease"),
            ("settle_constraint = -0.1", "settle_constraint"),
            ("settle_constraint = nan", "settle_constraint"),
            ("settle_data_change = -1", "settle_data_change"),
        ] {
            let e = check(extra).unwrap_err();
            assert!(e.contains(named), "{extra}: {e}");
        }
    }

    #[test]
    fn coarse_time_steps_must_divide_the_flows_steps() {
        // MINIMAL's flow has the default 40 steps.
        let check = |steps: usize| {
            let text = format!("{MINIMAL}al_iterations = 2\ncoarse_time_steps = {steps}\n");
            toml::from_str::<Config>(&text).unwrap().check()
        };
        check(20).unwrap();
        check(8).unwrap();
        for steps in [0, 3, 40, 80] {
            let e = check(steps).unwrap_err();
            assert!(e.contains("coarse_time_steps"), "{steps}: {e}");
        }
        // MINIMAL's stage has one AL iteration: none of them can be coarse.
        let with = |extra: &str| {
            let text = format!("{MINIMAL}coarse_time_steps = 20\n{extra}\n");
            toml::from_str::<Config>(&text).unwrap().check()
        };
        for extra in ["", "al_iterations = 3\ncoarse_al_iterations = 3"] {
            assert!(
                with(extra).unwrap_err().contains("coarse_al_iterations"),
                "{extra}"
            );
        }
        with("al_iterations = 3").unwrap();
        with("al_iterations = 3\ncoarse_al_iterations = 1").unwrap();
    }
}
