//! The sweep's SVG plot: error against time, the Pareto front drawn and labelled.

use crate::cli::driver::{self};
use antiradiance::error::{Error, Result};
use antiradiance::output::{self};
use antiradiance::solve::SolverKind;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::io::Write;
use std::path::Path;

use super::*;

/// The plot's chart: log time axis, linear error axis (percent).
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<LogCoord<f64>, RangedCoordf64>>;

/// Draws error (percent) against solve time (log axis) into an SVG string.
pub(super) fn plot(
    title: &str,
    solver: SolverKind,
    axis: TimeAxis,
    results: &[RunResult],
) -> std::result::Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (960, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        // Runs without a time on this axis (CPU time unavailable) sit at the left edge.
        let times: Vec<f64> = results
            .iter()
            .map(|r| {
                let t = r.time(axis);
                if t.is_finite() {
                    t.max(1e-3)
                } else {
                    1e-3
                }
            })
            .collect();
        let errors: Vec<f64> = results.iter().map(|r| 100.0 * r.error).collect();
        let t_lo = times.iter().copied().fold(f64::INFINITY, f64::min) / 1.4;
        let t_hi = times.iter().copied().fold(0.0, f64::max) * 1.4;
        let e_hi = errors.iter().copied().fold(0.0, f64::max).max(1e-3) * 1.15;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d((t_lo..t_hi).log_scale(), 0.0..e_hi)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(axis.title())
            .y_desc("error vs path tracer (%)")
            .label_style(("sans-serif", 14))
            .x_label_formatter(&|x| short_number(*x))
            .y_label_formatter(&|y| short_number(*y))
            .draw()
            .map_err(|e| e.to_string())?;

        draw_runs(&mut chart, results, &times, &errors)?;
        let front = draw_front(&mut chart, results, &times, &errors)?;
        draw_labels(&chart, results, solver, &times, &errors, &front)?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// The runs at (`times`, `errors`), coloured by direct light; the front's points filled.
fn draw_runs(
    chart: &mut Chart,
    results: &[RunResult],
    times: &[f64],
    errors: &[f64],
) -> std::result::Result<(), String> {
    let off = RGBColor(40, 90, 200);
    let on = RGBColor(210, 60, 40);
    for (direct, colour, name) in [
        (false, off, "direct light off"),
        (true, on, "direct light on"),
    ] {
        let points: Vec<(f64, f64, bool)> = results
            .iter()
            .zip(times.iter().zip(errors))
            .filter(|(r, _)| r.spec.options.direct_light == direct)
            .map(|(r, (&t, &e))| (t, e, r.pareto))
            .collect();
        if points.is_empty() {
            continue;
        }
        chart
            .draw_series(points.iter().map(|&(t, e, front)| {
                let style = if front {
                    colour.filled()
                } else {
                    colour.stroke_width(2)
                };
                Circle::new((t, e), if front { 6 } else { 4 }, style)
            }))
            .map_err(|e| e.to_string())?
            .label(name)
            .legend(move |(x, y)| Circle::new((x, y), 5, colour.filled()));
    }
    Ok(())
}

/// The Pareto front as a line, in time order; returns its runs in that order.
fn draw_front(
    chart: &mut Chart,
    results: &[RunResult],
    times: &[f64],
    errors: &[f64],
) -> std::result::Result<Vec<usize>, String> {
    let mut front: Vec<usize> = (0..results.len()).filter(|&i| results[i].pareto).collect();
    front.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    chart
        .draw_series(LineSeries::new(
            front.iter().map(|&i| (times[i], errors[i])),
            BLACK.stroke_width(1),
        ))
        .map_err(|e| e.to_string())?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x - 10, y), (x + 10, y)], BLACK));
    Ok(front)
}

/// Labels: the front's first (full knob labels), then the other runs' numbers; each goes to
/// the first of four places around its point that overlaps no earlier label, and a run number
/// that finds no free place is left out.
fn draw_labels(
    chart: &Chart,
    results: &[RunResult],
    solver: SolverKind,
    times: &[f64],
    errors: &[f64],
    front: &[usize],
) -> std::result::Result<(), String> {
    let names = labels(results, solver);
    let mut order: Vec<usize> = front.to_vec();
    order.extend((0..results.len()).filter(|&i| !results[i].pareto));
    let mut taken: Vec<(i32, i32, i32, i32)> = Vec::new();
    for i in order {
        let on_front = results[i].pareto;
        let (px, py) = chart.backend_coord(&(times[i], errors[i]));
        // Candidates: the full label (front only), then the run number alone.
        let mut candidates = Vec::new();
        if on_front {
            candidates.push((format!("{} {}", i + 1, names[i]), 13));
        }
        candidates.push(((i + 1).to_string(), if on_front { 13 } else { 11 }));
        let placed = candidates.iter().find_map(|(text, size)| {
            free_place(&taken, (px, py), text, *size).map(|p| (text.clone(), *size, p))
        });
        let (text, size, (dx, dy, width, height)) = match placed {
            Some(p) => p,
            // A front point always gets its number, even over another label.
            None if on_front => {
                let text = (i + 1).to_string();
                let width = (0.62 * 13.0 * text.len() as f64).ceil() as i32;
                (text, 13, (7, -17, width, 15))
            }
            None => continue,
        };
        taken.push((px + dx, py + dy, px + dx + width, py + dy + height));
        let colour = if on_front {
            BLACK
        } else {
            RGBColor(120, 120, 120)
        };
        let style = ("sans-serif", size).into_font().color(&colour);
        chart
            .plotting_area()
            .draw(&(EmptyElement::at((times[i], errors[i])) + Text::new(text, (dx, dy), style)))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The first of four places around the point at pixel `(px, py)` where `text` at font size
/// `size` overlaps none of the `taken` boxes: its offset and size `(dx, dy, width, height)`.
fn free_place(
    taken: &[(i32, i32, i32, i32)],
    (px, py): (i32, i32),
    text: &str,
    size: i32,
) -> Option<(i32, i32, i32, i32)> {
    let width = (0.62 * size as f64 * text.chars().count() as f64).ceil() as i32;
    let height = size + 2;
    let places = [
        (7, -height - 2),
        (7, 3),
        (-7 - width, -height - 2),
        (-7 - width, 3),
    ];
    places
        .into_iter()
        .find(|&(dx, dy)| {
            let (x0, y0) = (px + dx, py + dy);
            !taken
                .iter()
                .any(|&(a0, b0, a1, b1)| x0 < a1 && a0 < x0 + width && y0 < b1 && b0 < y0 + height)
        })
        .map(|(dx, dy)| (dx, dy, width, height))
}

/// A tick label: 3 significant digits at most, no trailing zeros (`0.3`, `1.25`, `12`).
pub(super) fn short_number(x: f64) -> String {
    if !(x.is_finite() && x != 0.0) {
        return "0".to_string();
    }
    let decimals = (2 - x.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let text = format!("{x:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// Writes the plot (atomically).
pub(super) fn write_svg(
    path: &Path,
    title: &str,
    solver: SolverKind,
    axis: TimeAxis,
    results: &[RunResult],
) -> Result<()> {
    let svg = plot(title, solver, axis, results).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        message: format!("cannot draw the plot: {}", driver::one_line(&e)),
    })?;
    output::write_atomic(path, |w| w.write_all(svg.as_bytes()))
}
