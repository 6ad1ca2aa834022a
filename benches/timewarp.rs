//! Time Warp measurements on the virtual executor, one run each (wall times on a shared
//! 2-core machine are noisy; counters are exact and reproducible):
//!
//! 1. **Overhead**: `falling-cubes`, 8 worlds, `cell` mode, window 16, against the reference
//!    run of the same steps — under the FIFO schedule (deliveries in order, worlds in turn:
//!    the overhead of logs, messages and GVT alone; reference and FIFO runs alternate
//!    `TW_REPEATS` times, default 5, and both the ratio of their medians and the median of
//!    the pair ratios are printed, for wall time and for the thread CPU clock) and under a
//!    seeded random schedule (adds the cost of rollbacks). Both runs use the system
//!    allocator (the `soda` binary uses mimalloc).
//! 2. **Rollback granularity**: `sparse-gas` and `falling-cubes`, 8 worlds, window 16, the
//!    same seeded schedule for `cell`, `world` and `conservative`: cell computations,
//!    re-executions, rollbacks, efficiency and wall time.
//! 3. **Log memory** at window 64: `falling-cubes`, 8 worlds, `cell`, seeded schedule; bytes
//!    held by the logs sampled every `TW_LOG_EVERY` steps (default 10) along the run and the
//!    most of them, bytes per body-step held, and by part (states,
//!    outputs, ghost views, migrations in, inputs, messages received and sent, per-slot
//!    headers).
//!
//! 4. **Log flatness** over 10,000 steps at window 64: synthetic particles (`TW_PARTICLES`,
//!    default 2000; `TW_FLAT_STEPS`, default 10000), logs sampled every tenth of the run.
//!
//! Sizes (environment): `TW_CUBES` (default 8000) and `TW_STEPS` (60) for 1 and 3;
//! `TW_GAS` (1000), `TW_FC` (8000, the size the overhead and memory parts use) and `TW_GRAN_STEPS` (120) for 2; `TW_LOG_STEPS` (240) for
//! 3. `cargo bench --bench timewarp -- --test` (or `cargo test --benches`) runs a tiny
//! version. Every run checks its final hash against the reference.
//!
//! Run: `cargo bench --bench timewarp` (`TW_PARTS=overhead,granularity,memory,flatness`
//! selects parts; `TW_GHOSTS=full` runs every part with full instead of delta ghosts).

#[path = "common/knobs.rs"]
mod knobs;

use knobs::{env, median, median_ratio};
use soda::exec::clock::thread_cpu_seconds;
use soda::exec::virtual_exec::{ScheduleSpec, VirtualOptions, VirtualRun};
use soda::hash::hex;
use soda::kernel::synthetic::Particles;
use soda::kernel::{Counters, GhostPolicy, KernelConfig, RollbackMode};
use soda::scene::builtin::builtin;
use soda::scene::Scene;
use soda::ReferenceRun;
use std::time::Instant;

/// Reference wall time, CPU time (the thread's clock) and final hash.
fn reference(scene: &Scene, steps: u64) -> (f64, f64, u64) {
    let (mut r, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    let (t, c) = (Instant::now(), thread_cpu_seconds());
    let mut hash = 0;
    for _ in 0..steps {
        hash = r.advance().hash;
    }
    (t.elapsed().as_secs_f64(), thread_cpu_seconds() - c, hash)
}

/// Virtual-executor wall time, CPU time (the thread's clock), final hash and counters.
fn virtual_run(
    scene: &Scene,
    cfg: &KernelConfig,
    schedule: ScheduleSpec,
    steps: u64,
) -> (f64, f64, u64, Counters) {
    let (mut r, _) = VirtualRun::new(
        scene.model(),
        scene.grid(),
        scene.initial_bodies(),
        cfg,
        &options(schedule),
    );
    let (t, c) = (Instant::now(), thread_cpu_seconds());
    let mut hash = 0;
    r.run_with(steps, |f| hash = f.hash);
    (
        t.elapsed().as_secs_f64(),
        thread_cpu_seconds() - c,
        hash,
        r.counters(),
    )
}

/// The ghost policy (`TW_GHOSTS=delta|full`, default delta).
fn ghosts() -> GhostPolicy {
    match std::env::var("TW_GHOSTS").as_deref() {
        Ok("full") => GhostPolicy::Full,
        _ => GhostPolicy::Delta,
    }
}

fn config(mode: RollbackMode, window: u64) -> KernelConfig {
    KernelConfig::new(8)
        .mode(mode)
        .window(window)
        .ghosts(ghosts())
}

/// The virtual executor under `schedule`, decisions not recorded.
fn options(schedule: ScheduleSpec) -> VirtualOptions {
    VirtualOptions::new(schedule).record_schedule(false)
}

fn overhead() {
    let cubes = env("TW_CUBES", 8000, 64) as usize;
    let steps = env("TW_STEPS", 60, 5);
    let repeats = env("TW_REPEATS", 5, 1).max(1);
    let scene = builtin("falling-cubes", Some(cubes), 0).expect("scene");
    // The reference and the FIFO run alternate `repeats` times; their medians are compared.
    let fifo = config(RollbackMode::Cell, 16);
    let (mut refs, mut fifos) = (Vec::new(), Vec::new());
    let (mut ref_cpu, mut fifo_cpu) = (Vec::new(), Vec::new());
    let (mut hr, mut fifo_counters) = (0, None);
    for k in 0..repeats {
        let (tr, cr, h) = reference(&scene, steps);
        let (tv, cv, hv, c) = virtual_run(&scene, &fifo, ScheduleSpec::Fifo, steps);
        assert_eq!(hv, h, "virtual executor diverged from the reference");
        println!(
            "  pair {k}: reference {tr:.3} s, fifo {tv:.3} s = {:.3}x; CPU {cr:.3} s, {cv:.3} s = {:.3}x",
            tv / tr,
            cv / cr
        );
        hr = h;
        refs.push(tr);
        fifos.push(tv);
        ref_cpu.push(cr);
        fifo_cpu.push(cv);
        // The FIFO schedule is deterministic: every pair has the same counters.
        fifo_counters = Some(c);
    }
    let tr = median(&refs);
    println!(
        "overhead: falling-cubes {cubes}, {steps} steps, grid {:?}; reference median of {repeats} {tr:.3} s ({:.0} body-steps/s), hash {}",
        scene.grid().dims,
        cubes as f64 * steps as f64 / tr,
        hex(hr),
    );
    let report = |label: &str, tv: f64, c: &Counters| {
        println!(
            "  virtual 8 worlds cell W16 {label:17}: {tv:.3} s = {:.3}x reference median; rollbacks {}, cells computed {} (re-executed {}), efficiency {:.3}, messages {} + {} anti",
            tv / tr,
            c.total.rollbacks(),
            c.total.cells_computed,
            c.total.cells_recomputed,
            c.total.efficiency(),
            c.total.messages_sent,
            c.total.anti_messages_sent
        );
    };
    report(
        "fifo (median)",
        median(&fifos),
        &fifo_counters.expect("at least one pair"),
    );
    println!(
        "  CPU time (thread clock, medians): reference {:.3} s, fifo {:.3} s = {:.3}x",
        median(&ref_cpu),
        median(&fifo_cpu),
        median(&fifo_cpu) / median(&ref_cpu)
    );
    println!(
        "  median of the {repeats} pair ratios: wall {:.3}x, CPU {:.3}x",
        median_ratio(&fifos, &refs),
        median_ratio(&fifo_cpu, &ref_cpu)
    );
    let seeded = config(RollbackMode::Cell, 16);
    let (tv, _, hv, c) = virtual_run(&scene, &seeded, ScheduleSpec::Seeded(1), steps);
    assert_eq!(hv, hr, "virtual executor diverged from the reference");
    report("seeded(1)", tv, &c);
}

fn granularity() {
    let steps = env("TW_GRAN_STEPS", 120, 8);
    for (name, n) in [
        ("sparse-gas", env("TW_GAS", 1000, 27)),
        ("falling-cubes", env("TW_FC", 8000, 27)),
    ] {
        let scene = builtin(name, Some(n as usize), 0).expect("scene");
        let (tr, _, hr) = reference(&scene, steps);
        println!(
            "granularity: {name} {n}, {steps} steps, 8 worlds, W16, schedule seeded(3); reference {tr:.3} s"
        );
        let mut recomputed = Vec::new();
        for mode in [
            RollbackMode::Cell,
            RollbackMode::World,
            RollbackMode::Conservative,
        ] {
            let (tv, _, hv, c) =
                virtual_run(&scene, &config(mode, 16), ScheduleSpec::Seeded(3), steps);
            assert_eq!(hv, hr, "{name} {mode:?} diverged from the reference");
            recomputed.push(c.total.cells_recomputed);
            println!(
                "  {:12}: {tv:.3} s ({:.3}x ref); cell-steps computed {}, re-executed {}, rollbacks {} (mean length {:.1}), efficiency {:.3}, messages {} + {} anti + {} null",
                mode.name(),
                tv / tr,
                c.total.cells_computed,
                c.total.cells_recomputed,
                c.total.rollbacks(),
                (c.total.rollback_length_primary + c.total.rollback_length_secondary) as f64
                    / c.total.rollbacks().max(1) as f64,
                c.total.efficiency(),
                c.total.messages_sent - c.total.null_messages_sent,
                c.total.anti_messages_sent,
                c.total.null_messages_sent,
            );
        }
        println!(
            "  cell re-executes {:.1} % of world's cell-steps",
            100.0 * recomputed[0] as f64 / recomputed[1].max(1) as f64
        );
    }
}

fn log_memory() {
    let cubes = env("TW_CUBES", 8000, 64) as usize;
    let steps = env("TW_LOG_STEPS", 240, 8);
    let scene = builtin("falling-cubes", Some(cubes), 0).expect("scene");
    let cfg = config(RollbackMode::Cell, 64);
    let (mut r, _) = VirtualRun::new(
        scene.model(),
        scene.grid(),
        scene.initial_bodies(),
        &cfg,
        &options(ScheduleSpec::Seeded(5)),
    );
    println!(
        "log memory: falling-cubes {cubes}, 8 worlds, cell, W64, seeded(5); a body's state is {} B",
        std::mem::size_of::<soda::physics::Body>()
    );
    r.set_horizon(steps + 64);
    let chunk = env("TW_LOG_EVERY", 10, 2).min(steps).max(1);
    let mut done = 0;
    let mut worst = 0f64;
    let t = Instant::now();
    while done < steps {
        r.run(chunk);
        done += chunk;
        let held = r.steps_held();
        let b = r.log_breakdown();
        let bytes = b.total();
        let per_body_step = bytes as f64 / (cubes as f64 * held as f64 / 8.0);
        worst = worst.max(per_body_step);
        println!(
            "  step {:6}: logs {:8.1} MiB over {held} world-steps = {:.1} B per body-step held (per-world steps held {:.1}, GVT {})",
            r.committed_step(),
            bytes as f64 / (1 << 20) as f64,
            per_body_step,
            held as f64 / 8.0,
            r.gvt()
        );
        let per = |x: u64| x as f64 / (cubes as f64 * held as f64 / 8.0);
        println!(
            "    B per body-step: states {:.1}, outputs {:.1}, ghosts {:.1}, migrations {:.1}, inputs {:.1}, received {:.1}, sent {:.1}, slots {:.1}",
            per(b.states),
            per(b.outputs),
            per(b.ghosts),
            per(b.migrations),
            per(b.inputs),
            per(b.received),
            per(b.sent),
            per(b.slots)
        );
    }
    println!("  most bytes per body-step held at a sample: {worst:.1}");
    let c = r.counters();
    println!(
        "  peak {:.1} MiB (sum of per-world peaks) = {:.0} B per body-step at a full window ({} bodies x 65 steps); {:.1} s",
        c.total.peak_log_bytes as f64 / (1 << 20) as f64,
        c.total.peak_log_bytes as f64 / (cubes as f64 * 65.0),
        cubes,
        t.elapsed().as_secs_f64()
    );
}

/// Flatness of the logs over a long run: synthetic particles (cheap enough for 10,000 steps).
fn log_flatness() {
    let n = env("TW_PARTICLES", 2000, 50) as usize;
    let steps = env("TW_FLAT_STEPS", 10_000, 40);
    let (m, g, b) = Particles::scene(n, [16, 8, 16], false, 1);
    let cfg = config(RollbackMode::Cell, 64);
    let (mut r, _) = VirtualRun::new(m, g, b, &cfg, &options(ScheduleSpec::Seeded(5)));
    r.set_horizon(steps + 64);
    println!(
        "log flatness: {n} synthetic particles in 16x8x16 cells, 8 worlds, cell, W64, seeded(5)"
    );
    let chunk = (steps / 10).max(1);
    let t = Instant::now();
    let mut done = 0;
    while done < steps {
        r.run(chunk);
        done += chunk;
        let held = r.steps_held();
        let b = r.log_breakdown();
        let bytes = b.total();
        println!(
            "  step {:6}: logs {:7.2} MiB over {held:4} world-steps = {:.0} B per body-step held; peak so far {:.2} MiB",
            r.committed_step(),
            bytes as f64 / (1 << 20) as f64,
            bytes as f64 / (n as f64 * held as f64 / 8.0),
            r.counters().total.peak_log_bytes as f64 / (1 << 20) as f64,
        );
    }
    let c = r.counters();
    println!(
        "  {:.1} s; efficiency {:.3}, rollbacks {}",
        t.elapsed().as_secs_f64(),
        c.total.efficiency(),
        c.total.rollbacks()
    );
}

fn main() {
    // `TW_PARTS=overhead,granularity,memory,flatness` (default: all) selects the parts.
    let parts = std::env::var("TW_PARTS").unwrap_or_default();
    let on = |p: &str| parts.is_empty() || parts.split(',').any(|x| x == p);
    if on("overhead") {
        overhead();
    }
    if on("granularity") {
        granularity();
    }
    if on("memory") {
        log_memory();
    }
    if on("flatness") {
        log_flatness();
    }
}
