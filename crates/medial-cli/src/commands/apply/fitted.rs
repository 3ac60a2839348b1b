//! The map of a finished fit, read from its folder: the flow of space of its momenta
//! ([`AmbientFlow`]) after its initial alignment and the projection that followed it, if it had
//! them.

use crate::config::Config;
use crate::error::CliError;
use crate::stage::flow_of;
use medial_core::flow::ambient::AmbientFlow;
use medial_core::Vec3;
use nalgebra::Matrix4;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The largest distance (mm) between the end of the re-computed flow of the template and the
/// fit's `fitted_template.vtk` for which the template is taken as the one the fit ran from.
const SAME_FIT_MM: f64 = 1e-6;

/// An affine map and its inverse.
type AffinePair = (Matrix4<f64>, Matrix4<f64>);

/// The given template that an automatic fit writes beside its aligned template.
const GIVEN_TEMPLATE: &str = "template.vtk";

/// Meshes and point sets of more points than this are carried with the truncated kernel in
/// blocks of nearby points ([`AmbientFlow::map_truncated`]) within [`POINTS_TOLERANCE_MM`].
pub const EXACT_POINTS: usize = 20_000;

/// The largest error (mm) of the truncated map of a large point set.
pub const POINTS_TOLERANCE_MM: f64 = 1e-9;

/// Which space the template side of the map is in.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TemplateSpace {
    /// The template the fit was given (`--template`, or the config's template).
    #[default]
    Given,
    /// The template an automatic fit started its flow from, `DIR/aligned_template.vtk`
    /// (after the initial alignment and the projection); the same as `given` for a fit with
    /// a config.
    Aligned,
}

/// What `apply` reads of `summary.json`.
#[derive(Deserialize)]
struct Listed {
    status: String,
    #[serde(default)]
    files: Vec<String>,
}

/// The map of a fit: template space → subject space, `F = φ₁ ∘ P ∘ A`, with `A` the initial
/// alignment of an automatic fit (`alignment.txt`, the template the fit started from being
/// `aligned_template.vtk`) or the identity, and `P` the projection after an affine `A`: the
/// landmarks' moves from `A(given)` to `aligned_template.vtk`, extended to all of space by the
/// kernel interpolation at the flow's σ ([`AmbientFlow::after_move`]), exact at the landmarks;
/// `P` is part of `flow`.
pub struct FittedMap {
    /// `A` and `A⁻¹`.
    alignment: Option<AffinePair>,
    flow: AmbientFlow,
}

impl FittedMap {
    /// Reads the fit in `dir`: `summary.json` (a complete set of results), `config.toml` (the
    /// flow and the template), `momenta.npy`, and `alignment.txt` when the fit started from its
    /// `aligned_template.vtk`. The flow of the template is checked against the fit's
    /// `fitted_template.vtk`, so that a template changed since the fit is refused.
    ///
    /// `space` says where the template side is: the given template's space (the map includes
    /// `A` and `P`) or the aligned template's (`φ₁` alone).
    pub fn open(dir: &Path, space: TemplateSpace) -> Result<Self, CliError> {
        let listed = complete_set(dir)?;
        if !matches!(listed.status.as_str(), "converged" | "budget") {
            tracing::warn!(
                "the fit in {} ended with status \"{}\" (see its summary.json): its map is carried \
                 as it is",
                dir.display(),
                listed.status
            );
        }
        let config = Config::load(&dir.join("config.toml"))?;
        let model = medial_io::model::read_model(&config.model.template)?;
        let k = model.landmarks().len();
        let flow = flow_of(&config, k)?;
        let momenta = read_momenta(&dir.join("momenta.npy"), flow.time_steps(), k)?;
        let trajectory = flow.shoot(model.landmarks(), &momenta)?;
        check_same_fit(dir, &config.model.template, trajectory.final_positions())?;
        let ambient = AmbientFlow::new(&flow, &trajectory, &momenta)?;
        let alignment = match space {
            TemplateSpace::Aligned => None,
            TemplateSpace::Given => alignment(dir, &config.model.template)?,
        };
        let Some((a, a_inverse)) = alignment else {
            return Ok(Self {
                alignment: None,
                flow: ambient,
            });
        };
        let given = dir.join(GIVEN_TEMPLATE);
        let flow = if given.is_file() {
            let given_model = medial_io::model::read_model(&given)?;
            if given_model.landmarks().len() != k {
                return Err(CliError::Input(format!(
                    "{} has {} landmarks, the fit's template {k}",
                    given.display(),
                    given_model.landmarks().len()
                )));
            }
            let from = medial_core::mesh::carry_points(given_model.landmarks(), &a);
            ambient
                .after_move(&from, model.landmarks())
                .map_err(|e| CliError::Input(format!("{}: {e}", given.display())))?
        } else {
            tracing::warn!(
                "{} has no {GIVEN_TEMPLATE} (a fit by an earlier release): the map includes the \
                 initial alignment but not the projection that may have followed it",
                dir.display()
            );
            ambient
        };
        Ok(Self {
            alignment: Some((a, a_inverse)),
            flow,
        })
    }

    /// The flow of space after the alignment (the projection's move included).
    pub fn flow(&self) -> &AmbientFlow {
        &self.flow
    }

    /// `A`, if the map has an initial alignment.
    pub fn alignment(&self) -> Option<&Matrix4<f64>> {
        self.alignment.as_ref().map(|(a, _)| a)
    }

    /// `A⁻¹`, if the map has an initial alignment.
    pub fn alignment_inverse(&self) -> Option<&Matrix4<f64>> {
        self.alignment.as_ref().map(|(_, a)| a)
    }

    /// `F(x)` (without `inverse`) or `F⁻¹(y)` of every point.
    pub fn carry(&self, points: &[Vec3], inverse: bool) -> Result<Vec<Vec3>, CliError> {
        let by = |m: &Matrix4<f64>, p: &[Vec3]| -> Vec<Vec3> {
            p.iter()
                .map(|x| m.transform_point(&(*x).into()).coords)
                .collect()
        };
        let flow = |p: &[Vec3], inverse: bool| -> Result<Vec<Vec3>, CliError> {
            Ok(match (p.len() > EXACT_POINTS, inverse) {
                (false, false) => self.flow.forward(p)?,
                (false, true) => self.flow.inverse(p)?,
                (true, _) => {
                    let epsilon = self.flow.truncation_for(POINTS_TOLERANCE_MM);
                    self.flow.map_truncated(p, inverse, epsilon, 256)?
                }
            })
        };
        Ok(match (&self.alignment, inverse) {
            (None, _) => flow(points, inverse)?,
            (Some((a, _)), false) => flow(&by(a, points), false)?,
            (Some((_, a_inv)), true) => by(a_inv, &flow(points, true)?),
        })
    }
}

/// The `summary.json` of a complete set of results in `dir` that lists `config.toml` and
/// `momenta.npy`.
fn complete_set(dir: &Path) -> Result<Listed, CliError> {
    let not_complete = |why: String| {
        CliError::Input(format!(
            "{} is not a complete fit folder: {why}",
            dir.display()
        ))
    };
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).map_err(|e| {
        not_complete(format!(
            "{} cannot be read ({e}); a fit writes it last, once its results are in place",
            path.display()
        ))
    })?;
    let listed: Listed = serde_json::from_str(&text)
        .map_err(|e| not_complete(format!("{} is malformed: {e}", path.display())))?;
    for file in ["config.toml", "momenta.npy", "fitted_template.vtk"] {
        if !listed.files.iter().any(|f| f == file) || !dir.join(file).is_file() {
            return Err(not_complete(format!("{file} is not among its results")));
        }
    }
    // The files that make the map are checked; the flow's time points and the views are not
    // read here (a fit folder copied without them still carries images).
    let unread = |r: &str| r.starts_with("flow/") || crate::report::is_view(r);
    crate::results::verify(dir, "summary.json", unread)?;
    Ok(listed)
}

/// The momenta of `momenta.npy`, checked to be `[N, k, 3]` for the fit's flow.
fn read_momenta(path: &Path, steps: usize, k: usize) -> Result<Vec<f64>, CliError> {
    let array = medial_io::npy::read_npy(path)?;
    if array.shape != [steps, k, 3] {
        return Err(CliError::Input(format!(
            "{}: shape {:?}, but the fit's config and template need [{steps}, {k}, 3] (time \
             steps, landmarks, 3)",
            path.display(),
            array.shape
        )));
    }
    Ok(array.data)
}

/// Refuses a template (or momenta) whose flow does not end at the fit's `fitted_template.vtk`.
fn check_same_fit(dir: &Path, template: &Path, end: &[Vec3]) -> Result<(), CliError> {
    let fitted = dir.join("fitted_template.vtk");
    let points = medial_io::mesh::read_points(&fitted)?;
    let off = (points.len() <= end.len())
        .then(|| {
            points
                .iter()
                .zip(end)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max)
        })
        .filter(|&d| d <= SAME_FIT_MM);
    match off {
        Some(_) => Ok(()),
        None => Err(CliError::Input(format!(
            "the flow of {} by {} does not end at {}: the template or the momenta have changed \
             since the fit",
            template.display(),
            dir.join("momenta.npy").display(),
            fitted.display()
        ))),
    }
}

/// `A` and `A⁻¹` of `dir/alignment.txt` when the fit's template is `dir/aligned_template.vtk`.
fn alignment(dir: &Path, template: &Path) -> Result<Option<AffinePair>, CliError> {
    let aligned =
        std::path::absolute(dir.join("aligned_template.vtk")).map_err(|e| CliError::io(dir, e))?;
    let path: PathBuf = dir.join("alignment.txt");
    if !(same_file(&aligned, template) && path.is_file()) {
        return Ok(None);
    }
    let a = medial_io::affine::read_affine(&path)?.to_homogeneous();
    let inverse = a
        .try_inverse()
        .ok_or_else(|| CliError::Input(format!("{}: the alignment is singular", path.display())))?;
    Ok(Some((a, inverse)))
}

/// Whether two paths name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
