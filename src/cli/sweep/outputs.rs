//! The sweep's outputs: the CSV, the table on stdout, and the runs described in words for the
//! progress lines and the plot's labels.

use std::io::Write;
use std::path::Path;

use super::*;
use antiradiance::error::Result;
use antiradiance::output::{self, format_f64};
use antiradiance::solve::SolverKind;

/// A run's knobs in words, for progress lines.
pub(super) fn describe(spec: &RunSpec, solver: SolverKind) -> String {
    let o = &spec.options;
    let mut s = format!("preset {}, bins {}", spec.preset.name(), o.bins);
    if solver == SolverKind::Hierarchical {
        s += &format!(", epsilon {}", o.epsilon);
    }
    s += &format!(
        ", tol {:e}, max iterations {}, direct light {}",
        o.tol,
        o.max_iterations,
        if o.direct_light { "on" } else { "off" }
    );
    s
}

/// Short labels of the runs for the plot: only the knobs that vary across the sweep
/// (`b` bins, `e` epsilon, `t` tolerance, `n` iteration cap, `DL` direct light on).
pub(super) fn labels(results: &[RunResult], solver: SolverKind) -> Vec<String> {
    type Part = fn(&RunResult) -> String;
    let mut parts: Vec<Part> = vec![|r| r.spec.preset.name().to_string(), |r| {
        format!("b{}", r.spec.options.bins)
    }];
    if solver == SolverKind::Hierarchical {
        parts.push(|r| format!("e{}", r.spec.options.epsilon));
    }
    parts.push(|r| format!("t{:e}", r.spec.options.tol));
    parts.push(|r| format!("n{}", r.spec.options.max_iterations));
    parts.push(|r| {
        if r.spec.options.direct_light {
            "DL".to_string()
        } else {
            String::new()
        }
    });
    let varying: Vec<Part> = match results.first() {
        Some(first) => parts
            .into_iter()
            .filter(|f| results.iter().any(|r| f(r) != f(first)))
            .collect(),
        None => Vec::new(),
    };
    results
        .iter()
        .map(|r| {
            varying
                .iter()
                .map(|f| f(r))
                .filter(|s| !s.is_empty())
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect()
}

/// Writes the CSV (atomically): [`CSV_HEADER`], then one row per run in run order.
pub(super) fn write_csv(path: &Path, solver: SolverKind, results: &[RunResult]) -> Result<()> {
    output::write_atomic(path, |w| {
        writeln!(w, "{CSV_HEADER}")?;
        for (i, r) in results.iter().enumerate() {
            let o = &r.spec.options;
            writeln!(
                w,
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                i + 1,
                r.spec.preset.name(),
                solver.name(),
                if solver == SolverKind::Hierarchical {
                    format_f64(o.epsilon)
                } else {
                    String::new()
                },
                o.bins,
                format_f64(o.tol),
                o.max_iterations,
                u8::from(o.direct_light),
                format_f64(r.seconds),
                r.cpu_seconds.map(|c| format!("{c:.2}")).unwrap_or_default(),
                r.iterations,
                u8::from(r.converged),
                format_f64(r.residual),
                r.links,
                r.peak_memory_delta_bytes
                    .map(|b| b.to_string())
                    .unwrap_or_default(),
                format_f64(r.negative_fraction),
                format_f64(r.error),
                u8::from(r.pareto)
            )?;
        }
        Ok(())
    })
}

/// The table printed on stdout.
pub(super) fn table(solver: SolverKind, results: &[RunResult]) -> String {
    let mut out = format!(
        "{:>4} {:<9} {:>8} {:>5} {:>8} {:>6} {:>7} {:>10} {:>8} {:>6} {:>12} {:>10} {:>9}\n",
        "run",
        "preset",
        "epsilon",
        "bins",
        "tol",
        "cap",
        "direct",
        "time (s)",
        "cpu (s)",
        "iter",
        "links",
        "peak mem",
        "error"
    );
    for (i, r) in results.iter().enumerate() {
        let o = &r.spec.options;
        out += &format!(
            "{:>4} {:<9} {:>8} {:>5} {:>8.1e} {:>6} {:>7} {:>10.3} {:>8} {:>6} {:>12} {:>10} {:>8.3}%{}\n",
            i + 1,
            r.spec.preset.name(),
            if solver == SolverKind::Hierarchical {
                format!("{}", o.epsilon)
            } else {
                "-".into()
            },
            o.bins,
            o.tol,
            o.max_iterations,
            if o.direct_light { "on" } else { "off" },
            r.seconds,
            r.cpu_seconds
                .map(|c| format!("{c:.2}"))
                .unwrap_or_else(|| "n/a".into()),
            if r.converged {
                r.iterations.to_string()
            } else if r.failed {
                format!("{}x", r.iterations)
            } else {
                format!("{}!", r.iterations)
            },
            r.links,
            r.peak_memory_delta_bytes
                .map(antiradiance::memory::format_bytes)
                .unwrap_or_else(|| "n/a".into()),
            100.0 * r.error,
            if r.pareto { "  *" } else { "" }
        );
    }
    out += "* = on the Pareto front (no other run is both faster and more accurate on the chosen \
            time axis); ! = stopped at the iteration cap; x = failed (diverged: its error \
            measures no solution)\n";
    out
}
