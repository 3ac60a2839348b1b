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
    /// The subject of every row (a CSV table's `subject` or `id` column), if named.
    subject_names: Option<Vec<String>>,
}

/// A subject a design's rows can be matched to: its name, and why its data cannot be used, if
/// so (a fit that failed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Candidate<'a> {
    /// The subject's name.
    pub name: &'a str,
    /// Why its data cannot be used (`None`: usable).
    pub unusable: Option<&'a str>,
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
            subject_names: None,
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

    /// The subjects of every group: for each categorical column every level (the reference's
    /// rows are those with none of the factor's indicators), and for every other column
    /// whose values are all 0 or 1 and not all 1 (a group indicator of a matrix design, not the
    /// intercept) the rows with 1. Each entry is (column or factor, level, subjects); the level
    /// is empty for a column.
    pub fn group_sizes(&self) -> Vec<(String, String, usize)> {
        let rows = self.subjects();
        let ones = |j: usize| (0..rows).filter(|&i| self.matrix[(i, j)] == 1.0).count();
        let mut sizes = Vec::new();
        let mut in_factor = vec![false; self.names.len()];
        for factor in &self.factors {
            let column = |level: &str| self.column(&format!("{}[{level}]", factor.name));
            let indicators: Vec<usize> = factor.levels.iter().filter_map(|l| column(l)).collect();
            for &j in &indicators {
                in_factor[j] = true;
            }
            for level in &factor.levels {
                let n = match column(level) {
                    Some(j) => ones(j),
                    None => (0..rows)
                        .filter(|&i| indicators.iter().all(|&j| self.matrix[(i, j)] == 0.0))
                        .count(),
                };
                sizes.push((factor.name.clone(), level.clone(), n));
            }
        }
        for (j, name) in self.names.iter().enumerate() {
            let column = self.matrix.column(j);
            let binary = column.iter().all(|&v| v == 0.0 || v == 1.0);
            if !in_factor[j] && binary && column.iter().any(|&v| v == 0.0) {
                sizes.push((name.clone(), String::new(), ones(j)));
            }
        }
        sizes
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
        let mut design = Self::with_factors(self.names.clone(), matrix, self.factors.clone())?;
        design.subject_names = self
            .subject_names
            .as_ref()
            .map(|names| rows.iter().map(|&i| names[i].clone()).collect());
        Ok(design)
    }

    /// The subject of every row, from a CSV table's column named `subject` or `id` (any letter
    /// case); `None` for a table without one and for a matrix.
    pub fn subject_names(&self) -> Option<&[String]> {
        self.subject_names.as_deref()
    }

    /// The same design with `names` as the subjects of its rows (one per row, distinct).
    pub fn with_subject_names(mut self, names: Vec<String>) -> Result<Self> {
        if names.len() != self.subjects() {
            return Err(StatsError::Shape {
                what: "subject names (one per design row)",
                expected: self.subjects(),
                found: names.len(),
            });
        }
        let mut seen = std::collections::BTreeMap::new();
        for (i, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err(StatsError::design(
                    format!("row {}", i + 1),
                    "has no subject name",
                ));
            }
            if let Some(first) = seen.insert(name.as_str(), i) {
                return Err(StatsError::design(
                    format!("subject `{name}`"),
                    format!("appears twice (rows {} and {})", first + 1, i + 1),
                ));
            }
        }
        self.subject_names = Some(names);
        Ok(self)
    }

    /// The design's rows matched to `candidates` by subject name. A row whose subject is not a
    /// candidate is an error (naming it); a row whose subject is unusable is left out of the
    /// design (and listed with why); candidates the design does not name are left out. At
    /// least one row must remain.
    ///
    /// ```
    /// use medial_stats::{design::Candidate, Design, TableOptions};
    ///
    /// let csv = "subject,group\ns3,b\ns1,a\ns2,b\ns4,a\ns5,a\n";
    /// let design = Design::from_csv(csv, &TableOptions::default())?;
    /// let mut cohort = ["s1", "s2", "s3", "s4", "s5"].map(|name| Candidate { name, unusable: None });
    /// cohort[3].unusable = Some("its fit failed");
    /// let matched = design.match_subjects(&cohort)?;
    /// assert_eq!(matched.subjects, [2, 0, 1, 4]);
    /// assert_eq!(matched.design.subject_names().unwrap(), ["s3", "s1", "s2", "s5"]);
    /// assert_eq!(matched.left_out, [("s4".to_string(), "its fit failed".to_string())]);
    /// let short = &cohort[..3];
    /// assert_eq!(
    ///     design.match_subjects(short).unwrap_err().to_string(),
    ///     "design, subject `s4` (row 4): is not in the cohort (its subjects: s1, s2, s3)"
    /// );
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn match_subjects(&self, candidates: &[Candidate<'_>]) -> Result<Matched> {
        let names = self.subject_names.as_ref().ok_or_else(|| {
            StatsError::design(
                "table",
                "has no `subject` (or `id`) column to match its rows to the subjects by name",
            )
        })?;
        let index: std::collections::HashMap<&str, usize> = candidates
            .iter()
            .enumerate()
            .map(|(k, c)| (c.name, k))
            .collect();
        let mut subjects = Vec::new();
        let mut left_out = Vec::new();
        let mut keep = Vec::with_capacity(names.len());
        for (row, name) in names.iter().enumerate() {
            let Some(&k) = index.get(name.as_str()) else {
                const SHOWN: usize = 8;
                let mut listed: Vec<&str> = candidates.iter().take(SHOWN).map(|c| c.name).collect();
                if candidates.len() > SHOWN {
                    listed.push("…");
                }
                return Err(StatsError::design(
                    format!("subject `{name}` (row {})", row + 1),
                    format!("is not in the cohort (its subjects: {})", listed.join(", ")),
                ));
            };
            match candidates[k].unusable {
                Some(why) => left_out.push((name.clone(), why.to_string())),
                None => subjects.push(k),
            }
            keep.push(candidates[k].unusable.is_none());
        }
        if subjects.is_empty() {
            return Err(StatsError::design(
                "table",
                "none of its subjects has data to test (every one's fit is unusable)",
            ));
        }
        Ok(Matched {
            design: self.select_rows(&keep)?,
            subjects,
            left_out,
        })
    }
}

/// A design matched to a cohort's subjects ([`Design::match_subjects`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Matched {
    /// The design on the rows whose subject is usable.
    pub design: Design,
    /// For every row of `design`, the index of its subject among the candidates.
    pub subjects: Vec<usize>,
    /// The rows left out: their subject and why.
    pub left_out: Vec<(String, String)>,
}
