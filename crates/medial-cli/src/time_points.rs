//! The medial figures of docs/method.md §4.4 at every time point of the fitted flow: `time_points.csv`
//! (one row per time point, for a spreadsheet or `numpy.genfromtxt`) and their worst values
//! over the flow for `summary.json`; among them the inscribed-ball fidelity
//! ([`medial_core::model::fidelity`]), as `medial check` prints it too. Medial templates only:
//! a plain mesh has no spokes.

use crate::error::CliError;
use medial_core::flow::Trajectory;
use medial_core::model::fidelity::{Fidelity, FidelitySummary, GroupFidelity};
use medial_core::model::{BallFidelity, MedialConstraints, Model};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The figures of one time point.
#[derive(Clone, Debug)]
pub struct TimePoint {
    /// `n = 0 … N`.
    pub index: usize,
    /// `t = n / N`.
    pub t: f64,
    /// Largest spoke–normal angle, degrees.
    pub max_spoke_normal_deg: f64,
    /// Mean spoke–normal angle, degrees.
    pub mean_spoke_normal_deg: f64,
    /// Largest spoke-length mismatch, %.
    pub max_spoke_mismatch_pct: f64,
    /// `max_l |C_l(q^n)|` in docs/method.md §4.3's units (mm²), whatever the stages' `constraint_units`.
    pub max_abs_constraint_mm2: f64,
    /// Smallest and largest local thickness (2 × mean spoke length of an atom), mm.
    pub thickness_range_mm: [f64; 2],
    /// The inscribed-ball fidelity of every atom, with its summary over sheet and free-edge
    /// atoms (`fidelity.summary`).
    pub fidelity: Fidelity,
}

/// The inscribed-ball fidelity of a group of atoms, for JSON: at one time point, or the worst of
/// each figure over time points.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct GroupFigures {
    /// Atoms in the group.
    pub atoms: usize,
    /// Mean residual `|d − r| / r`, %.
    pub mean_residual_pct: f64,
    /// Largest residual, %.
    pub max_residual_pct: f64,
    /// Atoms whose ball pokes out of the boundary.
    pub poking_out: usize,
}

/// The inscribed-ball fidelity of sheet atoms (two or three spokes) and free-edge atoms (one).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct BallFigures {
    /// Sheet and seam atoms.
    pub sheet: GroupFigures,
    /// Free-edge atoms.
    pub edge: GroupFigures,
}

impl GroupFigures {
    fn of(g: &GroupFidelity) -> Self {
        Self {
            atoms: g.atoms,
            mean_residual_pct: 100.0 * g.mean_residual,
            max_residual_pct: 100.0 * g.max_residual,
            poking_out: g.poking_out,
        }
    }

    /// The worse of each figure (NaN wins, as a figure that cannot be trusted).
    fn worse(self, other: Self) -> Self {
        let max = |a: f64, b: f64| {
            if a.is_nan() || b.is_nan() {
                f64::NAN
            } else {
                a.max(b)
            }
        };
        Self {
            atoms: self.atoms,
            mean_residual_pct: max(self.mean_residual_pct, other.mean_residual_pct),
            max_residual_pct: max(self.max_residual_pct, other.max_residual_pct),
            poking_out: self.poking_out.max(other.poking_out),
        }
    }
}

impl BallFigures {
    /// The figures of one configuration.
    pub fn of(f: &FidelitySummary) -> Self {
        Self {
            sheet: GroupFigures::of(&f.sheet),
            edge: GroupFigures::of(&f.edge),
        }
    }

    /// The worse of each figure of the two.
    pub fn worse(self, other: Self) -> Self {
        Self {
            sheet: self.sheet.worse(other.sheet),
            edge: self.edge.worse(other.edge),
        }
    }
}

/// The worst figures over time points `1 … N` (time point 0, the template, is not optimised).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct OverTime {
    /// Largest spoke–normal angle at any time point, degrees.
    pub max_spoke_normal_deg: f64,
    /// Largest spoke-length mismatch at any time point, %.
    pub max_spoke_mismatch_pct: f64,
    /// Largest `|C|` at any time point, mm² (docs/method.md §4.3's units).
    pub max_abs_constraint_mm2: f64,
    /// Smallest local thickness at any time point, mm.
    pub min_thickness_mm: f64,
    /// The worst inscribed-ball figures at any time point.
    pub ball_fidelity: BallFigures,
}

/// The figures at every time point of `trajectory`; empty for a plain mesh.
pub fn time_points(model: &Model, trajectory: &Trajectory) -> Vec<TimePoint> {
    let Some(template) = model.medial() else {
        return Vec::new();
    };
    let constraints = MedialConstraints::new(template);
    let fidelity = BallFidelity::new(template);
    let last = trajectory.time_points() - 1;
    (0..=last)
        .into_par_iter()
        .map(|n| {
            let q = trajectory.positions(n);
            let m = model
                .metrics(q)
                .expect("a medial template has spoke metrics");
            let mut values = vec![0.0; constraints.len()];
            constraints.evaluate(q, &mut values);
            TimePoint {
                index: n,
                t: n as f64 / last.max(1) as f64,
                max_spoke_normal_deg: m.max_spoke_normal_deg,
                mean_spoke_normal_deg: m.mean_spoke_normal_deg,
                max_spoke_mismatch_pct: 100.0 * m.max_spoke_mismatch,
                max_abs_constraint_mm2: values.iter().fold(0.0, |a: f64, c| a.max(c.abs())),
                thickness_range_mm: m
                    .thickness
                    .iter()
                    .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], &x| {
                        [lo.min(x), hi.max(x)]
                    }),
                fidelity: fidelity.measure(q),
            }
        })
        .collect()
}

/// The worst figures over time points `1 … N`; `None` without time points after the first.
pub fn over_time(points: &[TimePoint]) -> Option<OverTime> {
    let flow = points.get(1..).filter(|p| !p.is_empty())?;
    let max = |f: fn(&TimePoint) -> f64| flow.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    Some(OverTime {
        max_spoke_normal_deg: max(|p| p.max_spoke_normal_deg),
        max_spoke_mismatch_pct: max(|p| p.max_spoke_mismatch_pct),
        max_abs_constraint_mm2: max(|p| p.max_abs_constraint_mm2),
        min_thickness_mm: -max(|p| -p.thickness_range_mm[0]),
        ball_fidelity: flow
            .iter()
            .map(|p| BallFigures::of(&p.fidelity.summary))
            .reduce(BallFigures::worse)?,
    })
}

/// Writes `time_points.csv` (header and one row per time point) atomically.
pub fn write_csv(path: &Path, points: &[TimePoint]) -> Result<(), CliError> {
    medial_io::atomic::write_atomic(path, |w| {
        writeln!(
            w,
            "time_point,t,max_spoke_normal_deg,mean_spoke_normal_deg,max_spoke_mismatch_pct,\
             max_abs_constraint_mm2,min_thickness_mm,max_thickness_mm,\
             ball_residual_sheet_mean_pct,ball_residual_sheet_max_pct,balls_poking_out_sheet,\
             ball_residual_edge_mean_pct,ball_residual_edge_max_pct,balls_poking_out_edge"
        )?;
        for p in points {
            let ball = BallFigures::of(&p.fidelity.summary);
            writeln!(
                w,
                "{},{},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{},{:e},{:e},{}",
                p.index,
                p.t,
                p.max_spoke_normal_deg,
                p.mean_spoke_normal_deg,
                p.max_spoke_mismatch_pct,
                p.max_abs_constraint_mm2,
                p.thickness_range_mm[0],
                p.thickness_range_mm[1],
                ball.sheet.mean_residual_pct,
                ball.sheet.max_residual_pct,
                ball.sheet.poking_out,
                ball.edge.mean_residual_pct,
                ball.edge.max_residual_pct,
                ball.edge.poking_out,
            )?;
        }
        Ok(())
    })?;
    Ok(())
}
