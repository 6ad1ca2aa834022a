//! SVG charts of a run trace (plotters): the space-time diagram, the territory map and the
//! rollback heat map. SVG needs no fonts installed, and any browser or paper tool opens it.

use crate::app::output::counted;
use crate::kernel::RunTrace;
use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Turns a plotters error (not always `Send`) into an error naming the chart.
fn drawing<T, E: std::fmt::Display>(r: std::result::Result<T, E>, what: &Path) -> Result<T> {
    r.map_err(|e| anyhow!("cannot draw {}: {e}", what.display()))
}

/// Draws an SVG image in memory with `draw` and writes it to `path` through a temporary
/// file renamed into place (never a half-written chart).
fn svg_file(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Result<()>,
) -> Result<()> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw(&root)?;
        drawing(root.present(), path)?;
    }
    super::atomic::write(path, svg.as_bytes())
}

/// A world's colour (the same in every chart).
fn world_colour(w: u32) -> RGBColor {
    let c = Palette99::pick(w as usize).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Each world's LVT against wall time (rollbacks show as drops) and the GVT line.
pub fn space_time(trace: &RunTrace, path: &Path) -> Result<()> {
    svg_file(path, (900, 560), |root| {
        drawing(root.fill(&WHITE), path)?;
        let t_max = trace
            .lvt
            .iter()
            .map(|s| s.time)
            .chain(trace.gvt.iter().map(|g| g.time))
            .fold(1e-6, f64::max);
        let s_max = trace
            .lvt
            .iter()
            .map(|s| s.lvt)
            .chain(trace.gvt.iter().map(|g| g.gvt))
            .max()
            .unwrap_or(1)
            .max(1);
        let mut chart = drawing(
            ChartBuilder::on(root)
                .caption(
                    format!(
                        "Space-time diagram: LVT of {}, GVT in black",
                        counted(trace.worlds, "world", "worlds")
                    ),
                    ("sans-serif", 20),
                )
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..t_max * 1.02, 0u64..s_max + 1),
            path,
        )?;
        drawing(
            chart
                .configure_mesh()
                .x_desc("wall time (s)")
                .y_desc("step")
                .draw(),
            path,
        )?;
        for w in 0..trace.worlds as u32 {
            let colour = world_colour(w);
            let lvt = trace.lvt.iter().filter(|s| s.world == w);
            let points = step_line(lvt.map(|s| (s.time, s.lvt)));
            drawing(
                chart.draw_series(LineSeries::new(points, colour.stroke_width(1))),
                path,
            )?
            .label(format!("world {w}"))
            .legend(line_key(colour));
        }
        let gvt = step_line(trace.gvt.iter().map(|g| (g.time, g.gvt)));
        drawing(
            chart.draw_series(LineSeries::new(gvt, BLACK.stroke_width(2))),
            path,
        )?
        .label("GVT")
        .legend(line_key(BLACK));
        draw_key(&mut chart, SeriesLabelPosition::UpperLeft, path)?;
        Ok(())
    })
}

/// A value that holds until the next sample, then jumps (an LVT drops on a rollback).
fn step_line<Y: Copy>(samples: impl Iterator<Item = (f64, Y)>) -> Vec<(f64, Y)> {
    let mut points: Vec<(f64, Y)> = Vec::new();
    for (t, y) in samples {
        if let Some(&(_, last)) = points.last() {
            points.push((t, last));
        }
        points.push((t, y));
    }
    points
}

/// The key entry of a line series: a short line in its colour.
fn line_key(colour: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour)
}

/// Draws the series key (labels and legends) in a framed box at `position`.
fn draw_key<'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, CT>,
    position: SeriesLabelPosition,
    path: &Path,
) -> Result<()> {
    drawing(
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .position(position)
            .draw(),
        path,
    )
}

/// A top view of the grid (x across, z down): one square per column of cells, filled by
/// `value(x, z)`.
fn top_view(
    trace: &RunTrace,
    path: &Path,
    title: &str,
    fill: impl Fn(i32, i32) -> RGBColor,
) -> Result<()> {
    let [nx, _, nz] = trace.grid;
    let side = (560 / nx.max(nz).max(1)).clamp(4, 60) as u32;
    let size = (side * nx as u32 + 120, side * nz as u32 + 110);
    svg_file(path, size, |root| {
        drawing(root.fill(&WHITE), path)?;
        let mut chart = drawing(
            ChartBuilder::on(root)
                .caption(title, ("sans-serif", 16))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(40)
                .build_cartesian_2d(0..nx, nz..0),
            path,
        )?;
        drawing(
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("cell x")
                .y_desc("cell z")
                .draw(),
            path,
        )?;
        let squares = (0..nx).flat_map(|x| (0..nz).map(move |z| (x, z)));
        drawing(
            chart.draw_series(
                squares.map(|(x, z)| Rectangle::new([(x, z), (x + 1, z + 1)], fill(x, z).filled())),
            ),
            path,
        )?;
        Ok(())
    })
}

/// The owner of every column of cells, seen from above (the world owning most of the
/// column's cells; ties to the lower id).
pub fn territory_map(trace: &RunTrace, path: &Path) -> Result<()> {
    let [nx, ny, _] = trace.grid;
    let owner = |x: i32, z: i32| -> u32 {
        let mut count = vec![0u32; trace.worlds.max(1)];
        for y in 0..ny {
            let i = (x + nx * (y + ny * z)) as usize;
            if let Some(&w) = trace.owners.get(i) {
                if let Some(c) = count.get_mut(w as usize) {
                    *c += 1;
                }
            }
        }
        (0..count.len())
            .max_by_key(|&w| (count[w], std::cmp::Reverse(w)))
            .unwrap_or(0) as u32
    };
    top_view(
        trace,
        path,
        &format!(
            "Territories of {} (top view, majority owner of each column)",
            counted(trace.worlds, "world", "worlds")
        ),
        |x, z| world_colour(owner(x, z)),
    )
}

/// Re-executed cell computations per column of cells, seen from above (white: none; dark
/// red: the most).
pub fn rollback_heat_map(trace: &RunTrace, path: &Path) -> Result<()> {
    let [nx, ny, nz] = trace.grid;
    let mut heat = vec![0u64; (nx.max(0) * nz.max(0)) as usize];
    for &(cell, n) in &trace.recomputed_cells {
        let c = cell as i32;
        let (x, z) = (c % nx, c / (nx * ny));
        if x < nx && z < nz {
            heat[(x + nx * z) as usize] += n;
        }
    }
    let max = heat.iter().copied().max().unwrap_or(0).max(1);
    let total: u64 = heat.iter().sum();
    top_view(
        trace,
        path,
        &format!(
            "Rollback heat map: {} recomputed (darkest column: {max})",
            counted(total, "cell", "cells")
        ),
        |x, z| {
            let f = heat[(x + nx * z) as usize] as f64 / max as f64;
            let fade = |full: f64| (255.0 - (255.0 - full) * f).round() as u8;
            RGBColor(fade(160.0), fade(0.0), fade(0.0))
        },
    )
}

/// Grouped bars: one group per category, one bar per series.
pub fn bar_chart(
    path: &Path,
    title: &str,
    y_desc: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
) -> Result<()> {
    svg_file(path, (900, 520), |root| {
        drawing(root.fill(&WHITE), path)?;
        let y_max = series
            .iter()
            .flat_map(|s| s.1.iter().copied())
            .fold(1e-9, f64::max)
            * 1.15;
        let n = categories.len().max(1);
        let mut chart = drawing(
            ChartBuilder::on(root)
                .caption(title, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0f64..n as f64, 0f64..y_max),
            path,
        )?;
        let labels = categories.to_vec();
        drawing(
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(n * 2 + 1)
                .x_label_formatter(&move |x| {
                    let i = x.floor() as usize;
                    if (x - i as f64 - 0.5).abs() < 0.26 {
                        labels.get(i).cloned().unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .y_desc(y_desc)
                .draw(),
            path,
        )?;
        let k = series.len().max(1) as f64;
        for (j, (name, values)) in series.iter().enumerate() {
            let colour = world_colour(j as u32);
            let bars = values.iter().enumerate().map(move |(i, &v)| {
                let x0 = i as f64 + 0.1 + 0.8 * j as f64 / k;
                Rectangle::new([(x0, 0.0), (x0 + 0.8 / k, v)], colour.filled())
            });
            drawing(chart.draw_series(bars), path)?
                .label(name.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled())
                });
        }
        draw_key(&mut chart, SeriesLabelPosition::UpperRight, path)?;
        Ok(())
    })
}

/// Lines with markers: one per series.
pub fn line_chart(
    path: &Path,
    title: &str,
    axes: (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    svg_file(path, (900, 520), |root| {
        drawing(root.fill(&WHITE), path)?;
        let pts = || series.iter().flat_map(|s| s.1.iter().copied());
        let x_max = pts().map(|p| p.0).fold(1e-9, f64::max) * 1.05;
        let y_max = pts().map(|p| p.1).fold(1e-9, f64::max) * 1.15;
        let mut chart = drawing(
            ChartBuilder::on(root)
                .caption(title, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0f64..x_max, 0f64..y_max),
            path,
        )?;
        drawing(
            chart.configure_mesh().x_desc(axes.0).y_desc(axes.1).draw(),
            path,
        )?;
        for (j, (name, points)) in series.iter().enumerate() {
            let colour = world_colour(j as u32);
            drawing(
                chart.draw_series(LineSeries::new(points.clone(), colour.stroke_width(2))),
                path,
            )?
            .label(name.clone())
            .legend(line_key(colour));
            drawing(
                chart.draw_series(
                    points
                        .iter()
                        .map(move |&p| Circle::new(p, 3, colour.filled())),
                ),
                path,
            )?;
        }
        draw_key(&mut chart, SeriesLabelPosition::UpperLeft, path)?;
        Ok(())
    })
}
