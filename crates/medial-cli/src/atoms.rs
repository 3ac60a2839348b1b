//! The per-atom table of a fit of a medial template, for statistics across subjects:
//! `atoms.csv` (a header and one row per medial atom, for a spreadsheet, `pandas.read_csv` or
//! `numpy.genfromtxt`) and `atoms.npy`, the same numbers as one float64 array of shape
//! `[atoms, 10]` whose columns are those of the CSV, in its order ([`COLUMNS`]).
//!
//! Per atom `m`: its index and spoke count; its thickness `2 × mean spoke length` (mm, the medial
//! VTK's `Thickness`) at `t = 0` and `t = 1`; its medial point at `t = 1` (RAS mm); at `t = 1`
//! the largest angle between one of its spokes and the boundary normal (degrees), its spoke-length
//! mismatch `(max − min) / mean` (%) and its inscribed-ball residual `|d − r| / r` (a fraction,
//! the medial VTK's `BallResidual`; [`medial_core::model::fidelity`]).

use crate::error::CliError;
use crate::results::ResultSet;
use medial_core::model::fidelity::Fidelity;
use medial_core::model::SpokeMetrics;
use medial_core::{MedialTemplate, Vec3};

/// The columns of `atoms.csv` and of `atoms.npy`, in order.
pub const COLUMNS: [&str; 10] = [
    "atom",
    "spokes",
    "thickness_t0",
    "thickness_t1",
    "x_t1",
    "y_t1",
    "z_t1",
    "max_spoke_normal_deg",
    "mismatch_pct",
    "fidelity",
];

/// The rows of the table, one per atom, in [`COLUMNS`] order.
fn rows(
    template: &MedialTemplate,
    q0: &[Vec3],
    q1: &[Vec3],
    fidelity: &Fidelity,
) -> Vec<[f64; 10]> {
    let (start, end) = (
        SpokeMetrics::compute(template, q0),
        SpokeMetrics::compute(template, q1),
    );
    (0..template.medial_count())
        .map(|m| {
            let spokes = template.spokes(m);
            let p = q1[template.atom_landmark(m)];
            let max_angle = spokes
                .iter()
                .map(|&b| end.spoke_normal_deg[b])
                .fold(f64::NEG_INFINITY, f64::max);
            [
                m as f64,
                spokes.len() as f64,
                start.thickness[m],
                end.thickness[m],
                p.x,
                p.y,
                p.z,
                max_angle,
                100.0 * end.mismatch[m],
                fidelity.residual[m],
            ]
        })
        .collect()
}

/// Writes `atoms.csv` and `atoms.npy` into `set` for `template` flowed from `q0` to `q1`, with
/// the inscribed-ball `fidelity` measured at `q1`.
pub fn write(
    set: &mut ResultSet,
    template: &MedialTemplate,
    q0: &[Vec3],
    q1: &[Vec3],
    fidelity: &Fidelity,
) -> Result<(), CliError> {
    let rows = rows(template, q0, q1, fidelity);
    medial_io::atomic::write_atomic(&set.file("atoms.csv")?, |w| {
        writeln!(w, "{}", COLUMNS.join(","))?;
        for row in &rows {
            // The two counts as integers, the rest in the shortest form that reads back exactly.
            write!(w, "{},{}", row[0], row[1])?;
            for x in &row[2..] {
                write!(w, ",{x}")?;
            }
            writeln!(w)?;
        }
        Ok(())
    })?;
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    medial_io::npy::write_npy(&set.file("atoms.npy")?, &[rows.len(), COLUMNS.len()], &flat)?;
    Ok(())
}
