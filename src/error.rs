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

/// What a [`Warning`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// A material file or a material is missing: the default albedo is used.
    Material,
    /// Triangles repeat earlier ones: each is solved once.
    Duplicate,
    /// Nothing emits: the answer is all zero.
    NoEmitter,
    /// A camera line of the scene file is malformed and ignored.
    Camera,
    /// The model was coarsened to fit the memory limit.
    Memory,
    /// The solve stopped at the iteration cap without converging.
    IterationCap,
    /// Exact direct light was asked for but skipped.
    DirectLightSkipped,
    /// Form-factor rows above 1 were capped.
    CappedRows,
    /// Much negative radiance (clamped or kept).
    NegativeRadiance,
    /// Radiance above the bound the emission and albedos allow.
    OverBound,
    /// Two-sided emitters face a surface just behind them: the light trapped between is
    /// cancelled only approximately.
    CoveredEmitter,
    /// A texture could not be read or applied (no texture coordinates): the material's colour
    /// is used.
    Texture,
    /// Albedo at or above [`crate::scene::ALBEDO_MAX`] (a texture, a glTF factor) was lowered
    /// to it.
    Albedo,
    /// Something the scene file asks for is not modelled and is ignored (a glTF extension,
    /// a double-sided material, a light's range, primitives that are not triangles).
    Unsupported,
    /// A polygon could not be triangulated within its outline (it crosses itself) and was
    /// fanned.
    Polygon,
    /// A scene file is not UTF-8 and was read as Latin-1.
    Encoding,
}

/// A finding that does not stop the work (a missing material, a solve that hit its iteration
/// cap, ...): one line, with the file and line it is about when there is one. It displays as
/// `file:line: message`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Warning {
    /// What it is about.
    pub kind: WarningKind,
    /// What happened and what was done instead, one line.
    pub message: String,
    /// The file concerned, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// The 1-based line of `file` concerned, if known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<usize>,
}

impl Warning {
    /// A warning about no file in particular.
    pub fn new(kind: WarningKind, message: impl Into<String>) -> Warning {
        Warning {
            kind,
            message: message.into(),
            file: None,
            line: None,
        }
    }

    /// A warning about `file` (and its `line` when known).
    pub fn in_file(
        kind: WarningKind,
        file: impl Into<PathBuf>,
        line: Option<usize>,
        message: impl Into<String>,
    ) -> Warning {
        Warning {
            file: Some(file.into()),
            line,
            ..Warning::new(kind, message)
        }
    }

    /// True when the displayed warning contains `text`.
    pub fn contains(&self, text: &str) -> bool {
        self.to_string().contains(text)
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (&self.file, self.line) {
            (Some(file), Some(line)) => write!(f, "{}:{line}: {}", file.display(), self.message),
            (Some(file), None) => write!(f, "{}: {}", file.display(), self.message),
            _ => f.write_str(&self.message),
        }
    }
}
