//! A million bodies on the reference executor: how long the built-in scene takes to build
//! (scene and validation), to bin into its first state, and to step; and the peak resident
//! memory per body.
//!
//! Not criterion: one run of a million bodies takes tens of seconds and gigabytes are not
//! sampled ten times. Every phase prints its wall time and the CPU time of this thread
//! (`/proc/thread-self/schedstat`, nanoseconds on a CPU), so a run on the shared 2-core
//! machine can tell slowness from waiting for a core; the stepping rate is printed both
//! ways. Peak RSS is the process's `VmHWM` (`/proc/self/status`) at the end.
//!
//! Knobs: `MILLION_SCENE` (a built-in scene, default `sparse-gas`), `MILLION_OBJECTS`
//! (default 1,000,000), `MILLION_STEPS` (default 20), `MILLION_SEED` (default 0).
//!
//! Run: `cargo bench --bench million` (about a minute at the defaults);
//! `MILLION_OBJECTS=100000 cargo bench --bench million` for a tenth. `cargo test --benches`
//! runs it on 2,000 bodies for 2 steps.

// Only `env`: one run, no medians.
#[path = "common/knobs.rs"]
#[allow(dead_code)]
mod knobs;

use soda::hash::hex;
use soda::scene::builtin::builtin;
use soda::ReferenceRun;
use std::time::Instant;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// This thread's CPU time so far, s (0 where `/proc/thread-self/schedstat` is missing).
fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .map_or(0.0, |ns| ns as f64 * 1e-9)
}

/// The process's peak resident set, bytes (0 where `/proc/self/status` is missing).
fn peak_rss() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
            line.split_whitespace().nth(1)?.parse::<u64>().ok()
        })
        .map_or(0, |kb| kb * 1024)
}

/// Wall and CPU seconds of `f`, and its result.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let (t0, c0) = (Instant::now(), cpu_seconds());
    let out = f();
    (out, t0.elapsed().as_secs_f64(), cpu_seconds() - c0)
}

fn main() {
    let scene_name = std::env::var("MILLION_SCENE").unwrap_or_else(|_| "sparse-gas".into());
    let objects = knobs::env("MILLION_OBJECTS", 1_000_000, 2_000) as usize;
    let steps = knobs::env("MILLION_STEPS", 20, 2);
    let seed = knobs::env("MILLION_SEED", 0, 0);

    let (scene, wall, cpu) = timed(|| builtin(&scene_name, Some(objects), seed));
    let scene = scene.unwrap_or_else(|e| panic!("{scene_name} builds: {e}"));
    let bodies = scene.bodies.len();
    println!("million: {scene_name}, {bodies} bodies, seed {seed}");
    println!("million: build (scene and validation)  {wall:8.3} s wall {cpu:8.3} s CPU");

    let ((mut run, _left), wall, cpu) =
        timed(|| ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies()));
    println!("million: first state (bodies, binning) {wall:8.3} s wall {cpu:8.3} s CPU");

    let (last, wall, cpu) = timed(|| {
        let mut last = run.frame();
        for _ in 0..steps {
            last = run.advance();
        }
        last
    });
    let body_steps = (bodies as u64 * steps) as f64;
    println!(
        "million: {steps} steps                   {wall:8.3} s wall {cpu:8.3} s CPU \
         (final hash {}, {} bodies)",
        hex(last.hash),
        last.bodies
    );
    println!(
        "million: {:.3} M body-steps/s by wall time, {:.3} M by CPU time",
        body_steps / wall / 1e6,
        if cpu > 0.0 {
            body_steps / cpu / 1e6
        } else {
            f64::NAN
        }
    );
    let rss = peak_rss();
    println!(
        "million: peak RSS {:.1} MiB, {:.0} B per body",
        rss as f64 / (1024.0 * 1024.0),
        rss as f64 / bodies as f64
    );
}
