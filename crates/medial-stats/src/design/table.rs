//! A design table as analysts write it: CSV with a header, one row per subject.
//!
//! Columns are chosen by name ([`TableOptions::columns`]; by default every column but one
//! named `subject` or `id`). A column is categorical when it is named in
//! [`TableOptions::categorical`] or when one of its values is not a number; it becomes one
//! indicator column `name[level]` per level except the reference level (the first in sorted
//! order unless [`TableOptions::references`] names it). An intercept column named
//! `intercept` comes first unless [`TableOptions::intercept`] is false; then the first
//! categorical column keeps every level. Empty cells and `NA` are refused: leave the subject
//! out with a row mask instead.

use nalgebra::DMatrix;

use super::{Design, Factor};
use crate::{Result, StatsError};

/// How a CSV table becomes a design matrix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableOptions {
    /// The columns to use, in this order; `None`: every column but `subject`/`id`.
    pub columns: Option<Vec<String>>,
    /// Columns to treat as categorical even if their values are numbers (group codes 1, 2).
    pub categorical: Vec<String>,
    /// (column, level): the reference level of a categorical column.
    pub references: Vec<(String, String)>,
    /// Add an intercept column.
    pub intercept: bool,
}

impl Default for TableOptions {
    fn default() -> Self {
        Self {
            columns: None,
            categorical: Vec::new(),
            references: Vec::new(),
            intercept: true,
        }
    }
}

/// The fields of one CSV line: commas separate, double quotes protect commas, `""` is a quote.
fn split_csv_line(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field).trim().to_string()),
            _ => field.push(c),
        }
    }
    fields.push(field.trim().to_string());
    fields
}

pub(super) fn parse_table(text: &str, options: &TableOptions) -> Result<Design> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines
        .next()
        .ok_or_else(|| StatsError::design("table", "is empty"))?;
    let header = split_csv_line(header.trim_start_matches('\u{feff}'));
    let mut rows: Vec<(usize, Vec<String>)> = Vec::new();
    for (k, line) in lines {
        let fields = split_csv_line(line);
        if fields.len() != header.len() {
            return Err(StatsError::design(
                format!("line {}", k + 1),
                format!("{} fields, the header has {}", fields.len(), header.len()),
            ));
        }
        rows.push((k + 1, fields));
    }
    if rows.is_empty() {
        return Err(StatsError::design("table", "has a header but no subjects"));
    }
    let index = |name: &str| -> Result<usize> {
        header.iter().position(|h| h == name).ok_or_else(|| {
            StatsError::design(
                format!("column `{name}`"),
                format!("is not in the header ({})", header.join(", ")),
            )
        })
    };
    let chosen: Vec<usize> = match &options.columns {
        Some(names) => names.iter().map(|n| index(n)).collect::<Result<_>>()?,
        None => (0..header.len())
            .filter(|&j| !matches!(header[j].to_ascii_lowercase().as_str(), "subject" | "id"))
            .collect(),
    };
    for name in options
        .categorical
        .iter()
        .chain(options.references.iter().map(|(c, _)| c))
    {
        index(name)?;
    }

    let n = rows.len();
    let mut names = Vec::new();
    let mut columns: Vec<Vec<f64>> = Vec::new();
    let mut factors = Vec::new();
    if options.intercept {
        names.push("intercept".to_string());
        columns.push(vec![1.0; n]);
    }
    for &j in &chosen {
        let name = &header[j];
        let cells: Vec<&str> = rows.iter().map(|(_, r)| r[j].as_str()).collect();
        if let Some(i) = cells.iter().position(|c| {
            c.is_empty() || c.eq_ignore_ascii_case("na") || c.eq_ignore_ascii_case("nan")
        }) {
            return Err(StatsError::design(
                format!("line {}, column `{name}`", rows[i].0),
                "is missing: leave the subject out with a row mask",
            ));
        }
        let numbers: Option<Vec<f64>> = cells
            .iter()
            .map(|c| c.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        match numbers {
            Some(values) if !options.categorical.contains(name) => {
                names.push(name.clone());
                columns.push(values);
            }
            _ => {
                let mut levels: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
                levels.sort();
                levels.dedup();
                let keep_all = !options.intercept && factors.is_empty();
                let reference = match options.references.iter().find(|(c, _)| c == name) {
                    Some((_, level)) if !levels.contains(level) => {
                        return Err(StatsError::design(
                            format!("column `{name}`"),
                            format!(
                                "reference level `{level}` is not one of its levels ({})",
                                levels.join(", ")
                            ),
                        ))
                    }
                    Some((_, level)) => Some(level.clone()),
                    None => Some(levels[0].clone()),
                }
                .filter(|_| !keep_all);
                for level in levels.iter().filter(|l| Some(*l) != reference.as_ref()) {
                    names.push(format!("{name}[{level}]"));
                    columns.push(
                        cells
                            .iter()
                            .map(|c| f64::from(u8::from(c == level)))
                            .collect(),
                    );
                }
                factors.push(Factor {
                    name: name.clone(),
                    reference,
                    levels,
                });
            }
        }
    }
    let matrix = DMatrix::from_fn(n, columns.len(), |i, j| columns[j][i]);
    let design = Design::with_factors(names, matrix, factors)?;
    match header
        .iter()
        .position(|h| matches!(h.to_ascii_lowercase().as_str(), "subject" | "id"))
    {
        Some(j) => design.with_subject_names(rows.iter().map(|(_, r)| r[j].clone()).collect()),
        None => Ok(design),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &str = "subject,group,age,site\n\
                         a,control,60,1\n\
                         b,patient,65,2\n\
                         c,\"pat,ient\",70,1\n\
                         d,control,72,2\n";

    #[test]
    fn categorical_columns_become_indicators_against_the_first_level() {
        let d = Design::from_csv(TABLE, &TableOptions::default()).unwrap();
        assert_eq!(
            d.names(),
            [
                "intercept",
                "group[pat,ient]",
                "group[patient]",
                "age",
                "site"
            ]
        );
        assert_eq!(d.matrix().column(2).as_slice(), [0.0, 1.0, 0.0, 0.0]);
        assert_eq!(d.matrix().column(1).as_slice(), [0.0, 0.0, 1.0, 0.0]);
        assert_eq!(d.factors()[0].reference.as_deref(), Some("control"));
    }

    #[test]
    fn group_sizes_count_every_level_and_indicator_column() {
        let d = Design::from_csv(TABLE, &TableOptions::default()).unwrap();
        let size = |name: &str, level: &str, n: usize| (name.to_string(), level.to_string(), n);
        assert_eq!(
            d.group_sizes(),
            [
                size("group", "control", 2),
                size("group", "pat,ient", 1),
                size("group", "patient", 1)
            ]
        );
        // A matrix design: 0/1 columns are groups, the intercept and covariates are not.
        let m = Design::from_whitespace("1 1 0 3.5\n1 0 1 2\n1 0 1 0\n").unwrap();
        assert_eq!(m.group_sizes(), [size("x2", "", 1), size("x3", "", 2)]);
    }

    #[test]
    fn columns_references_and_forced_categories() {
        let options = TableOptions {
            columns: Some(vec!["site".into(), "age".into()]),
            categorical: vec!["site".into()],
            references: vec![("site".into(), "2".into())],
            intercept: true,
        };
        let d = Design::from_csv(TABLE, &options).unwrap();
        assert_eq!(d.names(), ["intercept", "site[1]", "age"]);
        assert_eq!(d.matrix().column(1).as_slice(), [1.0, 0.0, 1.0, 0.0]);
    }

    #[test]
    fn without_intercept_the_first_factor_keeps_every_level() {
        let options = TableOptions {
            columns: Some(vec!["group".into()]),
            intercept: false,
            ..TableOptions::default()
        };
        let d = Design::from_csv(TABLE, &options).unwrap();
        assert_eq!(
            d.names(),
            ["group[control]", "group[pat,ient]", "group[patient]"]
        );
    }

    #[test]
    fn bad_tables_name_the_place() {
        let missing = "group,age\ncontrol,\npatient,3\n";
        let e = Design::from_csv(missing, &TableOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "design, line 2, column `age`: is missing: leave the subject out with a row mask"
        );
        let ragged = "group,age\ncontrol,1,2\n";
        assert!(Design::from_csv(ragged, &TableOptions::default())
            .unwrap_err()
            .to_string()
            .contains("line 2"));
        let options = TableOptions {
            columns: Some(vec!["sex".into()]),
            ..TableOptions::default()
        };
        assert!(Design::from_csv(TABLE, &options)
            .unwrap_err()
            .to_string()
            .contains("`sex`"));
        let options = TableOptions {
            references: vec![("group".into(), "healthy".into())],
            ..TableOptions::default()
        };
        assert!(Design::from_csv(TABLE, &options)
            .unwrap_err()
            .to_string()
            .contains("`healthy`"));
    }
}
