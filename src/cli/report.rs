//! The JSON report every command can write (`--report`).

use crate::cli::flags::flagged;
use antiradiance::error::{Result, Warning};
use antiradiance::output;
use antiradiance::scene::{self};
use antiradiance::solve::solution::{self, SolveStats};
use serde::Serialize;
use serde_json::{Map, Value};
use std::path::Path;

use crate::cli::driver::*;

/// Scene counts as they appear in reports.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Counts {
    /// Input triangles (after fan triangulation), the length of every per-triangle output.
    pub input_triangles: usize,
    /// Patches the solver worked on (more than the triangles with `--max-edge`).
    pub patches: usize,
    /// Zero-area input triangles (kept in the outputs with B = E).
    pub degenerate_triangles: usize,
    /// Input triangles that emit.
    pub emitters: usize,
}

impl Counts {
    /// The counts of a loaded scene.
    pub fn of(loaded: &Loaded) -> Counts {
        Counts {
            input_triangles: loaded.scene.len(),
            patches: loaded.patches.len(),
            degenerate_triangles: loaded.scene.degenerate_count(),
            emitters: loaded.scene.emitter_count(),
        }
    }
}

/// A JSON report under construction: a header common to every command (`tool`, `version`,
/// `command`, `scene`, `counts`, `warnings`) plus whatever the command inserts.
#[derive(Clone, Debug, Default)]
pub struct Report {
    fields: Map<String, Value>,
}

impl Report {
    /// The common header of a report for `command` on a loaded scene.
    pub fn new(command: &str, scene_path: &Path, loaded: &Loaded) -> Report {
        let mut report = Report::default();
        report
            .insert("tool", env!("CARGO_PKG_NAME"))
            .insert("version", env!("CARGO_PKG_VERSION"))
            .insert("command", command)
            .insert("scene", scene_path.display().to_string())
            .insert("counts", Counts::of(loaded))
            .insert("warnings", Value::Array(Vec::new()));
        report.add_warnings(loaded.scene.warnings.iter().cloned());
        report
    }

    /// Appends warnings of the run (iteration cap, ...) to the scene's in `warnings`, each as
    /// `{kind, message, file, line}` (file and line when known) with the message naming flags.
    pub fn add_warnings(&mut self, warnings: impl IntoIterator<Item = Warning>) -> &mut Report {
        let list = self
            .fields
            .entry("warnings")
            .or_insert_with(|| Value::Array(Vec::new()));
        if let Value::Array(list) = list {
            list.extend(warnings.into_iter().map(|w| {
                let w = Warning {
                    message: one_line(&flagged(&w.message)),
                    ..w
                };
                serde_json::to_value(&w).unwrap_or(Value::Null)
            }));
        }
        self
    }

    /// Sets `key` (replacing any previous value); a value that cannot be serialized becomes null.
    pub fn insert(&mut self, key: &str, value: impl Serialize) -> &mut Report {
        let value = serde_json::to_value(value).unwrap_or(Value::Null);
        self.fields.insert(key.to_string(), value);
        self
    }

    /// Adds `time_seconds` and `peak_memory_bytes` (read now), the closing fields of a report.
    pub fn finish(&mut self, timings: &Timings, peak_memory_bytes: Option<u64>) -> &mut Report {
        self.insert("time_seconds", timings)
            .insert("peak_memory_bytes", peak_memory_bytes)
    }

    /// The report as a JSON value.
    pub fn to_value(&self) -> Value {
        Value::Object(self.fields.clone())
    }

    /// Writes the report (pretty-printed, atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        output::write_json(path, &self.to_value())
    }
}

/// What a mesh cost a solve (the report's `stats.mesh`): the shapes of the input triangles,
/// the elements solved and the links per input triangle.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MeshStats {
    /// Aspect ratios (longest edge squared over area) and area range of the non-degenerate
    /// input triangles ([`Scene::shapes`]).
    #[serde(flatten)]
    pub shapes: scene::TriangleShapes,
    /// Elements solved: the hierarchical solver's leaf triangles after its splits, the dense
    /// solver's patches; 0 for the path tracer.
    pub elements: usize,
    /// Links per non-degenerate input triangle (0 for the path tracer).
    pub links_per_triangle: f64,
}

impl MeshStats {
    /// The figures of a solve of a loaded scene.
    pub fn of(loaded: &Loaded, stats: &SolveStats) -> MeshStats {
        let shapes = loaded.scene.shapes();
        MeshStats {
            shapes,
            elements: stats.elements,
            links_per_triangle: if shapes.triangles > 0 {
                stats.links as f64 / shapes.triangles as f64
            } else {
                0.0
            },
        }
    }
}

/// Solver statistics as they appear in reports, with what the mesh cost (`mesh`, see
/// [`MeshStats`]). Non-finite numbers become 0 rather than null, except the residual of a
/// failed solve (null when it was NaN or infinite: that is what failed); `failure` is null for
/// a healthy solve, else the failure's figures with its one-line `message`.
pub fn stats_json(stats: &SolveStats, loaded: &Loaded) -> Value {
    let mut s = stats.clone();
    if s.failure.is_none() {
        s.residual = solution::sanitize(s.residual);
    }
    s.negative_fraction = solution::sanitize(s.negative_fraction);
    s.max_row_sum = solution::sanitize(s.max_row_sum);
    s.largest_b_over_bound = solution::sanitize(s.largest_b_over_bound);
    s.radiance_bound = solution::sanitize(s.radiance_bound);
    let mut value = serde_json::to_value(s).unwrap_or(Value::Null);
    if let (Some(f), Some(Value::Object(failure))) = (&stats.failure, value.get_mut("failure")) {
        failure.insert("message".into(), Value::String(f.to_string()));
    }
    if let Value::Object(map) = &mut value {
        let mesh = serde_json::to_value(MeshStats::of(loaded, stats)).unwrap_or(Value::Null);
        map.insert("mesh".into(), mesh);
    }
    value
}
