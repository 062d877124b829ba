//! Errors of bundle adjustment: reading BAL files, checking problems and solving them.

use std::path::PathBuf;

use thiserror::Error;

/// An error from the BAL reader or the bundle-adjustment solver. Each variant names the file,
/// line, element or stage at fault.
#[derive(Debug, Error)]
pub enum BaError {
    /// A BAL file could not be read from disk.
    #[error("reading BAL file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A BAL file is malformed: truncated, with negative or absurd counts, a token that is not a
    /// number, a non-finite value or an index out of range.
    #[error("{source_name}:{line}: {reason}")]
    Parse {
        /// The file name (or another label for in-memory input).
        source_name: String,
        /// The 1-based line at fault (the last line when the file is truncated).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A problem handed to the solver is inconsistent (an observation refers to a camera or point
    /// that does not exist, a parameter is not finite, …).
    #[error("invalid bundle-adjustment problem: {reason}")]
    InvalidProblem {
        /// What is wrong, naming the element.
        reason: String,
    },
    /// The initial cost is not finite, so the solver cannot start.
    #[error("the initial cost is not finite ({cost}); check the start parameters")]
    NonFiniteInitialCost {
        /// The initial cost.
        cost: f64,
    },
    /// A solver configuration value is out of range.
    #[error("invalid solver setting `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// The field of [`crate::ba::LmConfig`].
        field: &'static str,
        /// Its value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
}
