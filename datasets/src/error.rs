//! Errors of world building, rendering and sequence I/O.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// An error that names the file, line, key or field at fault.
#[derive(Debug, Error)]
pub enum DatasetError {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// A text file has a bad line.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A TOML file does not match its schema (unknown key, wrong type, missing field); the
    /// message carries TOML's own location and key.
    #[error("{}: {message}", path.display())]
    Toml {
        /// The file (or `<built-in default world>`).
        path: PathBuf,
        /// TOML's description, with line, column and key.
        message: String,
    },
    /// An image file that cannot be decoded or has the wrong format.
    #[error("{}: {message}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A mesh file that cannot be read.
    #[error("{}: {message}", path.display())]
    Mesh {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A configuration value that is out of range or inconsistent.
    #[error("invalid `{key}`: {message}")]
    Invalid {
        /// The key or field path, e.g. `rocks[2].pedestal.top_radius_m`.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A TUM trajectory file that cannot be read or written (names the file and line).
    #[error(transparent)]
    Trajectory(#[from] scarp_export::tum::TumError),
    /// A file that cannot be written atomically (names the file).
    #[error(transparent)]
    Write(#[from] scarp_export::atomic::AtomicWriteError),
    /// A geometry-core error.
    #[error(transparent)]
    Geometry(#[from] scarp_slam::SlamError),
}

impl DatasetError {
    /// An I/O error about `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// An invalid configuration value at `key`.
    pub fn invalid(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Invalid {
            key: key.into(),
            message: message.into(),
        }
    }

    /// A parse error at `path:line`.
    pub fn parse(path: &Path, line: usize, message: impl Into<String>) -> Self {
        Self::Parse {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }
}
