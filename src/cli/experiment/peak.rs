//! `soda experiment peak-resistance`: a computational peak (the `peak` scene's block of
//! cubes landing on one quadrant) costed as the thesis's §4.2 defines it — collisions during
//! the peak over collisions before it — and how the optimism window W absorbs it: threaded
//! runs for W = 1..64, timing every committed frame as the output stage receives it.

use super::{cores, f, median, scene, Row};
use anyhow::{bail, Context, Result};
use parry3d::query;
use parry3d::shape::{Ball, Cuboid, Shape as ParryShape};
use soda::app::charts;
use soda::app::output::counted;
use soda::exec::reference::{CellCost, ReferenceRun};
use soda::frame::StatesWanted;
use soda::grid::Grid;
use soda::hash::hex;
use soda::kernel::trace::RunTrace;
use soda::kernel::{KernelConfig, Partition, PartitionKind};
use soda::physics::{Body, RigidBodyModel, Shape};
use soda::scaling::WindowedRun;
use soda::scene::Scene;
use soda::sim::{run_scene, ExecutorKind, RunOptions};
use soda::state::CellStates;
use std::path::Path;
use std::time::Instant;

/// Two surfaces closer than this (m) are in contact for the collision count.
const CONTACT_TOLERANCE: f32 = 0.01;

/// A step is part of the peak while its collisions exceed this multiple of the baseline.
const PEAK_THRESHOLD: f64 = 2.0;

/// The reference run's cost of every step.
pub(super) struct Profile {
    /// Per step `t` (computing `t → t + 1`): contacts processed, see [`collisions`].
    collisions: Vec<u64>,
    /// Per step: summed wall time of the cell computations, s.
    compute: Vec<f64>,
    /// Per step: whether a cube (the burst) touches anything.
    burst_touching: Vec<bool>,
    /// Every cell computation's cost, for the model.
    cells: Vec<CellCost>,
    /// Hash of the final state (16 hex digits).
    pub(super) hash: String,
}

/// Where the peak is and what it costs.
pub(super) struct PeakWindow {
    /// First step at which a cube of the burst touches something.
    pub(super) landing: usize,
    /// Last step whose collisions exceed [`PEAK_THRESHOLD`] × the baseline.
    pub(super) end: usize,
    /// Mean collisions per step before the landing (steps 1..landing).
    baseline: f64,
    /// The thesis's peak cost: mean collisions over the peak / the baseline.
    pub(super) collision_ratio: f64,
    /// The same with the reference's compute time per step.
    compute_ratio: f64,
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (n, s) = v.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        0.0
    } else {
        s / n as f64
    }
}

fn parry_shape(s: &Shape) -> Box<dyn ParryShape> {
    match *s {
        Shape::Ball { radius } => Box::new(Ball::new(radius)),
        Shape::Cuboid { half_extents } => Box::new(Cuboid::new(half_extents.into())),
    }
}

/// Whether `b` is within the tolerance of a static plane (ground, walls, ceiling).
fn touches_planes(b: &Body, model: &RigidBodyModel) -> bool {
    model.environment.planes.iter().any(|p| {
        let lowest = match b.shape() {
            Shape::Ball { radius } => p.normal.dot(&b.position) - radius,
            Shape::Cuboid { .. } => b
                .shape()
                .vertices()
                .iter()
                .map(|v| p.normal.dot(&(b.position + b.rotation * v)))
                .fold(f32::INFINITY, f32::min),
        };
        lowest - p.offset <= CONTACT_TOLERANCE
    })
}

/// Contacts the step processes (the thesis's "collisions"): pairs of bodies, at least one
/// awake (a sleeping pair is not computed, SPEC.md §5.4), whose surfaces are within
/// [`CONTACT_TOLERANCE`] (parry's exact query), and awake bodies that close to a static
/// plane. Also returns whether a cube touches anything.
fn collisions(state: &CellStates<Body>, grid: &Grid, model: &RigidBodyModel) -> (u64, bool) {
    let (mut count, mut cube) = (0u64, false);
    let is_cube = |b: &Body| matches!(b.shape(), Shape::Cuboid { .. });
    for i in state.occupied() {
        let nb = state.neighbourhood(grid, grid.coord(i));
        for a in nb.own() {
            if !model.is_asleep(a) && touches_planes(a, model) {
                count += 1;
                cube |= is_cube(a);
            }
            for b in nb.iter().filter(|b| b.id() > a.id()) {
                if model.is_asleep(a) && model.is_asleep(b) {
                    continue;
                }
                let reach = a.bounding_radius() + b.bounding_radius() + CONTACT_TOLERANCE;
                if (a.position - b.position).norm_squared() > reach * reach {
                    continue;
                }
                let (sa, sb) = (parry_shape(&a.shape()), parry_shape(&b.shape()));
                let hit = query::contact(&a.pose(), &*sa, &b.pose(), &*sb, CONTACT_TOLERANCE);
                if matches!(hit, Ok(Some(_))) {
                    count += 1;
                    cube |= is_cube(a) || is_cube(b);
                }
            }
        }
    }
    (count, cube)
}

/// Runs the reference for `steps` steps, counting each step's collisions and timing its
/// cell computations.
pub(super) fn profile(s: &Scene, steps: u64) -> Profile {
    let (model, grid) = (s.model(), s.grid());
    let (mut run, _) = ReferenceRun::new(model.clone(), grid.clone(), s.initial_bodies());
    run.record_costs(true);
    let mut p = Profile {
        collisions: Vec::new(),
        compute: Vec::new(),
        burst_touching: Vec::new(),
        cells: Vec::new(),
        hash: String::new(),
    };
    for _ in 0..steps {
        let (c, cube) = collisions(run.state(), &grid, &model);
        p.collisions.push(c);
        p.burst_touching.push(cube);
        let frame = run.advance();
        let costs = run.take_costs();
        p.compute.push(costs.iter().map(|c| c.seconds).sum::<f64>());
        p.cells.extend(costs);
        p.hash = hex(frame.hash);
    }
    p
}

impl PeakWindow {
    /// Finds the peak in a profile, or explains why there is none.
    pub(super) fn find(p: &Profile) -> Result<PeakWindow> {
        let Some(landing) = p.burst_touching.iter().position(|&t| t).filter(|&l| l > 1) else {
            bail!("the burst never landed in this run: run more steps (it lands near step 90)");
        };
        let baseline = mean(p.collisions[1..landing].iter().map(|&c| c as f64)).max(1.0);
        let end = (landing..p.collisions.len())
            .rev()
            .find(|&t| p.collisions[t] as f64 > PEAK_THRESHOLD * baseline)
            .unwrap_or(landing);
        let over = |v: &[f64]| mean(v[landing..=end].iter().copied());
        let before = |v: &[f64]| mean(v[1..landing].iter().copied()).max(1e-12);
        let collisions: Vec<f64> = p.collisions.iter().map(|&c| c as f64).collect();
        Ok(PeakWindow {
            landing,
            end,
            baseline,
            collision_ratio: over(&collisions) / baseline,
            compute_ratio: over(&p.compute) / before(&p.compute),
        })
    }
}

/// Writes `peak-resistance-cost.csv` and `.svg` beside `svg`: the profile, per step.
fn write_profile(p: &Profile, w: &PeakWindow, svg: &Path, title: &str) -> Result<()> {
    let mut text = String::from("step,collisions,compute_seconds,collisions_ratio,compute_ratio\n");
    let before = mean(p.compute[1..w.landing].iter().copied()).max(1e-12);
    let (mut col, mut cpu) = (Vec::new(), Vec::new());
    for t in 0..p.collisions.len() {
        let (rc, rt) = (p.collisions[t] as f64 / w.baseline, p.compute[t] / before);
        text.push_str(&format!(
            "{t},{},{},{},{}\n",
            p.collisions[t],
            f(p.compute[t]),
            f(rc),
            f(rt)
        ));
        col.push((t as f64, rc));
        cpu.push((t as f64, rt));
    }
    let csv = svg.with_file_name("peak-resistance-cost.csv");
    soda::app::atomic::write(&csv, text.as_bytes())?;
    let chart = svg.with_file_name("peak-resistance-cost.svg");
    charts::line_chart(
        &chart,
        title,
        ("step", "cost / mean cost before the landing"),
        &[
            ("collisions (the thesis's peak cost)".into(), col),
            ("reference compute time".into(), cpu),
        ],
    )?;
    super::super::output::print_line(format_args!("wrote {}", csv.display()))?;
    super::super::output::print_line(format_args!("wrote {}", chart.display()))?;
    Ok(())
}

/// How far the leading world got ahead of GVT: the largest `LVT − GVT` over the trace (a
/// world's LVT against the GVT recorded last before that sample; the world may already have
/// seen the next GVT, so this can exceed the true lead by one).
fn max_lead(trace: &RunTrace) -> u64 {
    let mut gvt: Vec<(f64, u64)> = trace.gvt.iter().map(|g| (g.time, g.gvt)).collect();
    gvt.sort_by(|a, b| a.0.total_cmp(&b.0));
    trace
        .lvt
        .iter()
        .map(|s| {
            let k = gvt.partition_point(|g| g.0 <= s.time);
            let g = if k == 0 { 0 } else { gvt[k - 1].1 };
            s.lvt.saturating_sub(g)
        })
        .max()
        .unwrap_or(0)
}

/// The model (`soda::scaling::WindowedRun`) of `worlds` blocks worlds on `workers` workers
/// with ideal optimism, per window: (window, makespan s, worst commit gap s).
fn model(
    s: &Scene,
    p: &Profile,
    worlds: usize,
    workers: usize,
    windows: &[u64],
) -> Vec<(u64, f64, f64)> {
    let grid = s.grid();
    let positions: Vec<[f32; 3]> = s.bodies.iter().map(|b| b.position).collect();
    let part = Partition::build(&PartitionKind::Blocks, &grid, worlds, &positions, 0);
    let mut per_step = vec![vec![0.0f64; worlds]; p.compute.len()];
    let mut cells: Vec<&CellCost> = p.cells.iter().collect();
    cells.sort_by_key(|c| (c.step, c.cell));
    for c in cells {
        per_step[c.step as usize][part.owner(c.cell) as usize] += c.seconds;
    }
    windows
        .iter()
        .map(|&w| {
            let m = WindowedRun::simulate(&per_step, workers, w);
            (w, m.makespan, m.worst_gap())
        })
        .collect()
}

/// The experiment: the peak's cost from a reference run, then threaded runs for every
/// window, world count and repeat (interleaved, so the machine's load spreads over all).
pub(super) fn peak_resistance(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (bodies, steps, windows, repeats): (usize, u64, &[u64], usize) = if quick {
        (200, 150, &[1, 4, 16, 64], 1)
    } else {
        (1000, 300, &[1, 2, 4, 8, 16, 32, 64], 3)
    };
    let s = scene("peak", bodies, 0)?;
    let threads = cores().max(2);
    let world_counts = [threads, 2 * threads];
    let runs = repeats * world_counts.len() * windows.len();
    let bar = super::super::output::runs_bar(1 + runs as u64);
    bar.set_message("reference: collisions and compute time per step");
    let p = profile(&s, steps);
    let w = PeakWindow::find(&p)?;
    bar.inc(1);
    write_profile(
        &p,
        &w,
        svg,
        &format!(
            "Peak cost per step (peak {bodies}, reference): collisions x{:.1}, compute x{:.1} \
             over steps {}-{}",
            w.collision_ratio, w.compute_ratio, w.landing, w.end
        ),
    )?;
    let mut rows = Vec::new();
    // (worlds, window) -> wall times and worst gaps over the repeats
    let mut wall: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); windows.len()]; world_counts.len()];
    let mut gaps = wall.clone();
    for rep in 0..repeats {
        for (a, &worlds) in world_counts.iter().enumerate() {
            for (b, &window) in windows.iter().enumerate() {
                bar.set_message(format!("{worlds} worlds, W {window}, repeat {rep}"));
                let options = RunOptions {
                    executor: ExecutorKind::Threaded,
                    kernel: KernelConfig::new(worlds).window(window).trace(true),
                    threads,
                    ..RunOptions::default()
                };
                let mut times: Vec<(u64, f64)> = Vec::with_capacity(steps as usize + 1);
                let start = Instant::now();
                let r = run_scene(&s, &options, steps, &StatesWanted::none(), |fr, _| {
                    times.push((fr.step, start.elapsed().as_secs_f64()))
                })
                .context("the threaded executor failed")?;
                if r.hash != p.hash {
                    bail!(
                        "threaded run ({worlds} worlds, W {window}) ended in {} but the \
                         reference in {}: a determinism bug; please report it",
                        r.hash,
                        p.hash
                    );
                }
                let times = &times;
                let gap = |k: usize| times[k].1 - times[k - 1].1;
                let in_range = |lo: usize, hi: usize| {
                    (1..times.len()).filter(move |&k| (lo..=hi).contains(&(times[k].0 as usize)))
                };
                let (worst_k, worst) = (1..times.len())
                    .map(|k| (k, gap(k)))
                    .max_by(|x, y| x.1.total_cmp(&y.1))
                    .unwrap_or((0, 0.0));
                let before = mean(in_range(2, w.landing).map(gap));
                let peak_worst = in_range(w.landing + 1, w.end + 1)
                    .map(gap)
                    .fold(0.0, f64::max);
                let peak_seconds: f64 = in_range(w.landing + 1, w.end + 1).map(gap).sum();
                let lead = r.trace.as_ref().map_or(0, max_lead);
                wall[a][b].push(r.wall_seconds);
                gaps[a][b].push(worst * 1e3);
                rows.push(Row {
                    bodies,
                    extra: vec![
                        ("repeat".into(), rep.to_string()),
                        ("peak_landing_step".into(), w.landing.to_string()),
                        ("peak_end_step".into(), w.end.to_string()),
                        ("peak_collision_ratio".into(), f(w.collision_ratio)),
                        ("peak_compute_ratio".into(), f(w.compute_ratio)),
                        ("worst_gap_ms".into(), f(worst * 1e3)),
                        ("worst_gap_step".into(), times[worst_k].0.to_string()),
                        ("mean_gap_before_peak_ms".into(), f(before * 1e3)),
                        ("worst_gap_in_peak_ms".into(), f(peak_worst * 1e3)),
                        ("peak_commit_seconds".into(), f(peak_seconds)),
                        ("max_lead_steps".into(), lead.to_string()),
                    ],
                    report: r,
                });
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    let mut model_csv = String::from("worlds,workers,window,model_seconds,model_worst_gap_ms\n");
    let (mut model_wall, mut model_gap) = (Vec::new(), Vec::new());
    for &worlds in &world_counts {
        let m = model(&s, &p, worlds, threads, windows);
        for &(win, secs, gap) in &m {
            model_csv.push_str(&format!(
                "{worlds},{threads},{win},{},{}\n",
                f(secs),
                f(gap * 1e3)
            ));
        }
        let label = format!(
            "MODEL (ideal optimism), {} on {}",
            counted(worlds, "world", "worlds"),
            counted(threads, "worker", "workers")
        );
        let x = |w: u64| (w as f64).log2();
        model_wall.push((
            label.clone(),
            m.iter().map(|e| (x(e.0), e.1)).collect::<Vec<_>>(),
        ));
        model_gap.push((
            label,
            m.iter().map(|e| (x(e.0), e.2 * 1e3)).collect::<Vec<_>>(),
        ));
    }
    let model_path = svg.with_file_name("peak-resistance-model.csv");
    soda::app::atomic::write(&model_path, model_csv.as_bytes())?;
    super::super::output::print_line(format_args!("wrote {}", model_path.display()))?;
    let series = |values: &[Vec<Vec<f64>>], what: &str| -> Vec<(String, Vec<(f64, f64)>)> {
        world_counts
            .iter()
            .zip(values)
            .map(|(worlds, per_window)| {
                let points = windows
                    .iter()
                    .zip(per_window)
                    .map(|(&win, v)| ((win as f64).log2(), median(v.clone())))
                    .collect();
                (
                    format!(
                        "{what}, {} on {}",
                        counted(*worlds, "world", "worlds"),
                        counted(threads, "thread", "threads")
                    ),
                    points,
                )
            })
            .collect()
    };
    let title = format!(
        "Peak resistance: peak {bodies}, {steps} steps, threaded, median of {repeats}; \
         peak x{:.1} collisions at steps {}-{}",
        w.collision_ratio, w.landing, w.end
    );
    charts::line_chart(
        svg,
        &title,
        ("log2 of the window W", "wall time (s)"),
        &[series(&wall, "measured wall time"), model_wall].concat(),
    )?;
    let gap_chart = svg.with_file_name("peak-resistance-gaps.svg");
    charts::line_chart(
        &gap_chart,
        &title,
        (
            "log2 of the window W",
            "worst gap between committed frames (ms)",
        ),
        &[series(&gaps, "measured worst commit gap"), model_gap].concat(),
    )?;
    super::super::output::print_line(format_args!("wrote {}", gap_chart.display()))?;
    Ok(rows)
}
