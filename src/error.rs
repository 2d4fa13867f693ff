//! The one error type at the library boundary.
//!
//! Every user-facing failure is a single line that names the file (and the line when known), so the
//! CLI can print `error: {e}` and exit non-zero without a panic or a half-written output.

use std::path::PathBuf;

/// Everything that can go wrong between reading a scene and writing results.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// What the operating system said.
        message: String,
    },
    /// A scene or material file is malformed at a known line (1-based).
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file concerned.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong on that line.
        message: String,
    },
    /// A scene is unusable as a whole (no triangles, nothing valid) or a file has no line to blame.
    #[error("{path}: {message}")]
    Scene {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// A command-line or library parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    Parameter(String),
    /// A solve failed its health checks (see [`crate::solve::health`]): it diverged, produced NaN or
    /// infinite values, radiance beyond what the emission and albedos allow, or negative
    /// radiance comparable to the positive. The message names the solver, the check, the sweep
    /// and the figures.
    #[error("{0}")]
    Solve(String),
    /// A solve does not fit its memory limit, even coarsened (see [`crate::solve::budget`]); raised
    /// before the large arrays are allocated.
    #[error("{0}")]
    Memory(String),
}

impl Error {
    /// Builds an [`Error::Io`] from a path and an `std::io::Error`.
    pub fn io(path: impl Into<PathBuf>, err: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            message: err.to_string(),
        }
    }
}

/// Result alias used across the crate.
pub type Result<T> = std::result::Result<T, Error>;
