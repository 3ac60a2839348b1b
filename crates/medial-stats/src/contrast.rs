//! Contrasts: which combination of the design's coefficients is tested.
//!
//! A contrast is a matrix C (q × columns). One row is a t-test of cᵀβ = 0 (one-sided towards
//! cᵀβ > 0 unless two-sided); several rows are an F-test of Cβ = 0. As text
//! ([`Contrast::parse`]) a contrast is `name: row; row; …` (the name is optional), each row
//! either numbers (`-1 1 0.05`, `[-1, 1, 0.05]`) or an expression over the columns' names:
//! `group[patient] - group[control]`, `0.5*age`, `-2 dose + sex[m]`. A categorical column's
//! reference level has no column of its own: its term counts as zero, so that
//! `group[patient] - group[control]` is the patient indicator's coefficient, the difference
//! of the two groups' means.

use nalgebra::DMatrix;

use crate::{Design, Result, StatsError};

/// A contrast on a design: a name and its matrix (q rows, one column per design column).
#[derive(Clone, Debug, PartialEq)]
pub struct Contrast {
    name: String,
    matrix: DMatrix<f64>,
}

impl Contrast {
    /// A contrast from its rows of weights, one weight per design column. The rows must be
    /// linearly independent.
    pub fn from_rows(name: impl Into<String>, rows: &[Vec<f64>], design: &Design) -> Result<Self> {
        let name = name.into();
        let p = design.names().len();
        if rows.is_empty() {
            return Err(StatsError::contrast(name, "has no rows"));
        }
        if let Some(row) = rows.iter().find(|r| r.len() != p) {
            return Err(StatsError::contrast(
                name,
                format!(
                    "has {} weights, the design has {p} columns ({})",
                    row.len(),
                    design.names().join(", ")
                ),
            ));
        }
        if rows.iter().flatten().any(|w| !w.is_finite()) {
            return Err(StatsError::contrast(
                name,
                "has a weight that is not finite",
            ));
        }
        let matrix = DMatrix::from_fn(rows.len(), p, |i, j| rows[i][j]);
        let singular = matrix.clone().svd(false, false).singular_values;
        let largest = singular.max();
        if largest == 0.0 {
            return Err(StatsError::contrast(name, "is zero"));
        }
        if singular.iter().filter(|&&s| s > largest * 1e-10).count() < rows.len() {
            return Err(StatsError::contrast(
                name,
                "has rows that are linearly dependent: drop the redundant ones",
            ));
        }
        Ok(Self { name, matrix })
    }

    /// A contrast written as text (see the module's documentation).
    ///
    /// ```
    /// use medial_stats::{Contrast, Design, TableOptions};
    ///
    /// let csv = "group,age\ncontrol,60\npatient,61\ncontrol,70\npatient,72\n";
    /// let design = Design::from_csv(csv, &TableOptions::default())?;
    /// let c = Contrast::parse("disease: group[patient] - group[control]", &design)?;
    /// assert_eq!(c.name(), "disease");
    /// assert_eq!(c.matrix().row(0).iter().copied().collect::<Vec<_>>(), [0.0, 1.0, 0.0]);
    /// let f = Contrast::parse("0 1 0; 0 0 1", &design)?;
    /// assert_eq!(f.rows(), 2);
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn parse(spec: &str, design: &Design) -> Result<Self> {
        let (name, body) = match spec.split_once(':') {
            Some((name, body)) if is_plain_name(name.trim()) => (name.trim(), body),
            _ => (spec.trim(), spec),
        };
        let rows = body
            .split(';')
            .map(|row| {
                parse_row(row, design).map_err(|problem| StatsError::contrast(spec.trim(), problem))
            })
            .collect::<Result<Vec<_>>>()?;
        Self::from_rows(name, &rows, design)
    }

    /// A contrast from a file's text, as meshglm reads its contrast files: one row per line
    /// (numbers or an expression; blank lines and lines starting with `#` skipped), named
    /// `name`.
    pub fn parse_file(name: &str, text: &str, design: &Design) -> Result<Self> {
        let rows: Vec<&str> = text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .collect();
        let parsed = rows
            .iter()
            .map(|row| {
                parse_row(row, design).map_err(|problem| StatsError::contrast(name, problem))
            })
            .collect::<Result<Vec<_>>>()?;
        Self::from_rows(name, &parsed, design)
    }

    /// The contrast's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// C, q × design columns.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.matrix
    }

    /// q: 1 for a t-test, more for an F-test.
    pub fn rows(&self) -> usize {
        self.matrix.nrows()
    }
}

fn is_plain_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | ' '))
        && s.chars().any(char::is_alphabetic)
}

/// One row: numbers only, or an expression over the columns' names.
fn parse_row(row: &str, design: &Design) -> std::result::Result<Vec<f64>, String> {
    let numbers: Option<Vec<f64>> = row
        .split(|c: char| c.is_whitespace() || matches!(c, ',' | '[' | ']'))
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f64>().ok())
        .collect();
    match numbers {
        Some(v) if !v.is_empty() => Ok(v),
        Some(_) => Err("has an empty row".into()),
        None => parse_expression(row, design),
    }
}

/// `[sign] [number ['*']] name`, repeated.
fn parse_expression(text: &str, design: &Design) -> std::result::Result<Vec<f64>, String> {
    let mut weights = vec![0.0; design.names().len()];
    let chars: Vec<char> = text.chars().collect();
    let mut i = 0;
    let skip_spaces = |i: &mut usize| {
        while *i < chars.len() && chars[*i].is_whitespace() {
            *i += 1;
        }
    };
    let mut first = true;
    loop {
        skip_spaces(&mut i);
        if i == chars.len() {
            break;
        }
        let mut sign = 1.0;
        match chars[i] {
            '+' => i += 1,
            '-' => {
                sign = -1.0;
                i += 1;
            }
            _ if !first => return Err(format!("expected + or - at `{}`", tail(&chars, i))),
            _ => {}
        }
        first = false;
        skip_spaces(&mut i);
        let start = i;
        while i < chars.len()
            && (chars[i].is_ascii_digit()
                || chars[i] == '.'
                || (matches!(chars[i], 'e' | 'E') && i > start)
                || (matches!(chars[i], '+' | '-')
                    && i > start
                    && matches!(chars[i - 1], 'e' | 'E')))
        {
            i += 1;
        }
        let factor = if i > start {
            let s: String = chars[start..i].iter().collect();
            s.parse::<f64>()
                .map_err(|_| format!("`{s}` is not a number"))?
        } else {
            1.0
        };
        skip_spaces(&mut i);
        if i < chars.len() && chars[i] == '*' {
            i += 1;
            skip_spaces(&mut i);
        }
        let start = i;
        let mut depth = 0;
        while i < chars.len()
            && (depth > 0 || !(chars[i].is_whitespace() || matches!(chars[i], '+' | '-' | '*')))
        {
            match chars[i] {
                '[' => depth += 1,
                ']' => depth -= 1,
                _ => {}
            }
            i += 1;
        }
        let name: String = chars[start..i].iter().collect();
        if name.is_empty() {
            return Err(format!(
                "a weight without a column name at `{}`",
                tail(&chars, start)
            ));
        }
        add_term(&mut weights, &name, sign * factor, design)?;
    }
    Ok(weights)
}

fn tail(chars: &[char], i: usize) -> String {
    chars[i..].iter().collect::<String>().trim().to_string()
}

fn add_term(
    weights: &mut [f64],
    name: &str,
    w: f64,
    design: &Design,
) -> std::result::Result<(), String> {
    if let Some(j) = design.column(name) {
        weights[j] += w;
        return Ok(());
    }
    let bracket = name.find('[').filter(|_| name.ends_with(']'));
    if let Some(b) = bracket {
        let (column, level) = (&name[..b], &name[b + 1..name.len() - 1]);
        if let Some(f) = design.factors().iter().find(|f| f.name == column) {
            if f.reference.as_deref() == Some(level) {
                return Ok(());
            }
            return Err(format!(
                "`{level}` is not a level of `{column}` ({})",
                f.levels.join(", ")
            ));
        }
    }
    if let Some(f) = design.factors().iter().find(|f| f.name == name) {
        return Err(format!(
            "`{name}` is categorical: name a level, as `{name}[{}]`",
            f.levels.last().map_or("", String::as_str)
        ));
    }
    Err(format!(
        "`{name}` is not a column of the design ({})",
        design.names().join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TableOptions;

    fn design() -> Design {
        let csv = "group,age,dose\nc,1,2\np,2,3\nq,3,5\nc,4,7\np,5,11\n";
        Design::from_csv(csv, &TableOptions::default()).unwrap()
    }

    fn row(c: &Contrast, i: usize) -> Vec<f64> {
        c.matrix().row(i).iter().copied().collect()
    }

    #[test]
    fn expressions_weigh_columns_and_drop_the_reference_level() {
        let d = design();
        assert_eq!(
            d.names(),
            ["intercept", "group[p]", "group[q]", "age", "dose"]
        );
        let c = Contrast::parse("group[p] - group[c]", &d).unwrap();
        assert_eq!(row(&c, 0), [0.0, 1.0, 0.0, 0.0, 0.0]);
        assert_eq!(c.name(), "group[p] - group[c]");
        let c = Contrast::parse("mix: -0.5*group[p] + 5e-1 age-2 dose + 0.25 * age", &d).unwrap();
        assert_eq!(c.name(), "mix");
        assert_eq!(row(&c, 0), [0.0, -0.5, 0.0, 0.75, -2.0]);
    }

    #[test]
    fn files_have_a_row_per_line() {
        let d = design();
        let c = Contrast::parse_file("file", "# weights\n0 1 0 0 0\n\n group[q] \n", &d).unwrap();
        assert_eq!((c.name(), c.rows()), ("file", 2));
        assert_eq!(row(&c, 1), [0.0, 0.0, 1.0, 0.0, 0.0]);
        assert!(Contrast::parse_file("file", "1 2\n", &d).is_err());
    }

    #[test]
    fn vectors_and_f_tests() {
        let d = design();
        let c = Contrast::parse("[0, 0, 0, 1, -1]", &d).unwrap();
        assert_eq!(row(&c, 0), [0.0, 0.0, 0.0, 1.0, -1.0]);
        let f = Contrast::parse("groups: group[p]; group[q] - group[p]", &d).unwrap();
        assert_eq!(f.rows(), 2);
        assert_eq!(row(&f, 1), [0.0, -1.0, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn bad_contrasts_say_why() {
        let d = design();
        let message = |s: &str| Contrast::parse(s, &d).unwrap_err().to_string();
        assert!(message("sex[m]").contains("`sex[m]` is not a column"));
        assert!(message("group").contains("is categorical"));
        assert!(message("group[r]").contains("`r` is not a level"));
        assert!(message("1 2").contains("has 2 weights"));
        assert!(message("group[c]").contains("is zero"));
        assert!(message("age; 2 age").contains("linearly dependent"));
        assert!(message("age dose").contains("expected + or -"));
        assert!(message("age + 2").contains("without a column name"));
    }
}
