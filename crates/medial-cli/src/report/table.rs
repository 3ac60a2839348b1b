//! A CSV file of a fit folder (`log.csv`, `time_points.csv`) as a table of named columns,
//! whatever its columns are.

use crate::error::CliError;
use std::path::Path;

/// A CSV table: a header and rows of text fields.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Column names, in file order.
    pub columns: Vec<String>,
    /// Rows, each with one field per column.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// Reads a CSV file with a header line.
    ///
    /// Errors: [`CliError::File`] when the file cannot be read or a row is malformed (another
    /// number of fields than the header, bad quoting), naming the file and the line.
    pub fn read(path: &Path) -> Result<Self, CliError> {
        let bytes = std::fs::read(path).map_err(|e| medial_io::Error::io(path, e))?;
        Self::parse(&bytes, path)
    }

    /// Parses CSV text with a header line; `path` names the file in errors.
    ///
    /// Errors: as [`Table::read`].
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self, CliError> {
        let format = |e: csv::Error| medial_io::Error::format(path, e.to_string());
        let mut reader = csv::Reader::from_reader(bytes);
        let columns = reader
            .headers()
            .map_err(format)?
            .iter()
            .map(str::to_owned)
            .collect();
        let rows = reader
            .records()
            .map(|r| r.map(|r| r.iter().map(str::to_owned).collect()))
            .collect::<Result<_, _>>()
            .map_err(format)?;
        Ok(Self { columns, rows })
    }

    /// The fields of column `name`, if the table has it.
    pub fn text(&self, name: &str) -> Option<Vec<&str>> {
        let c = self.columns.iter().position(|n| n == name)?;
        Some(self.rows.iter().map(|r| r[c].as_str()).collect())
    }

    /// The values of column `name` as numbers (NaN for an empty or non-numeric field), if the
    /// table has it.
    pub fn numbers(&self, name: &str) -> Option<Vec<f64>> {
        Some(
            self.text(name)?
                .iter()
                .map(|s| s.trim().parse().unwrap_or(f64::NAN))
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_by_name_with_quoted_fields_and_gaps() {
        let text = "stage,iteration,dice\n\"a,b\",0,\n\"a,b\",1,0.5\n";
        let table = Table::parse(text.as_bytes(), Path::new("log.csv")).unwrap();
        assert_eq!(table.text("stage").unwrap(), ["a,b", "a,b"]);
        let dice = table.numbers("dice").unwrap();
        assert!(dice[0].is_nan() && dice[1] == 0.5);
        assert!(table.numbers("mu").is_none());
    }

    #[test]
    fn a_short_row_is_an_error_naming_the_file() {
        let err = Table::parse(b"a,b\n1\n", Path::new("t.csv")).unwrap_err();
        assert!(err.to_string().starts_with("t.csv: "), "{err}");
    }
}
