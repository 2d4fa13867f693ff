//! The summary text on stdout and the one-line messages on stderr.

use crate::cli::flags::flagged;
use antiradiance::error::Warning;
use antiradiance::memory::format_bytes;
use antiradiance::reference::ReferenceOptions;
use antiradiance::solve::solution::{Solution, SolveStats};
use antiradiance::solve::{SolverKind, SolverOptions};
use std::path::Path;

use crate::cli::driver::*;

/// Prints `warning: ...` on stderr: the warning on one line, naming flags.
pub fn print_warning(w: &Warning) {
    eprintln!("warning: {}", one_line(&flagged(&w.to_string())));
}

/// A message on one line (line breaks become spaces).
pub fn one_line(text: &str) -> String {
    text.split(['\n', '\r'])
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// `n` and the noun in singular or plural (`plural(2, "patch", "patches")`).
pub(crate) fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

pub(crate) fn scene_phrase(loaded: &Loaded) -> String {
    let c = Counts::of(loaded);
    let mut s = plural(c.input_triangles, "triangle", "triangles");
    if c.patches != c.input_triangles {
        s += &format!(" ({} patches)", c.patches);
    }
    s
}

pub(crate) fn time_phrase(t: &Timings, peak: Option<u64>) -> String {
    let mut s = format!(
        "in {:.2} s (load {:.2} s, build {:.2} s, solve {:.2} s, output {:.2} s)",
        t.total, t.load, t.build, t.solve, t.output
    );
    if let Some(p) = peak {
        s += &format!(", peak memory {}", format_bytes(p));
    }
    s
}

/// The paragraph `solve` prints on stderr when done.
pub fn solve_summary(
    solver: &str,
    loaded: &Loaded,
    stats: &SolveStats,
    options: &SolverOptions,
    timings: &Timings,
    peak: Option<u64>,
) -> String {
    let convergence = if stats.converged {
        format!(
            "converged after {} (residual {:.2e})",
            plural(stats.iterations, "iteration", "iterations"),
            stats.residual
        )
    } else {
        format!(
            "stopped at the iteration cap ({}) with residual {:.2e} (tolerance {:.1e})",
            stats.iterations, stats.residual, options.tol
        )
    };
    let negative = if stats.negative_patches == 0 {
        "no negative radiance".to_string()
    } else {
        format!(
            "negative radiance {:.3}% of the positive mass on {} ({})",
            100.0 * stats.negative_fraction,
            plural(stats.negative_patches, "patch", "patches"),
            if options.clamp_negative {
                "clamped to 0"
            } else {
                "kept"
            }
        )
    };
    format!(
        "Solved {} with the {solver} solver {}; {convergence}; {negative}; {} links.",
        scene_phrase(loaded),
        time_phrase(timings, peak),
        stats.links
    )
}

/// The paragraph `reference` prints on stderr when done.
pub fn reference_summary(
    loaded: &Loaded,
    options: &ReferenceOptions,
    stats: &SolveStats,
    timings: &Timings,
    peak: Option<u64>,
) -> String {
    format!(
        "Path-traced {} with {} samples per patch (seed {}) {}; {} iterations.",
        scene_phrase(loaded),
        options.spp,
        options.seed,
        time_phrase(timings, peak),
        stats.iterations
    )
}

pub(crate) fn percent(x: f64) -> String {
    format!("{:.3}%", 100.0 * x)
}

pub(crate) fn compare_table(
    loaded: &Loaded,
    scene_path: &Path,
    runs: &[(SolverKind, Solution, f64, Option<u64>)],
    results: &[(SolverKind, CompareRun)],
    between: f64,
    reference: &Option<(Solution, f64, Option<u64>)>,
) -> String {
    let c = Counts::of(loaded);
    let mut out = format!(
        "{}: {}, {} patches, {}\n",
        scene_path.display(),
        plural(c.input_triangles, "triangle", "triangles"),
        c.patches,
        plural(c.emitters, "emitter", "emitters")
    );
    let mut header = format!(
        "{:<13} {:>10} {:>12} {:>12} {:>10} {:>10}",
        "solver", "time (s)", "peak mem", "links", "iterations", "residual"
    );
    if reference.is_some() {
        header += &format!(" {:>12}", "vs reference");
    }
    out += &header;
    out.push('\n');
    let mem = |d: Option<u64>| d.map(format_bytes).unwrap_or_else(|| "n/a".into());
    for ((kind, solution, seconds, delta), (_, run)) in runs.iter().zip(results) {
        let s = &solution.stats;
        let mut line = format!(
            "{:<13} {:>10.3} {:>12} {:>12} {:>10} {:>10.2e}",
            kind.name(),
            seconds,
            mem(*delta),
            s.links,
            if s.converged {
                s.iterations.to_string()
            } else if s.failure.is_some() {
                format!("{} (failed)", s.iterations)
            } else {
                format!("{} (cap)", s.iterations)
            },
            s.residual
        );
        if let Some(e) = run.error_vs_reference {
            line += &format!(" {:>12}", percent(e));
        }
        out += &line;
        out.push('\n');
    }
    if let Some((solution, seconds, delta)) = reference {
        out += &format!(
            "{:<13} {:>10.3} {:>12} {:>12} {:>10} {:>10}\n",
            "reference",
            seconds,
            mem(*delta),
            "-",
            format!("{} spp", solution.stats.iterations),
            "-"
        );
    }
    out += &format!(
        "hierarchical vs dense (area-weighted relative L1, non-emissive): {}\n",
        percent(between)
    );
    out
}
