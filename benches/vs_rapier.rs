//! SODA's reference run against rapier3d (single-threaded, its defaults) on `falling-cubes`,
//! side by side in one process.
//!
//! Both engines start from the same bodies — `builtin("falling-cubes", Some(n), 0)`, the same
//! lattice and jitter — and run 600 steps of 1/60 s (10 simulated seconds). Rapier gets its
//! defaults (`IntegrationParameters::default()`, sleeping on; built with `parallel` but run in
//! a one-thread rayon pool) and a
//! ground: a fixed cuboid collider whose top is y = 0, with the scene's ground friction and
//! restitution; each cube gets the scene's density, friction and restitution.
//!
//! Only the stepping is timed (world construction and measurement are not). Runs alternate
//! (SODA then Rapier, then Rapier then SODA, ...) for up to `SODA_BENCH_REPS` repetitions
//! (default 3) while a size's time budget `SODA_BENCH_BUDGET_S` (default 150 s) allows; the
//! reported wall time is the median. Final states are measured by the same code for both
//! engines (benches/common): exact penetration with parry3d's `query::contact`, max speed,
//! highest centre, distance outside the initial x/z footprint.
//!
//! `cargo bench --bench vs_rapier` (cargo passes `--bench`) runs the full comparison, prints
//! a markdown table and writes it as JSON to target/vs_rapier.json. Without `--bench` (as under
//! `cargo test --benches`) or with `--test` (`cargo bench -- --test`) it runs a 20-step smoke
//! version on 1,000 cubes and writes nothing.
//! `SODA_BENCH_SIZES=1000,8000` selects the sizes (default both). `SODA_BENCH_ENGINES=soda`
//! (or `rapier`) runs one engine only, for quick quality checks; the ratio is then absent.
//! `SODA_BENCH_STEPS` replaces the 600 steps (e.g. 3600 for 60 simulated seconds).

mod common;
#[path = "common/knobs.rs"]
#[allow(dead_code)]
mod knobs;
#[path = "common/rapier_world.rs"]
mod rapier_world;

use rapier_world::RapierWorld;

use common::{measure_pile, soda_pile, Footprint, PileBody, PileMetrics};
use knobs::median;
use serde::Serialize;
use soda::physics::Body;
use soda::scene::builtin::builtin;
use soda::scene::Scene;
use soda::sim::Simulation;
use soda::EventKind;
use std::path::PathBuf;
use std::time::Instant;

const FULL_STEPS: u64 = 600;
const SMOKE_STEPS: u64 = 20;

/// What one engine did on one size.
#[derive(Clone, Debug, Serialize)]
struct EngineResult {
    engine: &'static str,
    cubes: usize,
    steps: u64,
    /// Wall time of every repetition, in the order run, s.
    wall_seconds: Vec<f64>,
    /// Median of `wall_seconds`, s.
    wall_median_seconds: f64,
    /// Body-steps per second at the median.
    body_steps_per_second: f64,
    /// Whether every repetition ended in the same state (bit-identical).
    repeatable: bool,
    /// Final-state hash (SODA: its canonical hash; Rapier: FNV-1a over pose bits).
    final_hash: String,
    /// The final state, measured by benches/common.
    end: PileMetrics,
    /// SODA only: speed-capped events over the run.
    speed_capped_events: Option<usize>,
    /// SODA only: bodies removed for leaving the domain over the run.
    left_domain_events: Option<usize>,
    /// SODA only: max penetration as SODA's own `sim::measure` reports it (a cross-check).
    soda_measure_max_penetration: Option<f32>,
    /// Rapier only: bodies asleep at the end.
    asleep: Option<usize>,
}

/// Both engines on one size.
#[derive(Clone, Debug, Serialize)]
struct Comparison {
    cubes: usize,
    steps: u64,
    dt: f32,
    repetitions: usize,
    footprint: Footprint,
    soda: Option<EngineResult>,
    rapier: Option<EngineResult>,
    /// SODA's median wall time over Rapier's (when both ran).
    ratio_soda_over_rapier: Option<f64>,
}

/// One timed run's outcome: wall time, final hash and the end state.
struct Run {
    wall: f64,
    hash: u64,
    pile: Vec<PileBody>,
    extra: Extra,
}

enum Extra {
    Soda {
        capped: usize,
        left: usize,
        measured_penetration: f32,
    },
    Rapier {
        asleep: usize,
    },
}

/// With `SODA_BENCH_TRACE=1`, the first repetition prints, once per simulated second, the
/// wall time so far and the pile's state (the measuring is then inside the timing).
fn trace_enabled() -> bool {
    std::env::var("SODA_BENCH_TRACE").is_ok_and(|v| v == "1")
}

fn trace(engine: &str, step: u64, wall: f64, pile: &[PileBody], fp: &Footprint, extra: &str) {
    let speed = pile.iter().map(|b| b.linvel.norm()).fold(0.0f32, f32::max);
    let out = pile
        .iter()
        .map(|b| fp.outside(&b.position))
        .fold(0.0f32, f32::max);
    let far = pile
        .iter()
        .filter(|b| fp.outside(&b.position) > 2.0)
        .count();
    eprintln!(
        "trace {engine:6} step {step:4}: wall {wall:8.3} s, {} bodies, max speed {speed:7.3}, \
         max outside footprint {out:6.2} m, {far} more than 2 m outside{extra}",
        pile.len()
    );
}

fn run_soda(scene: &Scene, steps: u64, check: bool) -> Run {
    let mut sim = Simulation::new(scene.clone());
    let (mut capped, mut left) = (0, 0);
    let tracing = check && trace_enabled();
    let fp = Footprint::of(&scene.initial_bodies());
    let start = Instant::now();
    for step in 1..=steps {
        let f = sim.step();
        for e in &f.events {
            match e.kind {
                EventKind::SpeedCapped => capped += 1,
                EventKind::LeftDomain => left += 1,
            }
        }
        if tracing && step % 60 == 0 {
            let w = start.elapsed().as_secs_f64();
            let events = format!(", {capped} speed-capped, {left} left domain so far");
            trace("SODA", step, w, &soda_pile(sim.state()), &fp, &events);
        }
    }
    let wall = start.elapsed().as_secs_f64();
    // SODA's own measurement is a cross-check, computed on the first repetition only.
    let measured_penetration = if check {
        soda::sim::measure(sim.reference()).max_penetration
    } else {
        f32::NAN
    };
    Run {
        wall,
        hash: sim.state().hash::<soda::physics::RigidBodyModel>(),
        pile: soda_pile(sim.state()),
        extra: Extra::Soda {
            capped,
            left,
            measured_penetration,
        },
    }
}

fn run_rapier(
    scene: &Scene,
    initial: &[Body],
    footprint: &Footprint,
    steps: u64,
    first: bool,
) -> Run {
    let mut world = RapierWorld::new(scene, initial, footprint);
    let tracing = first && trace_enabled();
    // rapier3d is built with its `parallel` feature (for the threaded bench): a one-thread
    // rayon pool keeps this comparison single-threaded.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    let start = Instant::now();
    pool.install(|| {
        for step in 1..=steps {
            world.step();
            if tracing && step % 60 == 0 {
                let w = start.elapsed().as_secs_f64();
                let asleep = format!(", {} asleep", world.asleep());
                trace("Rapier", step, w, &world.pile(initial), footprint, &asleep);
            }
        }
    });
    let wall = start.elapsed().as_secs_f64();
    let asleep = world.asleep();
    Run {
        wall,
        hash: world.hash(),
        pile: world.pile(initial),
        extra: Extra::Rapier { asleep },
    }
}

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} is not a valid value")),
        Err(_) => default,
    }
}

fn sizes(full: bool) -> Vec<usize> {
    match std::env::var("SODA_BENCH_SIZES") {
        Ok(v) => v
            .split(',')
            .map(|s| {
                s.trim()
                    .parse()
                    .unwrap_or_else(|_| panic!("SODA_BENCH_SIZES: {s:?} is not a count"))
            })
            .collect(),
        Err(_) if full => vec![1000, 8000],
        Err(_) => vec![1000],
    }
}

/// Which engines run: `SODA_BENCH_ENGINES` (`soda`, `rapier` or both, comma-separated).
fn engines() -> (bool, bool) {
    match knobs::list("SODA_BENCH_ENGINES") {
        Some(names) => {
            for n in &names {
                assert!(
                    n == "soda" || n == "rapier",
                    "SODA_BENCH_ENGINES: {n:?} is not `soda` or `rapier`"
                );
            }
            (
                names.iter().any(|n| n == "soda"),
                names.iter().any(|n| n == "rapier"),
            )
        }
        None => (true, true),
    }
}

fn result(
    engine: &'static str,
    cubes: usize,
    steps: u64,
    runs: &[Run],
    ground_y: f32,
    footprint: &Footprint,
) -> EngineResult {
    let walls: Vec<f64> = runs.iter().map(|r| r.wall).collect();
    let first = &runs[0];
    let med = median(&walls);
    let mut r = EngineResult {
        engine,
        cubes,
        steps,
        wall_median_seconds: med,
        body_steps_per_second: (cubes as u64 * steps) as f64 / med,
        wall_seconds: walls,
        repeatable: runs.iter().all(|r| r.hash == first.hash),
        final_hash: format!("{:016x}", first.hash),
        end: measure_pile(&first.pile, ground_y, footprint),
        speed_capped_events: None,
        left_domain_events: None,
        soda_measure_max_penetration: None,
        asleep: None,
    };
    match first.extra {
        Extra::Soda {
            capped,
            left,
            measured_penetration,
        } => {
            r.speed_capped_events = Some(capped);
            r.left_domain_events = Some(left);
            r.soda_measure_max_penetration = Some(measured_penetration);
        }
        Extra::Rapier { asleep } => r.asleep = Some(asleep),
    }
    r
}

fn compare(cubes: usize, steps: u64, reps: usize, budget: f64) -> Comparison {
    let scene = builtin("falling-cubes", Some(cubes), 0).expect("falling-cubes builds");
    let initial = scene.initial_bodies();
    let footprint = Footprint::of(&initial);
    let ground_y = scene
        .environment
        .ground
        .expect("falling-cubes has a ground");
    let (mut soda_runs, mut rapier_runs) = (Vec::new(), Vec::new());
    let (with_soda, with_rapier) = engines();
    let mut spent = 0.0;
    for rep in 0..reps {
        // Alternate the order so neither engine always runs second (warmer caches, a
        // neighbour's build finishing, ...).
        for soda_turn in [rep % 2 == 0, rep % 2 == 1] {
            if (soda_turn && !with_soda) || (!soda_turn && !with_rapier) {
                continue;
            }
            if soda_turn {
                let r = run_soda(&scene, steps, rep == 0);
                eprintln!(
                    "vs_rapier: {cubes} cubes, rep {}: SODA   {:.3} s",
                    rep + 1,
                    r.wall
                );
                spent += r.wall;
                soda_runs.push(r);
            } else {
                let r = run_rapier(&scene, &initial, &footprint, steps, rep == 0);
                eprintln!(
                    "vs_rapier: {cubes} cubes, rep {}: Rapier {:.3} s",
                    rep + 1,
                    r.wall
                );
                spent += r.wall;
                rapier_runs.push(r);
            }
        }
        let per_rep = spent / (rep + 1) as f64;
        if rep + 1 < reps && spent + per_rep > budget {
            eprintln!(
                "vs_rapier: {cubes} cubes: stopping after {} repetition(s), another would pass \
                 the {budget:.0} s budget (SODA_BENCH_BUDGET_S)",
                rep + 1
            );
            break;
        }
    }
    let soda = (!soda_runs.is_empty())
        .then(|| result("SODA", cubes, steps, &soda_runs, ground_y, &footprint));
    let rapier = (!rapier_runs.is_empty())
        .then(|| result("Rapier", cubes, steps, &rapier_runs, ground_y, &footprint));
    let ratio = match (&soda, &rapier) {
        (Some(s), Some(r)) => Some(s.wall_median_seconds / r.wall_median_seconds),
        _ => None,
    };
    Comparison {
        cubes,
        steps,
        dt: scene.dt,
        repetitions: soda_runs.len().max(rapier_runs.len()),
        footprint,
        ratio_soda_over_rapier: ratio,
        soda,
        rapier,
    }
}

fn table(rows: &[Comparison]) -> String {
    let mut s = String::from(
        "| cubes | engine | wall s (median) | runs, s | SODA/Rapier | body-steps/s | \
         max penetration m | max speed m/s | highest centre m | outside footprint m | \
         > 2 m outside | bodies at end | notes |\n\
         |---:|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|\n",
    );
    for c in rows {
        for r in [&c.soda, &c.rapier].into_iter().flatten() {
            let runs: Vec<String> = r.wall_seconds.iter().map(|w| format!("{w:.3}")).collect();
            let ratio = match (r.engine, c.ratio_soda_over_rapier) {
                ("SODA", Some(x)) => format!("{x:.2}×"),
                ("SODA", None) => "–".into(),
                _ => "1".into(),
            };
            let mut notes = Vec::new();
            if let Some(n) = r.asleep {
                notes.push(format!("{n} asleep"));
            }
            if let (Some(cap), Some(left)) = (r.speed_capped_events, r.left_domain_events) {
                notes.push(format!("{cap} speed-capped, {left} left domain"));
            }
            if !r.repeatable {
                notes.push("NOT repeatable across runs".into());
            }
            s += &format!(
                "| {} | {} | {:.3} | {} | {} | {:.0} | {:.4} | {:.3} | {:.2} | {:.2} | {} | {} | {} |\n",
                c.cubes,
                r.engine,
                r.wall_median_seconds,
                runs.join(", "),
                ratio,
                r.body_steps_per_second,
                r.end.max_penetration,
                r.end.max_speed,
                r.end.highest_centre,
                r.end.max_outside_footprint,
                r.end.bodies_more_than_2m_outside,
                r.end.bodies,
                notes.join("; "),
            );
        }
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let full = args.iter().any(|a| a == "--bench") && !args.iter().any(|a| a == "--test");
    let steps = if full {
        env_or("SODA_BENCH_STEPS", FULL_STEPS)
    } else {
        SMOKE_STEPS
    };
    let reps = if full {
        env_or("SODA_BENCH_REPS", 3usize).max(1)
    } else {
        1
    };
    let budget = env_or("SODA_BENCH_BUDGET_S", 150.0f64);
    let sizes = sizes(full);
    eprintln!(
        "vs_rapier: {} mode, {steps} steps, sizes {sizes:?}, up to {reps} alternating \
         repetition(s), budget {budget:.0} s per size",
        if full {
            "benchmark"
        } else {
            "smoke (no --bench)"
        }
    );
    let rows: Vec<Comparison> = sizes
        .iter()
        .map(|&n| compare(n, steps, reps, budget))
        .collect();
    let t = table(&rows);
    println!(
        "\nfalling-cubes, seed 0, {steps} steps of 1/60 s, single thread; runs alternate \
         between the engines; only stepping is timed\n"
    );
    println!("{t}");
    if full {
        let path = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target"))
            .join("vs_rapier.json");
        let json = serde_json::json!({
            "scene": "falling-cubes",
            "seed": 0,
            "comparisons": rows,
            "table_markdown": t,
        });
        std::fs::write(
            &path,
            serde_json::to_string_pretty(&json).expect("serialises"),
        )
        .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        println!("written to {}", path.display());
    }
}
