//! `antiradiance solve`, `reference` and `compare`: check, load, solve, write, report.

use antiradiance::error::{Error, Result};
use antiradiance::memory;
use antiradiance::reference::ReferenceOptions;
use antiradiance::solve::solution::{self};
use antiradiance::solve::warnings::solve_warnings;
use antiradiance::solve::SolverKind;
use serde::Serialize;
use serde_json::{json, Map, Value};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

use crate::cli::driver::*;

/// `antiradiance solve`.
pub fn solve(args: &SolveArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    let options = antiradiance::solve::SolverOptions {
        keep_elements: args.output.elements.is_some(),
        ..args.solver_args.options()?
    };
    args.output.validate(&args.scene.scene)?;

    let loaded = load(&args.scene, &mut timings)?;
    let solution = timed(&mut timings.solve, || {
        run_solver(args.solver, &loaded.patches, &options, args.quiet)
    })?;
    let cap = solve_warnings(args.solver, &solution.stats, &options, &loaded.patches);
    for w in &cap {
        print_warning(w);
    }
    // A failed solve writes no result (picture, PLY, CSV); its report says why.
    let failed = solution.stats.check(args.solver.name());
    if failed.is_ok() {
        timed(&mut timings.output, || {
            write_outputs(&args.output, &loaded, &solution)
        })?;
    }
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();

    if let Some(path) = &args.output.report {
        let mut report = Report::new("solve", &args.scene.scene, &loaded);
        report
            .add_warnings(cap)
            .insert(
                "parameters",
                json!({
                    "solver": args.solver,
                    "preset": args.solver_args.preset_name(),
                    "solver_options": options,
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("stats", stats_json(&solution.stats, &loaded))
            .finish(&timings, peak);
        report.write(path)?;
    }
    failed?;
    if !args.quiet {
        eprintln!(
            "{}",
            solve_summary(
                args.solver.name(),
                &loaded,
                &solution.stats,
                &options,
                &timings,
                peak
            )
        );
    }
    Ok(())
}

/// `antiradiance reference`.
pub fn reference(args: &ReferenceArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    if args.spp == 0 {
        return Err(Error::Parameter("--spp must be at least 1".into()));
    }
    args.output.validate(&args.scene.scene)?;
    let options = ReferenceOptions {
        spp: args.spp,
        seed: args.seed,
        ..ReferenceOptions::default()
    };

    let loaded = load(&args.scene, &mut timings)?;
    let solution = timed(&mut timings.solve, || {
        run_reference(&loaded.patches, &options, args.quiet)
    });
    timed(&mut timings.output, || {
        write_outputs(&args.output, &loaded, &solution)
    })?;
    timings.total = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();

    if let Some(path) = &args.output.report {
        let mut report = Report::new("reference", &args.scene.scene, &loaded);
        report
            .insert(
                "parameters",
                json!({
                    "solver": "reference",
                    "reference_options": {
                        "spp": options.spp,
                        "seed": options.seed,
                        "max_depth": options.max_depth,
                    },
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("stats", stats_json(&solution.stats, &loaded))
            .finish(&timings, peak);
        report.write(path)?;
    }
    if !args.quiet {
        eprintln!(
            "{}",
            reference_summary(&loaded, &options, &solution.stats, &timings, peak)
        );
    }
    Ok(())
}

/// One solver's run in `compare`.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRun {
    /// Wall-clock seconds of the solve.
    pub seconds: f64,
    /// Peak resident memory during the solve above the resident memory before it, in bytes
    /// (`None` when the peak cannot be measured per stage, e.g. off Linux).
    pub peak_memory_delta_bytes: Option<u64>,
    /// The solver's statistics.
    pub stats: Value,
    /// Design-note error against the path tracer (when it was run).
    pub error_vs_reference: Option<f64>,
}

/// Runs `f` and measures its time and peak memory above the resident memory before it.
/// `overall_peak` keeps the process's peak across the resets this needs.
pub fn measured<T>(overall_peak: &mut Option<u64>, f: impl FnOnce() -> T) -> (T, f64, Option<u64>) {
    *overall_peak = (*overall_peak).max(memory::peak_rss_bytes());
    let reset = memory::reset_peak_rss();
    let base = memory::current_rss_bytes();
    let start = Instant::now();
    let value = f();
    let seconds = start.elapsed().as_secs_f64();
    let peak = memory::peak_rss_bytes();
    *overall_peak = (*overall_peak).max(peak);
    let delta = match (reset, base, peak) {
        (true, Some(b), Some(p)) => Some(p.saturating_sub(b)),
        _ => None,
    };
    (value, seconds, delta)
}

/// `antiradiance compare`: prints a table on stdout.
pub fn compare(args: &CompareArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    args.scene.validate()?;
    let options = args.solver_args.options()?;
    if args.reference_spp == Some(0) {
        return Err(Error::Parameter(
            "--reference-spp must be at least 1".into(),
        ));
    }
    let report_files: Vec<(&str, &Path)> = args
        .report
        .iter()
        .map(|p| ("--report", p.as_path()))
        .collect();
    check_outputs(&report_files, &args.scene.scene)?;

    let loaded = load(&args.scene, &mut timings)?;
    let mut overall_peak = None;
    let mut runs = Vec::new();
    let mut cap_warnings = Vec::new();
    for kind in [SolverKind::Dense, SolverKind::Hierarchical] {
        let (solution, seconds, delta) = measured(&mut overall_peak, || {
            run_solver(kind, &loaded.patches, &options, args.quiet)
        });
        let solution = solution?;
        timings.solve += seconds;
        for w in solve_warnings(kind, &solution.stats, &options, &loaded.patches) {
            print_warning(&w);
            cap_warnings.push(w);
        }
        // A failed solve makes the comparison meaningless: no table, no report.
        solution.stats.check(kind.name())?;
        runs.push((kind, solution, seconds, delta));
    }
    let reference_options = args.reference_spp.map(|spp| ReferenceOptions {
        spp,
        seed: args.seed,
        ..ReferenceOptions::default()
    });
    let reference = reference_options.as_ref().map(|ro| {
        let (solution, seconds, delta) = measured(&mut overall_peak, || {
            run_reference(&loaded.patches, ro, args.quiet)
        });
        timings.solve += seconds;
        (solution, seconds, delta)
    });
    let between = solution::error_against(&loaded.scene, &runs[1].1, &runs[0].1);
    timings.total = start.elapsed().as_secs_f64();
    overall_peak = overall_peak.max(memory::peak_rss_bytes());

    let mut results: Vec<(SolverKind, CompareRun)> = Vec::new();
    for (kind, solution, seconds, delta) in &runs {
        results.push((
            *kind,
            CompareRun {
                seconds: *seconds,
                peak_memory_delta_bytes: *delta,
                stats: stats_json(&solution.stats, &loaded),
                error_vs_reference: reference
                    .as_ref()
                    .map(|r| solution::error_against(&loaded.scene, solution, &r.0)),
            },
        ));
    }

    let table = compare_table(
        &loaded,
        &args.scene.scene,
        &runs,
        &results,
        between,
        &reference,
    );
    let mut stdout = std::io::stdout().lock();
    // A closed pipe (`| head`) is not an error worth a message.
    let _ = stdout.write_all(table.as_bytes());
    let _ = stdout.flush();

    if let Some(path) = &args.report {
        let mut solvers = Map::new();
        for (kind, run) in &results {
            solvers.insert(
                kind.name().to_string(),
                serde_json::to_value(run).unwrap_or(Value::Null),
            );
        }
        let reference_json = match (&reference, &reference_options) {
            (Some((solution, seconds, delta)), Some(ro)) => json!({
                "spp": ro.spp,
                "seed": ro.seed,
                "seconds": seconds,
                "peak_memory_delta_bytes": delta,
                "stats": stats_json(&solution.stats, &loaded),
            }),
            _ => Value::Null,
        };
        let mut report = Report::new("compare", &args.scene.scene, &loaded);
        report
            .add_warnings(cap_warnings)
            .insert(
                "parameters",
                json!({
                    "preset": args.solver_args.preset_name(),
                    "solver_options": options,
                    "scene_options": args.scene.to_json(),
                }),
            )
            .insert("solvers", solvers)
            .insert("reference", reference_json)
            .insert("hierarchical_vs_dense_error", between)
            .finish(&timings, overall_peak);
        report.write(path)?;
    }
    Ok(())
}
