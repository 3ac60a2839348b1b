//! The one error type of the statistics: every bad input is a typed variant whose message is
//! one line naming the parameter, the value and the rule it breaks.

/// What can go wrong setting up or running an analysis.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StatsError {
    /// An option is out of its range.
    #[error("{parameter} = {value}: {rule}")]
    Parameter {
        /// The option's name.
        parameter: &'static str,
        /// Its value, as given.
        value: String,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// The design table or matrix cannot be read or used; `place` is a line, column or name.
    #[error("design, {place}: {problem}")]
    Design {
        /// Where (line and column, or column name).
        place: String,
        /// What is wrong.
        problem: String,
    },
    /// A contrast cannot be read or tested on the design.
    #[error("contrast `{contrast}`: {problem}")]
    Contrast {
        /// The contrast as given.
        contrast: String,
        /// What is wrong.
        problem: String,
    },
    /// Two inputs disagree in size.
    #[error("{what}: expected {expected}, found {found}")]
    Shape {
        /// Which count.
        what: &'static str,
        /// The size the other inputs require.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// The mesh is not a valid triangle mesh.
    #[error("mesh: {0}")]
    Mesh(String),
    /// An analysis asks for something the data cannot give (no element left, too few subjects).
    #[error("{0}")]
    Data(String),
}

/// The result type of this crate.
pub type Result<T> = std::result::Result<T, StatsError>;

impl StatsError {
    /// A [`StatsError::Parameter`] for `parameter` whose `value` breaks `rule`.
    pub fn parameter(parameter: &'static str, value: impl ToString, rule: &'static str) -> Self {
        Self::Parameter {
            parameter,
            value: value.to_string(),
            rule,
        }
    }

    /// A [`StatsError::Design`] at `place`.
    pub fn design(place: impl Into<String>, problem: impl Into<String>) -> Self {
        Self::Design {
            place: place.into(),
            problem: problem.into(),
        }
    }

    /// A [`StatsError::Contrast`] on `contrast`.
    pub fn contrast(contrast: impl Into<String>, problem: impl Into<String>) -> Self {
        Self::Contrast {
            contrast: contrast.into(),
            problem: problem.into(),
        }
    }
}
