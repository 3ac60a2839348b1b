//! The TOML config of `medial fit`: a serde view of the engine's [`FitSpec`] (model, flow and
//! stages) with the files each stage fits to. Unknown keys are refused by name; relative paths
//! are relative to the config file. [`StageConfig::spec`] and [`StageConfig::of_spec`] are the
//! one conversion between the flat `[[stage]]` table and the typed [`StageSpec`].

use crate::error::CliError;
use medial_core::attachment::varifold::Kind;
use medial_core::fit::augmented_lagrangian::{CoarseTime, Extend, MuUpdate, Settle};
use medial_core::fit::optimize::{LbfgsOptions, ProgressRule};
use medial_core::fit::spec::{kind_name, kind_of_name};
use medial_core::fit::{
    AttachmentSpec, DiceSpec, FitSpec, FlowSettings, MedialTolerance, StageSpec, VarifoldSpec,
};
use medial_core::model::constraints::ConstraintUnits;
use medial_io::affine::Convention;
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
    pub flow: FlowSettings,
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
    pub transform_convention: Option<Convention>,
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
    #[serde(default, with = "varifold_kind")]
    pub varifold_kind: Kind,
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
    pub mu_update: MuUpdate,
    /// Unit of the medial constraints in the penalty (default: relative).
    #[serde(default = "defaults::constraint_units")]
    pub constraint_units: ConstraintUnits,
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
    /// Go on past `al_iterations`, up to this many more AL iterations, while the largest
    /// spoke–normal angle or spoke mismatch is beyond `extend_beyond` of its tolerance and the
    /// rate at which the last AL iteration lowered it, kept up over the AL iterations left,
    /// would bring it within the tolerance (default: off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extend_al_iterations: Option<usize>,
    /// With `extend_al_iterations`: the fraction of `tolerance_deg` / `tolerance_pct` beyond
    /// which the AL iterations go on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extend_beyond: Option<f64>,
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

/// The defaults of the keys: those of [`StageSpec::new`] and [`DiceSpec::default`]; the
/// progress and settle rules' values where the rule is off.
mod defaults {
    use super::*;

    fn stage() -> StageSpec {
        StageSpec::new("", AttachmentSpec::Ssd)
    }
    pub fn constraint_units() -> ConstraintUnits {
        stage().constraint_units
    }
    pub fn image_sigma() -> f64 {
        DiceSpec::default().image_sigma
    }
    pub fn image_refine() -> usize {
        DiceSpec::default().image_refine
    }
    pub fn subdivision() -> usize {
        DiceSpec::default().subdivision
    }
    pub fn layers() -> usize {
        DiceSpec::default().layers
    }
    pub fn mu() -> f64 {
        stage().schedule.mu
    }
    pub fn mu_factor() -> f64 {
        stage().schedule.mu_factor
    }
    pub fn mu_max() -> f64 {
        stage().schedule.mu_max
    }
    pub fn al_iterations() -> usize {
        stage().schedule.iterations
    }
    pub fn max_iterations() -> usize {
        stage().lbfgs.max_iterations
    }
    pub fn gradient_tolerance() -> f64 {
        stage().lbfgs.gradient_tolerance
    }
    pub fn relative_decrease() -> f64 {
        stage().lbfgs.relative_decrease
    }
    pub fn progress_decrease() -> f64 {
        0.01
    }
    pub fn settle_data_change() -> f64 {
        1e-3
    }
    pub fn lbfgs_memory() -> usize {
        stage().lbfgs.memory
    }
    pub fn tolerance_deg() -> f64 {
        stage().tolerance.angle_deg
    }
    pub fn tolerance_pct() -> f64 {
        stage().tolerance.mismatch_pct
    }
}

/// `varifold_kind` as its config name ([`kind_name`]).
mod varifold_kind {
    use super::*;

    pub fn serialize<S: serde::Serializer>(kind: &Kind, s: S) -> Result<S::Ok, S::Error> {
        let name = kind_name(*kind).ok_or_else(|| {
            serde::ser::Error::custom("an oriented varifold of another normal width has no name")
        })?;
        s.serialize_str(name)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Kind, D::Error> {
        let name = String::deserialize(d)?;
        kind_of_name(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown varifold_kind `{name}`, expected one of `varifold`, `oriented`, `current`"
            ))
        })
    }
}

/// The data a stage fits to, as files: what [`StageConfig::of_spec`] writes beside the settings.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// SSD: points in correspondence with the template boundary's.
    Target(PathBuf),
    /// SSD: an affine map (RAS) that carries the template boundary to its targets.
    Transform(PathBuf),
    /// Dice: an image and its foreground label (none: every voxel > 0).
    Image(PathBuf, Option<f64>),
    /// Varifold: a surface.
    Surface(PathBuf),
}

impl StageConfig {
    /// The config view of `spec` fitting to `source`.
    pub fn of_spec(spec: &StageSpec, source: Source) -> Self {
        let (attachment, dice, varifold) = match &spec.attachment {
            AttachmentSpec::Ssd => (AttachmentKind::Ssd, DiceSpec::default(), None),
            AttachmentSpec::Dice(d) => (AttachmentKind::Dice, *d, None),
            AttachmentSpec::Varifold(v) => {
                (AttachmentKind::Varifold, DiceSpec::default(), Some(*v))
            }
        };
        let (mut target, mut transform, mut image, mut label, mut surface) =
            (None, None, None, None, None);
        match source {
            Source::Target(p) => target = Some(p),
            Source::Transform(p) => transform = Some(p),
            Source::Image(p, l) => (image, label) = (Some(p), l),
            Source::Surface(p) => surface = Some(p),
        }
        let s = &spec.schedule;
        let l = &spec.lbfgs;
        Self {
            name: spec.name.clone(),
            attachment,
            target,
            transform,
            transform_convention: None,
            transform_invert: None,
            image,
            surface,
            varifold_kind: varifold.map_or(Kind::default(), |v| v.kind),
            varifold_width: varifold.and_then(|v| v.width),
            label,
            weight: spec.weight,
            image_sigma: dice.image_sigma,
            image_refine: dice.image_refine,
            subdivision: dice.subdivision,
            layers: dice.layers,
            constraints: spec.constraints,
            mu: s.mu,
            mu_factor: s.mu_factor,
            mu_max: s.mu_max,
            mu_update: s.mu_update,
            constraint_units: spec.constraint_units,
            al_iterations: s.iterations,
            max_iterations: l.max_iterations,
            first_iterations: s.first_iterations,
            settle_constraint: s.settle.map(|t| t.max_abs_constraint),
            coarse_time_steps: s.coarse.map(|c| c.time_steps),
            coarse_al_iterations: s.coarse.map(|c| c.al_iterations),
            settle_data_change: s
                .settle
                .map_or_else(defaults::settle_data_change, |t| t.data_change),
            extend_al_iterations: s.extend.map(|e| e.at_most),
            extend_beyond: s.extend.map(|e| e.above),
            gradient_tolerance: l.gradient_tolerance,
            relative_decrease: l.relative_decrease,
            progress_window: l.progress.map_or(0, |p| p.window),
            progress_decrease: l
                .progress
                .map_or_else(defaults::progress_decrease, |p| p.decrease),
            lbfgs_memory: l.memory,
            tolerance_deg: spec.tolerance.angle_deg,
            tolerance_pct: spec.tolerance.mismatch_pct,
        }
    }

    /// The engine's description of this stage.
    pub fn spec(&self) -> StageSpec {
        let attachment = match self.attachment {
            AttachmentKind::Ssd => AttachmentSpec::Ssd,
            AttachmentKind::Dice => AttachmentSpec::Dice(DiceSpec {
                image_sigma: self.image_sigma,
                image_refine: self.image_refine,
                subdivision: self.subdivision,
                layers: self.layers,
            }),
            AttachmentKind::Varifold => AttachmentSpec::Varifold(VarifoldSpec {
                kind: self.varifold_kind,
                width: self.varifold_width,
            }),
        };
        StageSpec {
            name: self.name.clone(),
            attachment,
            weight: self.weight,
            constraints: self.constraints,
            constraint_units: self.constraint_units,
            schedule: medial_core::fit::AlSchedule {
                mu: self.mu,
                mu_factor: self.mu_factor,
                mu_max: self.mu_max,
                iterations: self.al_iterations,
                mu_update: self.mu_update,
                first_iterations: self.first_iterations,
                settle: self.settle_constraint.map(|max_abs_constraint| Settle {
                    max_abs_constraint,
                    data_change: self.settle_data_change,
                }),
                extend: self
                    .extend_al_iterations
                    .zip(self.extend_beyond)
                    .map(|(at_most, above)| Extend { above, at_most }),
                coarse: self.coarse_time_steps.map(|time_steps| CoarseTime {
                    time_steps,
                    al_iterations: self
                        .coarse_al_iterations
                        .unwrap_or(self.al_iterations.saturating_sub(1)),
                }),
            },
            lbfgs: LbfgsOptions {
                max_iterations: self.max_iterations,
                memory: self.lbfgs_memory,
                gradient_tolerance: self.gradient_tolerance,
                relative_decrease: self.relative_decrease,
                progress: (self.progress_window > 0).then_some(ProgressRule {
                    window: self.progress_window,
                    decrease: self.progress_decrease,
                }),
                ..LbfgsOptions::default()
            },
            tolerance: MedialTolerance {
                angle_deg: self.tolerance_deg,
                mismatch_pct: self.tolerance_pct,
            },
        }
    }

    /// The data source of the stage: its file and how to read it.
    pub fn source(&self) -> Result<Source, String> {
        let missing = |what: &str| format!("stage '{}': {what}", self.name);
        Ok(match self.attachment {
            AttachmentKind::Ssd => match (&self.target, &self.transform) {
                (Some(t), None) => Source::Target(t.clone()),
                (None, Some(t)) => Source::Transform(t.clone()),
                (Some(_), Some(_)) => {
                    return Err(missing("give either target or transform, not both"))
                }
                (None, None) => {
                    return Err(missing(
                        "an ssd stage needs target (a mesh) or transform (a 4×4 matrix file)",
                    ))
                }
            },
            AttachmentKind::Dice => Source::Image(
                self.image
                    .clone()
                    .ok_or_else(|| missing("a dice stage needs image"))?,
                self.label,
            ),
            AttachmentKind::Varifold => Source::Surface(
                self.surface
                    .clone()
                    .ok_or_else(|| missing("a varifold stage needs surface (a triangle mesh)"))?,
            ),
        })
    }

    /// Checks that every key given applies to the stage's attachment and that it has its data;
    /// the values are checked by [`FitSpec::check`].
    fn check_keys(&self) -> Result<(), String> {
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
                "stage '{}': {key} does not apply to attachment = \"{}\"",
                self.name,
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
            return Err(format!("stage '{}': {key} needs transform", self.name));
        }
        if self.image_refine > 1 && self.label.is_some() {
            return Err(format!(
                "stage '{}': image_refine interpolates intensities: it does not apply to a label",
                self.name
            ));
        }
        // Kept in the file even where their rule is off: checked here, not by the engine.
        for (key, value) in [
            ("progress_decrease", self.progress_decrease),
            ("settle_data_change", self.settle_data_change),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!(
                    "stage '{}': {key} must be a non-negative number, got {value}",
                    self.name
                ));
            }
        }
        if self.extend_al_iterations.is_some() != self.extend_beyond.is_some() {
            return Err(format!(
                "stage '{}': extend_al_iterations and extend_beyond go together",
                self.name
            ));
        }
        if let Some(a) = self.coarse_al_iterations {
            if self.coarse_time_steps.is_none() {
                return Err(format!(
                    "stage '{}': coarse_al_iterations ({a}) needs coarse_time_steps",
                    self.name
                ));
            }
        }
        self.source().map(|_| ())
    }
}

impl Config {
    /// The config of `spec` for `template`, each stage fitting to its source.
    pub fn of_spec(spec: &FitSpec, template: PathBuf, sources: Vec<Source>) -> Self {
        Self {
            model: ModelConfig { template },
            flow: spec.flow,
            output: OutputConfig::default(),
            stages: spec
                .stages
                .iter()
                .zip(sources)
                .map(|(stage, source)| StageConfig::of_spec(stage, source))
                .collect(),
        }
    }

    /// This config with the flow and stage settings of `spec` (same template, sources and
    /// output); `spec` has this config's stages, in order.
    pub fn with_spec(&self, spec: &FitSpec) -> Result<Self, CliError> {
        let sources = (self.stages.iter())
            .map(StageConfig::source)
            .collect::<Result<Vec<_>, _>>()
            .map_err(CliError::Input)?;
        Ok(Self {
            output: self.output,
            ..Self::of_spec(spec, self.model.template.clone(), sources)
        })
    }

    /// The engine's description of the fit.
    pub fn spec(&self) -> FitSpec {
        FitSpec {
            flow: self.flow,
            stages: self.stages.iter().map(StageConfig::spec).collect(),
        }
    }

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

    /// Checks the keys of each stage ([`StageConfig::check_keys`]) and the values
    /// ([`FitSpec::check`]): the message names the key.
    pub fn check(&self) -> Result<(), String> {
        for s in &self.stages {
            s.check_keys()?;
        }
        self.spec().check_text()
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
        assert_eq!(c.stages[0].spec().data_weight(), 1.0);
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
