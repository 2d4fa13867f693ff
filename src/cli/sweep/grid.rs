//! The sweep's grid: the knob lists parsed, every run's options built and validated, and the
//! reference and output files checked before anything runs.

use std::path::Path;

use super::*;
use crate::cli::driver;
use antiradiance::error::{Error, Result};
use antiradiance::solve::{Preset, SolverKind};

/// One value of a knob list: a value, or the value of the preset being run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Choice<T> {
    Value(T),
    Preset,
}

impl<T: Copy> Choice<T> {
    fn resolve(self, preset_value: T) -> T {
        match self {
            Choice::Value(v) => v,
            Choice::Preset => preset_value,
        }
    }
}

/// Parses a comma-separated list for `--flag`: each item through `parse` (which says what it
/// expected when it fails), or the word `preset` when `allow_preset`. Repeated items are kept
/// once, in first-seen order.
pub(super) fn parse_list<T: Copy + PartialEq>(
    flag: &str,
    text: &str,
    allow_preset: bool,
    parse: impl Fn(&str) -> std::result::Result<T, String>,
) -> Result<Vec<Choice<T>>> {
    let mut out: Vec<Choice<T>> = Vec::new();
    for item in text.split(',').map(str::trim) {
        if item.is_empty() {
            return Err(Error::Parameter(format!(
                "--{flag} '{text}': empty item in the comma-separated list"
            )));
        }
        let choice = if allow_preset && item.eq_ignore_ascii_case("preset") {
            Choice::Preset
        } else {
            Choice::Value(
                parse(item).map_err(|why| Error::Parameter(format!("--{flag} '{item}': {why}")))?,
            )
        };
        if !out.contains(&choice) {
            out.push(choice);
        }
    }
    Ok(out)
}

pub(super) fn parse_number(item: &str) -> std::result::Result<f64, String> {
    item.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| "not a finite number".to_string())
}

pub(super) fn parse_count(item: &str) -> std::result::Result<usize, String> {
    item.parse::<usize>()
        .map_err(|_| "not a non-negative integer".to_string())
}

pub(super) fn parse_switch(item: &str) -> std::result::Result<bool, String> {
    match item.to_ascii_lowercase().as_str() {
        "on" | "true" | "yes" | "1" => Ok(true),
        "off" | "false" | "no" | "0" => Ok(false),
        _ => Err("expected on or off".to_string()),
    }
}

pub(super) fn parse_preset(item: &str) -> std::result::Result<Preset, String> {
    Preset::from_name(item).ok_or_else(|| "expected fast, default or accurate".to_string())
}

/// One point of the grid: the preset it starts from and the complete, validated options.
#[derive(Clone, Debug)]
pub struct RunSpec {
    /// The preset the run starts from.
    pub preset: Preset,
    /// The solver options of the run (preset with the grid's values applied).
    pub options: SolverOptions,
}

impl RunSpec {
    /// The knob values that identify a run (for removing duplicates from the grid).
    fn key(&self) -> (&'static str, usize, u64, u64, usize, bool) {
        let o = &self.options;
        (
            self.preset.name(),
            o.bins,
            o.epsilon.to_bits(),
            o.tol.to_bits(),
            o.max_iterations,
            o.direct_light,
        )
    }
}

impl SweepArgs {
    /// The grid of runs, every one validated, in the order they will run (presets, then direct
    /// light off/on, bins, epsilon, tolerance, iteration cap). Fails on a malformed list, an
    /// out-of-range value (naming the flag) or a grid of more than [`MAX_RUNS`] runs.
    pub fn runs(&self) -> Result<Vec<RunSpec>> {
        let presets = parse_list("preset", &self.preset, false, parse_preset)?;
        let direct = parse_list("direct-light", &self.direct_light, false, parse_switch)?;
        let bins = parse_list("bins", &self.bins, true, parse_count)?;
        let epsilon = match self.solver {
            SolverKind::Hierarchical => parse_list("epsilon", &self.epsilon, true, parse_number)?,
            // The dense solver has no links to refine: one run, whatever the list says.
            SolverKind::Dense => vec![Choice::Preset],
        };
        let tol = parse_list("tol", &self.tol, true, parse_number)?;
        let max_iterations = parse_list("max-iterations", &self.max_iterations, true, parse_count)?;
        let count = presets.len()
            * direct.len()
            * bins.len()
            * epsilon.len()
            * tol.len()
            * max_iterations.len();
        if count > MAX_RUNS {
            return Err(Error::Parameter(format!(
                "the sweep grid has {count} runs (at most {MAX_RUNS}); shorten the lists"
            )));
        }
        let mut runs: Vec<RunSpec> = Vec::with_capacity(count);
        for preset in presets.iter().map(|p| p.resolve(Preset::Default)) {
            let base = preset.options();
            for d in &direct {
                let direct_light = d.resolve(base.direct_light);
                for b in &bins {
                    for e in &epsilon {
                        for t in &tol {
                            for m in &max_iterations {
                                let mut options = base.clone();
                                options.bins = b.resolve(base.bins);
                                options.epsilon = e.resolve(base.epsilon);
                                options.tol = t.resolve(base.tol);
                                options.max_iterations = m.resolve(base.max_iterations);
                                options.direct_light = direct_light;
                                options.two_sided = self.two_sided_antiradiance;
                                if let Some(depth) = self.split_depth {
                                    options.split_depth = depth;
                                }
                                if let Some(limit) = self.memory_limit {
                                    options.memory_limit_bytes = Some(limit);
                                }
                                options.validate()?;
                                let run = RunSpec { preset, options };
                                if !runs.iter().any(|r| r.key() == run.key()) {
                                    runs.push(run);
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(runs)
    }

    /// Checks the reference options and every output path (before anything is loaded).
    pub(super) fn check_files(&self) -> Result<()> {
        match (&self.reference, self.reference_spp) {
            (None, None) => {
                return Err(Error::Parameter(
                    "sweep needs a reference: --reference REF.csv or --reference-spp N".into(),
                ))
            }
            (Some(_), Some(_)) => {
                return Err(Error::Parameter(
                    "give either --reference or --reference-spp, not both".into(),
                ))
            }
            (None, Some(0)) => {
                return Err(Error::Parameter(
                    "--reference-spp must be at least 1".into(),
                ))
            }
            _ => {}
        }
        if self.time_axis == TimeAxis::Cpu && process_cpu_ticks().is_none() {
            return Err(Error::Parameter(
                "--time-axis cpu needs /proc/self/stat (Linux); use --time-axis wall".into(),
            ));
        }
        if !(1..=100).contains(&self.repeat) {
            return Err(Error::Parameter(format!(
                "--repeat {} outside 1..=100",
                self.repeat
            )));
        }
        if self.save_reference.is_some() && self.reference_spp.is_none() {
            return Err(Error::Parameter(
                "--save-reference needs --reference-spp (it saves the reference computed here)"
                    .into(),
            ));
        }
        let mut files: Vec<(&str, &Path)> = vec![("--csv", self.csv.as_path())];
        if let Some(p) = &self.svg {
            files.push(("--svg", p.as_path()));
        }
        if let Some(p) = &self.save_reference {
            files.push(("--save-reference", p.as_path()));
        }
        driver::check_outputs(&files, &self.scene.scene)?;
        if let Some(reference) = &self.reference {
            let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
                (Ok(x), Ok(y)) => x == y,
                _ => false,
            };
            for (flag, path) in &files {
                if same(path, reference) {
                    return Err(Error::Io {
                        path: path.to_path_buf(),
                        message: format!("{flag} would overwrite the --reference file"),
                    });
                }
            }
        }
        Ok(())
    }
}
