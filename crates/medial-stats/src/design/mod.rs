//! The design matrix X (subjects × columns) with a name for every column.
//!
//! | file | what it holds |
//! |---|---|
//! | `table` | a CSV with a header, as analysts write it: columns by name, categorical columns as indicators against a reference level, an intercept unless told otherwise |
//! | `matrix` | whitespace-separated numbers, as meshglm takes its design and contrast files |

mod matrix;
mod table;

pub use matrix::parse_matrix;
pub use table::TableOptions;

use nalgebra::DMatrix;

use crate::{Result, StatsError};

/// A categorical column expanded into indicator columns `name[level]`, one per level but the
/// reference (a design without an intercept gives its first categorical column no reference:
/// an indicator for every level).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Factor {
    /// The column's name in the table.
    pub name: String,
    /// The level without a column (its indicator is implied by the intercept).
    pub reference: Option<String>,
    /// Every level, sorted, the reference included.
    pub levels: Vec<String>,
}

/// A design matrix with named columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Design {
    names: Vec<String>,
    matrix: DMatrix<f64>,
    factors: Vec<Factor>,
}

impl Design {
    /// A design from its columns' names and its matrix (one row per subject). Values must be
    /// finite and names distinct.
    ///
    /// ```
    /// use medial_stats::Design;
    /// use nalgebra::dmatrix;
    ///
    /// let x = dmatrix![1.0, 0.0; 1.0, 0.0; 1.0, 1.0; 1.0, 1.0];
    /// let design = Design::new(vec!["intercept".into(), "patient".into()], x)?;
    /// assert_eq!(design.column("patient"), Some(1));
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn new(names: Vec<String>, matrix: DMatrix<f64>) -> Result<Self> {
        Self::with_factors(names, matrix, Vec::new())
    }

    pub(crate) fn with_factors(
        names: Vec<String>,
        matrix: DMatrix<f64>,
        factors: Vec<Factor>,
    ) -> Result<Self> {
        if names.len() != matrix.ncols() {
            return Err(StatsError::Shape {
                what: "design column names",
                expected: matrix.ncols(),
                found: names.len(),
            });
        }
        if matrix.nrows() == 0 || matrix.ncols() == 0 {
            return Err(StatsError::design(
                "matrix",
                "needs at least one subject and one column",
            ));
        }
        for (j, name) in names.iter().enumerate() {
            if names[..j].contains(name) {
                return Err(StatsError::design(
                    format!("column `{name}`"),
                    "appears twice",
                ));
            }
        }
        if let Some(k) = matrix.iter().position(|v| !v.is_finite()) {
            let (row, col) = (k % matrix.nrows(), k / matrix.nrows());
            return Err(StatsError::design(
                format!("row {}, column `{}`", row + 1, names[col]),
                "is not a finite number",
            ));
        }
        Ok(Self {
            names,
            matrix,
            factors,
        })
    }

    /// A design read from a CSV table (see [`TableOptions`]).
    ///
    /// ```
    /// use medial_stats::{Design, TableOptions};
    ///
    /// let csv = "subject,group,age\ns1,control,60\ns2,patient,61\ns3,control,70\ns4,patient,72\n";
    /// let design = Design::from_csv(csv, &TableOptions::default())?;
    /// assert_eq!(design.names(), ["intercept", "group[patient]", "age"]);
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn from_csv(text: &str, options: &TableOptions) -> Result<Self> {
        table::parse_table(text, options)
    }

    /// A design from meshglm's whitespace-separated matrix, taken as it is (no intercept is
    /// added); its columns are named `x1`, `x2`, ….
    pub fn from_whitespace(text: &str) -> Result<Self> {
        let rows =
            parse_matrix(text).map_err(|(place, problem)| StatsError::design(place, problem))?;
        let names = (1..=rows[0].len()).map(|j| format!("x{j}")).collect();
        let matrix = DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j]);
        Self::new(names, matrix)
    }

    /// The columns' names, in the order of the matrix's columns.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The matrix, one row per subject.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.matrix
    }

    /// The categorical columns expanded into indicators.
    pub fn factors(&self) -> &[Factor] {
        &self.factors
    }

    /// The index of the column `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Subjects (rows).
    pub fn subjects(&self) -> usize {
        self.matrix.nrows()
    }

    /// The design on the subjects whose `keep` is true (the row mask).
    pub fn select_rows(&self, keep: &[bool]) -> Result<Self> {
        if keep.len() != self.subjects() {
            return Err(StatsError::Shape {
                what: "row mask entries",
                expected: self.subjects(),
                found: keep.len(),
            });
        }
        let rows: Vec<usize> = (0..keep.len()).filter(|&i| keep[i]).collect();
        let matrix = self.matrix.select_rows(rows.iter());
        Self::with_factors(self.names.clone(), matrix, self.factors.clone())
    }
}
