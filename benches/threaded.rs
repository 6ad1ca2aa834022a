//! Threaded executor against the reference, side by side in one run: `falling-cubes`
//! (`TH_CUBES`, default 8000) for `TH_STEPS` steps (default 600 = 10 simulated seconds),
//! the threaded executor on `TH_THREADS` threads (default 2) with each world count of
//! `TH_WORLDS` (default "2,4,8"), each window of `TH_WINDOW` (default "16") and each
//! laggard lead of `TH_LEAD` (default "0", `--lead` of `soda run`) and each setting of
//! `TH_AHEAD` (default "1": postponed worlds compute their interior ahead; "0,1" compares
//! both), `cell` mode;
//! `TH_REPS` (default 1) repetitions, each timing the reference again beside every case,
//! then the median of each case's pair ratios. Prints wall
//! times, the speed-up over the reference, efficiency, rollbacks and the threads' busy,
//! GVT and idle time, and checks every committed hash against the reference's.
//!
//! It also times rapier3d (built with `parallel`) on the same bodies on 1 and `TH_THREADS`
//! rayon threads (`TH_RAPIER=0` skips it). And in each repetition it measures this host's
//! ceiling (`TH_CEILING=0` skips it): `TH_THREADS` whole reference runs at once, one per
//! thread, sharing nothing; their throughput over one run's is what two threads can give
//! here at best, which on a shared host is less than the thread count. Wall times on a shared 2-core machine are noisy: compare within one run
//! only.
//!
//! Every run uses the `soda` binary's allocator and its settings (`MIMALLOC_PURGE_DELAY=1000`
//! restores mimalloc's default purging for comparison).
//!
//! Run: `cargo bench --bench threaded`; `cargo bench --bench threaded -- --test` (or
//! `cargo test --benches`) runs a tiny version.

#[allow(dead_code)]
mod common;
#[allow(dead_code)]
#[path = "common/rapier_world.rs"]
mod rapier_world;

use common::Footprint;
use rapier_world::RapierWorld;
use soda::exec::sync::StdFacade;
use soda::exec::threaded::{run_threaded_with, ThreadedOptions, ThreadedSetup};
use soda::kernel::{KernelConfig, RollbackMode};
use soda::scene::builtin::builtin;
use soda::ReferenceRun;
use std::time::Instant;

fn quick() -> bool {
    let args: Vec<String> = std::env::args().collect();
    !args.iter().any(|a| a == "--bench") || args.iter().any(|a| a == "--test")
}

fn env(name: &str, default: &str, quick_value: &str) -> String {
    if quick() {
        return quick_value.to_string();
    }
    std::env::var(name).unwrap_or_else(|_| default.to_string())
}

/// The `soda` binary's allocator, with its settings (`soda::app::allocator`), for the
/// reference and the threaded runs alike: what a user of the command line gets.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    soda::app::allocator::configure();
    let cubes: usize = env("TH_CUBES", "8000", "64").parse().expect("TH_CUBES");
    let steps: u64 = env("TH_STEPS", "600", "10").parse().expect("TH_STEPS");
    let threads: usize = env("TH_THREADS", "2", "2").parse().expect("TH_THREADS");
    let windows: Vec<u64> = env("TH_WINDOW", "16", "8")
        .split(',')
        .map(|w| w.trim().parse().expect("TH_WINDOW"))
        .collect();
    let leads: Vec<u64> = env("TH_LEAD", "0", "0,1")
        .split(',')
        .map(|l| l.trim().parse().expect("TH_LEAD"))
        .collect();
    let aheads: Vec<bool> = env("TH_AHEAD", "1", "1")
        .split(',')
        .map(|a| a.trim() == "1")
        .collect();
    let worlds: Vec<usize> = env("TH_WORLDS", "2,4,8", "2,4")
        .split(',')
        .map(|w| w.trim().parse().expect("TH_WORLDS"))
        .collect();
    let reps: usize = env("TH_REPS", "1", "1").parse().expect("TH_REPS");
    let scene = builtin("falling-cubes", Some(cubes), 0).expect("scene");
    let run_reference = || {
        let (mut reference, _) =
            ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
        let t = Instant::now();
        let hashes: Vec<u64> = (0..steps).map(|_| reference.advance().hash).collect();
        (hashes, t.elapsed().as_secs_f64())
    };
    let (expected, tr) = run_reference();
    println!(
        "threaded: falling-cubes {cubes}, {steps} steps, grid {:?}; reference {tr:.2} s ({:.0} body-steps/s)",
        scene.grid().dims,
        cubes as f64 * steps as f64 / tr
    );
    let rapier = |threads: usize| {
        let initial = scene.initial_bodies();
        let footprint = Footprint::of(&initial);
        let mut world = RapierWorld::new(&scene, &initial, &footprint);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let t = Instant::now();
        pool.install(|| (0..steps).for_each(|_| world.step()));
        t.elapsed().as_secs_f64()
    };
    if env("TH_RAPIER", "1", "1") != "0" {
        let (r1, r2) = (rapier(1), rapier(threads));
        println!(
            "  rapier3d (parallel feature, sleeping on): 1 thread {r1:.2} s, {threads} threads {r2:.2} s = {:.2}x its 1-thread speed; SODA's reference is {:.1}x Rapier's 1-thread time",
            r1 / r2,
            tr / r1
        );
    }
    let cases: Vec<(usize, u64, u64, bool)> = worlds
        .iter()
        .flat_map(|&w| {
            let (leads, aheads) = (&leads, &aheads);
            windows.iter().flat_map(move |&v| {
                leads
                    .iter()
                    .flat_map(move |&l| aheads.iter().map(move |&a| (w, v, l, a)))
            })
        })
        .collect();
    // Each repetition times the reference again, then every case: the speed-up of a case is
    // the median over repetitions of (reference time / case time) measured side by side.
    let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); cases.len()];
    let mut ceilings: Vec<f64> = Vec::new();
    let ceiling = env("TH_CEILING", "1", "1") != "0";
    for rep in 0..reps {
        let tr = if rep == 0 { tr } else { run_reference().1 };
        if rep > 0 {
            println!("  rep {}: reference {tr:.2} s", rep + 1);
        }
        if ceiling {
            // What this host gives two threads that share nothing: `threads` whole
            // reference runs at once, each on its own thread. Their throughput over one
            // reference run's is the speed-up no executor can beat here (`threads` on an
            // idle host with a core per thread; less when the host's other guests take
            // their share, or when the cores share caches).
            // Each run's stepping time, as `tr` is timed (setup excluded); the slowest sets
            // the pace.
            let together = std::thread::scope(|s| {
                let runs: Vec<_> = (0..threads)
                    .map(|_| {
                        s.spawn(|| {
                            let (hashes, seconds) = run_reference();
                            assert_eq!(hashes, expected);
                            seconds
                        })
                    })
                    .collect();
                runs.into_iter()
                    .map(|r| r.join().expect("a reference run beside the other"))
                    .fold(0.0, f64::max)
            });
            let c = threads as f64 * tr / together;
            ceilings.push(c);
            println!(
                "  ceiling: {threads} reference runs side by side on {threads} threads took {together:.2} s = {c:.2}x one run's throughput"
            );
        }
        for (k, &(w, window, lead, ahead)) in cases.iter().enumerate() {
            let config = KernelConfig::new(w).mode(RollbackMode::Cell).window(window);
            let r = run_threaded_with::<_, StdFacade>(
                ThreadedSetup::new(scene.model(), scene.grid(), scene.initial_bodies()),
                &ThreadedOptions::new(&config, threads, steps)
                    .lead(lead)
                    .compute_ahead(ahead),
                |_, _| {},
            )
            .expect("threaded run");
            let got: Vec<u64> = r.frames.iter().map(|f| f.hash).collect();
            assert_eq!(got, expected, "threaded run diverged from the reference");
            ratios[k].push(tr / r.wall_seconds);
            let c = &r.counters.total;
            let tt = &r.times;
            println!(
                "  {threads} threads, {w:2} worlds, cell W{window}, lead {lead}, ahead {ahead}: {:.2} s = {:.2}x the reference's speed; efficiency {:.3}, rollbacks {} ({} steps), cells re-executed {}, messages {} + {} anti; thread time busy {:.2} s (ahead {:.2} s), gvt {:.2} s, idle {:.2} s, steals {}, moves {}",
                r.wall_seconds,
                tr / r.wall_seconds,
                c.efficiency(),
                c.rollbacks(),
                c.steps_rolled_back,
                c.cells_recomputed,
                c.messages_sent,
                c.anti_messages_sent,
                tt.busy_seconds,
                tt.ahead_seconds,
                tt.gvt_seconds,
                tt.idle_seconds,
                tt.steals,
                tt.moves
            );
        }
    }
    if reps > 1 {
        if ceiling {
            let mut c = ceilings.clone();
            c.sort_by(f64::total_cmp);
            println!(
                "  median ceiling of {reps}: {:.2}x (runs: {})",
                c[c.len() / 2],
                c.iter()
                    .map(|x| format!("{x:.2}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        for (k, &(w, window, lead, ahead)) in cases.iter().enumerate() {
            let mut r = ratios[k].clone();
            r.sort_by(f64::total_cmp);
            println!(
                "  median of {reps} pair ratios, {w} worlds, W{window}, lead {lead}, ahead {ahead}: {:.2}x the reference's speed (runs: {})",
                r[r.len() / 2],
                r.iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>().join(", ")
            );
        }
    }
}
