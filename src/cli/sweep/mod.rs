//! `antiradiance sweep`: the speed/accuracy trade of the solver's knobs, measured.
//!
//! The command runs the chosen solver once per point of a grid of knob values (presets,
//! direct-light on/off, bins, epsilon, tolerance, iteration cap), measures each run's solve time,
//! iterations, links and peak memory, and its error against the path tracer (the design note's
//! area-weighted relative L1 error over non-emissive triangles), then writes
//!
//! - a CSV, one row per run ([`CSV_HEADER`]), with a `pareto` column marking the runs no other run
//!   beats in both time and error;
//! - optionally an SVG plot of error against time (log time axis) with the Pareto front drawn as
//!   a line and its points labelled;
//! - a table on stdout.
//!
//! Like every command it checks every parameter and output path first, and writes nothing
//! before every run is done (each writer is atomic).

mod grid;
mod outputs;
mod plot;

use grid::*;
use outputs::*;
use plot::*;
use std::io::Write;
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use crate::cli::driver::{self, Loaded, SceneArgs, Timings};
use crate::cli::flags::flagged;
use antiradiance::error::{Error, Result};
use antiradiance::output;
use antiradiance::reference::ReferenceOptions;
use antiradiance::solve::solution::{relative_error, Solution};
use antiradiance::solve::SolverKind;
use antiradiance::solve::SolverOptions;

/// The exact header line of the sweep CSV (without the line break).
pub const CSV_HEADER: &str = "run,preset,solver,epsilon,bins,tol,max_iterations,direct_light,\
seconds,cpu_seconds,iterations,converged,residual,links,peak_memory_delta_bytes,negative_fraction,\
error,pareto";

/// Most runs one sweep may have (a guard against a grid that would run for days).
pub const MAX_RUNS: usize = 1000;

/// Which time the Pareto front and the plot use.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeAxis {
    /// Wall-clock seconds of each solve.
    Wall,
    /// CPU seconds of each solve, all threads (Linux): steadier than wall-clock time on a
    /// machine shared with other jobs.
    Cpu,
}

impl TimeAxis {
    /// The axis title of the plot.
    fn title(self) -> &'static str {
        match self {
            TimeAxis::Wall => "solve time (wall-clock s, log scale)",
            TimeAxis::Cpu => "solve time (CPU s, all threads, log scale)",
        }
    }
}

/// `antiradiance sweep`: runs the solver over a grid of knob values and measures each run's
/// time and error against the path tracer.
///
/// Every knob takes a comma-separated LIST; the word `preset` in a list stands for the value of
/// the preset being run. The grid is the product of all lists.
#[derive(Args, Clone, Debug)]
pub struct SweepArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Solver to sweep (with dense, --epsilon does not apply: one run per other combination).
    #[arg(long, value_enum, default_value_t = SolverKind::Hierarchical, help_heading = "Sweep options")]
    pub solver: SolverKind,
    /// Presets the runs start from: LIST of fast, default, accurate.
    #[arg(
        long,
        value_name = "LIST",
        default_value = "default",
        help_heading = "Sweep options"
    )]
    pub preset: String,
    /// Link refinement thresholds (LIST of numbers >= 0, or `preset`).
    #[arg(
        long,
        value_name = "LIST",
        default_value = "0.25,0.5,1,2",
        allow_hyphen_values = true,
        help_heading = "Sweep options"
    )]
    pub epsilon: String,
    /// Direction bins per side of the octahedral map (LIST of integers, or `preset`).
    #[arg(
        long,
        value_name = "LIST",
        allow_hyphen_values = true,
        default_value = "6,8,12",
        help_heading = "Sweep options"
    )]
    pub bins: String,
    /// Convergence tolerances (LIST of numbers in (0, 1), or `preset`).
    #[arg(
        long,
        value_name = "LIST",
        allow_hyphen_values = true,
        default_value = "preset",
        help_heading = "Sweep options"
    )]
    pub tol: String,
    /// Iteration caps (LIST of integers >= 1, or `preset`).
    #[arg(
        long,
        value_name = "LIST",
        allow_hyphen_values = true,
        default_value = "preset",
        help_heading = "Sweep options"
    )]
    pub max_iterations: String,
    /// Exact direct light (LIST of off, on).
    #[arg(
        long,
        value_name = "LIST",
        default_value = "off,on",
        help_heading = "Sweep options"
    )]
    pub direct_light: String,
    /// Split depth of the hierarchical solver for every run (default: the preset's).
    #[arg(long, value_name = "D", help_heading = "Sweep options")]
    pub split_depth: Option<u8>,
    /// Antiradiance from both sides of every surface, in every run.
    #[arg(long, help_heading = "Sweep options")]
    pub two_sided_antiradiance: bool,
    /// Memory limit of every run (bytes, or with a suffix K, M, G, T: 512M, 4G); a run whose
    /// model would not fit is coarsened, with a warning. Default: half the physical memory.
    #[arg(
        long,
        value_name = "SIZE",
        value_parser = driver::parse_memory_limit,
        allow_hyphen_values = true,
        help_heading = "Sweep options"
    )]
    pub memory_limit: Option<u64>,
    /// Per-triangle reference radiance: a CSV written by `antiradiance reference ...
    /// --triangles REF.csv` on the same scene with the same scene options.
    #[arg(long, value_name = "REF.csv", help_heading = "Reference")]
    pub reference: Option<PathBuf>,
    /// Compute the reference with the path tracer at N samples per patch instead.
    #[arg(long, value_name = "N", help_heading = "Reference")]
    pub reference_spp: Option<usize>,
    /// Seed of the path tracer (with --reference-spp).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 1,
        help_heading = "Reference"
    )]
    pub seed: u64,
    /// Also write the reference computed with --reference-spp (per-triangle CSV), to reuse it
    /// with --reference.
    #[arg(long, value_name = "OUT.csv", help_heading = "Reference")]
    pub save_reference: Option<PathBuf>,
    /// The results, one row per run.
    #[arg(long, value_name = "OUT.csv", help_heading = "Output options")]
    pub csv: PathBuf,
    /// Plot of error against solve time with the Pareto front.
    #[arg(long, value_name = "OUT.svg", help_heading = "Output options")]
    pub svg: Option<PathBuf>,
    /// Run the whole grid N times, round by round, and keep each run's shortest time (timings
    /// on a busy machine are noisy; the results of the repeats are identical).
    #[arg(
        long,
        value_name = "N",
        default_value_t = 1,
        help_heading = "Sweep options"
    )]
    pub repeat: usize,
    /// Time used for the Pareto front and the plot (both are in the CSV).
    #[arg(long, value_enum, default_value_t = TimeAxis::Wall, help_heading = "Sweep options")]
    pub time_axis: TimeAxis,
    /// No progress bars and no per-run lines (the table is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

// ---------------------------------------------------------------------------------------------
// Running

/// The measurements of one run.
#[derive(Clone, Debug)]
pub struct RunResult {
    /// What was run.
    pub spec: RunSpec,
    /// Wall-clock seconds of the solve (tree, links, direct light and iterations; not loading),
    /// the shortest of the `--repeat` rounds.
    pub seconds: f64,
    /// CPU seconds of the solve, all threads (Linux only), the shortest of the rounds.
    pub cpu_seconds: Option<f64>,
    /// Iterations performed.
    pub iterations: usize,
    /// True when the tolerance was met before the iteration cap.
    pub converged: bool,
    /// Final relative residual.
    pub residual: f64,
    /// Transport links.
    pub links: u64,
    /// Peak resident memory during the solve above the memory before it, bytes (Linux only;
    /// the largest of the `--repeat` rounds). Memory the allocator kept from an earlier run
    /// is not counted again, so small runs may show 0.
    pub peak_memory_delta_bytes: Option<u64>,
    /// Negative radiance mass relative to the positive mass (before clamping).
    pub negative_fraction: f64,
    /// Design-note error against the reference (fraction, not percent).
    pub error: f64,
    /// True when no other run is at least as fast and as accurate and better in one of them.
    pub pareto: bool,
    /// True when the solve failed its health checks ([`antiradiance::solve::health`]): `converged` is false,
    /// `error` measures a result that is not a solution, and the run is never on the front.
    pub failed: bool,
}

impl RunResult {
    /// The run's time on the chosen axis (NaN when CPU time is unknown).
    pub fn time(&self, axis: TimeAxis) -> f64 {
        match axis {
            TimeAxis::Wall => self.seconds,
            TimeAxis::Cpu => self.cpu_seconds.unwrap_or(f64::NAN),
        }
    }
}

/// CPU time (user + system, all threads) this process has used so far, in clock ticks of
/// 1/100 s (Linux's `USER_HZ` on every common architecture), from `/proc/self/stat` (fields 14
/// and 15). `None` off Linux or when the file cannot be read.
pub fn process_cpu_ticks() -> Option<u64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: split after it.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // `fields[0]` is field 3 (state), so field n is `fields[n - 3]`.
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

/// Seconds of CPU time between two readings of [`process_cpu_ticks`] (resolution 10 ms; equal
/// tick counts give bit-identical seconds).
fn cpu_seconds_between(before: Option<u64>, after: Option<u64>) -> Option<f64> {
    match (before, after) {
        (Some(a), Some(b)) => Some(b.saturating_sub(a) as f64 / 100.0),
        _ => None,
    }
}

/// For points (seconds, error), true where no other point is at least as good in both and
/// strictly better in one: the Pareto front of the speed/accuracy trade. NaN points are never on
/// the front and never dominate.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    let valid = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    points
        .iter()
        .map(|p| {
            valid(p)
                && !points
                    .iter()
                    .any(|q| valid(q) && q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1))
        })
        .collect()
}

/// The reference solution per input triangle: read from `--reference` (checked against the
/// scene's triangle count) or computed with the path tracer.
fn reference_radiance(
    args: &SweepArgs,
    loaded: &Loaded,
    file: Option<Vec<[f64; 3]>>,
) -> Result<Vec<[f64; 3]>> {
    if let Some(values) = file {
        if values.len() != loaded.scene.len() {
            let path = args.reference.clone().unwrap_or_default();
            return Err(Error::Parameter(format!(
                "{}: {} rows but the scene has {} triangles (was it written for the same scene and --max-edge?)",
                path.display(),
                values.len(),
                loaded.scene.len()
            )));
        }
        return Ok(values);
    }
    let options = ReferenceOptions {
        spp: args.reference_spp.unwrap_or(1),
        seed: args.seed,
        ..ReferenceOptions::default()
    };
    let truth: Solution = driver::run_reference(&loaded.patches, &options, args.quiet);
    if let Some(path) = &args.save_reference {
        output::write_triangles_csv(path, &loaded.scene, &truth)?;
    }
    Ok(truth.triangle_radiance)
}

/// `antiradiance sweep`.
pub fn sweep(args: &SweepArgs) -> Result<()> {
    // 1. Check every parameter and path; read the reference file (a bad one fails before the
    //    scene is even loaded).
    args.scene.validate()?;
    let runs = args.runs()?;
    args.check_files()?;
    let reference_file = match &args.reference {
        Some(path) => Some(output::read_triangles_csv(path)?),
        None => None,
    };

    // 2. Load the scene and get the reference.
    let mut timings = Timings::default();
    let loaded = driver::load(&args.scene, &mut timings)?;
    let truth = reference_radiance(args, &loaded, reference_file)?;

    // 3. Run the grid and mark the Pareto front.
    let mut results = run_grid(args, &runs, &loaded, &truth)?;
    mark_pareto_front(&mut results, args.time_axis);

    // 4. Outputs: CSV, plot, table.
    write_csv(&args.csv, args.solver, &results)?;
    if let Some(path) = &args.svg {
        write_svg(
            path,
            &plot_title(args),
            args.solver,
            args.time_axis,
            &results,
        )?;
    }
    let mut stdout = std::io::stdout().lock();
    // A closed pipe (`| head`) is not an error worth a message.
    let _ = stdout.write_all(table(args.solver, &results).as_bytes());
    let _ = stdout.flush();
    Ok(())
}

/// Runs the grid, one solve at a time (each solve uses every core), and measures each run
/// against `truth` (per input triangle). With --repeat, the whole grid runs again round by
/// round, so that a burst of load from other jobs hits every run alike; each run keeps its
/// shortest time and its largest memory figure. The results are in grid order, off the front.
fn run_grid(
    args: &SweepArgs,
    runs: &[RunSpec],
    loaded: &Loaded,
    truth: &[[f64; 3]],
) -> Result<Vec<RunResult>> {
    let areas: Vec<f64> = (0..loaded.scene.len())
        .map(|t| loaded.scene.area(t))
        .collect();
    let emissive: Vec<bool> = (0..loaded.scene.len())
        .map(|t| loaded.scene.is_emitter(t))
        .collect();
    let mut overall_peak = None;
    let total = runs.len();
    let mut results: Vec<RunResult> = Vec::with_capacity(total);
    for round in 0..args.repeat {
        for (i, spec) in runs.iter().enumerate() {
            let cpu_before = process_cpu_ticks();
            let (solution, seconds, delta) = driver::measured(&mut overall_peak, || {
                driver::run_solver(args.solver, &loaded.patches, &spec.options, args.quiet)
            });
            let solution = solution?;
            if round == 0 {
                if let Some(w) =
                    antiradiance::solve::warnings::memory_warning(solution.stats.memory.as_ref())
                {
                    eprintln!(
                        "warning: run {}/{}: {}",
                        i + 1,
                        runs.len(),
                        flagged(&w.to_string())
                    );
                }
            }
            let cpu_seconds = cpu_seconds_between(cpu_before, process_cpu_ticks());
            if round > 0 {
                keep_best(&mut results[i], seconds, cpu_seconds, delta);
                continue;
            }
            let error = relative_error(&areas, &emissive, &solution.triangle_radiance, truth);
            let s = &solution.stats;
            // A failed run stays in the table (converged 0) and off the Pareto front.
            if let Err(e) = s.check(args.solver.name()) {
                eprintln!(
                    "warning: run {}/{}: {}",
                    i + 1,
                    total,
                    flagged(&e.to_string())
                );
            }
            let result = RunResult {
                spec: spec.clone(),
                seconds,
                cpu_seconds,
                iterations: s.iterations,
                converged: s.converged,
                residual: s.residual,
                links: s.links,
                peak_memory_delta_bytes: delta,
                negative_fraction: s.negative_fraction,
                error,
                pareto: false,
                failed: s.failure.is_some(),
            };
            if !args.quiet {
                eprintln!(
                    "run {}/{}: {} -> {:.3} s ({} CPU s), {} iterations, error {:.3}%",
                    i + 1,
                    total,
                    describe(&result.spec, args.solver),
                    seconds,
                    cpu_seconds
                        .map(|c| format!("{c:.2}"))
                        .unwrap_or_else(|| "n/a".into()),
                    result.iterations,
                    100.0 * error
                );
            }
            results.push(result);
        }
    }
    Ok(results)
}

/// A repeat of run `r` (a later `--repeat` round): keeps the shorter times and the larger
/// memory figure.
fn keep_best(r: &mut RunResult, seconds: f64, cpu_seconds: Option<f64>, delta: Option<u64>) {
    r.seconds = r.seconds.min(seconds);
    r.cpu_seconds = match (r.cpu_seconds, cpu_seconds) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    r.peak_memory_delta_bytes = r.peak_memory_delta_bytes.max(delta);
}

/// Sets `pareto` on the runs of the Pareto front of time on `axis` against error; a failed run
/// is never on it.
fn mark_pareto_front(results: &mut [RunResult], axis: TimeAxis) {
    let front = pareto_front(
        &results
            .iter()
            .map(|r| {
                let error = if r.failed { f64::INFINITY } else { r.error };
                (r.time(axis), error)
            })
            .collect::<Vec<_>>(),
    );
    for (r, on_front) in results.iter_mut().zip(front) {
        r.pareto = on_front && !r.failed;
    }
}

/// The plot's title: the scene's file name with the scene options that change it, and the
/// solver.
fn plot_title(args: &SweepArgs) -> String {
    let mut scene_label = args
        .scene
        .scene
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if let Some(y) = args.scene.emit_above {
        scene_label += &format!(" --emit-above {y}");
    }
    if let Some(l) = args.scene.max_edge {
        scene_label += &format!(" --max-edge {l}");
    }
    format!(
        "{scene_label}: error vs solve time ({} solver)",
        args.solver.name()
    )
}

#[cfg(test)]
mod tests;
