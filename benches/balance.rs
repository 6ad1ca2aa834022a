//! Load balancing off against on, side by side in one run: the built-in `skewed` scene
//! (`BAL_OBJECTS` cubes, default 2000, all in one corner) for `BAL_STEPS` steps (default
//! 200) with `BAL_WORLDS` worlds (default 8) on `BAL_THREADS` threads (default 2), `cell`
//! mode, window 16, partition `BAL_PARTITION` (default `equal-blocks`: equal territories, so
//! the skewed load starts unbalanced; `blocks` cuts where the bodies balance and leaves
//! balancing little to do). Runs off and on alternately `BAL_REPEATS` times
//! (default 3), with the threaded laggard lead `BAL_LEAD` (default 0), thresholds
//! `BAL_THRESHOLDS=U,H,O` (default 0.8,1.05,1.5), backoff `BAL_BACKOFF=on|off` (default on)
//! and ghost policy `BAL_GHOSTS`
//! (delta or full, default delta), and prints each run's wall time, the medians and their ratio (and the
//! median of the pair speed-ups), the run-wide
//! imbalance (max/mean busy seconds per world) and the balancing counters; every run's
//! committed hashes must be identical. Each run also shows the CPU other processes took
//! meanwhile (`other cores`, from `/proc`), and the medians are repeated over the pairs where
//! it stayed below 0.1 core: a neighbour on one of two cores slows the balanced run, which
//! needs both, and not the unbalanced one, which is effectively serial.
//!
//! The timed "on" runs use the default backoff (SPEC.md §K13: idle rounds thin out).
//! Imbalance over time: one more run of each with a balancing round every `BAL_PERIOD`
//! steps (default 20, no backoff) — "off" as a monitor only (thresholds that never trigger a move, so it
//! pays the same rounds) — written with the on run's cells moved per round to
//! `target/balance/imbalance.csv`.
//!
//! Wall times on a shared 2-core machine are noisy: compare within one run, read the
//! medians. Run: `cargo bench --bench balance`; `cargo bench --bench balance -- --test` (or
//! `cargo test --benches`) runs a tiny version.

/// The `soda` binary's allocator (src/main.rs), so the bench measures what the CLI runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[path = "common/knobs.rs"]
mod knobs;

use knobs::{env, median, median_ratio};
use soda::exec::sync::StdFacade;
use soda::exec::threaded::{run_threaded_with, ThreadedOptions, ThreadedReport, ThreadedSetup};
use soda::kernel::{BalanceConfig, GhostPolicy, KernelConfig, PartitionKind, RollbackMode};
use soda::scene::builtin::builtin;
use std::io::Write;

fn main() {
    let objects = env("BAL_OBJECTS", 2000, 200) as usize;
    let steps = env("BAL_STEPS", 200, 30);
    let worlds = env("BAL_WORLDS", 8, 8) as usize;
    let threads = env("BAL_THREADS", 2, 2) as usize;
    let repeats = env("BAL_REPEATS", 3, 1);
    let period = env("BAL_PERIOD", 20, 10);
    let lead = env("BAL_LEAD", 0, 0);
    let ghosts = match std::env::var("BAL_GHOSTS").as_deref() {
        Ok("full") => GhostPolicy::Full,
        _ => GhostPolicy::Delta,
    };
    let partition: PartitionKind = std::env::var("BAL_PARTITION")
        .as_deref()
        .unwrap_or("equal-blocks")
        .parse()
        .expect("BAL_PARTITION");
    let scene = builtin("skewed", Some(objects), 0).expect("built-in scene");
    let mut on = BalanceConfig {
        period,
        ..BalanceConfig::on()
    };
    // `BAL_BACKOFF=off` holds a round every period in the timed runs too.
    on.backoff = std::env::var("BAL_BACKOFF").as_deref() != Ok("off");
    // `BAL_THRESHOLDS=U,H,O` replaces the load-level thresholds (as `--balance-thresholds`).
    if let Ok(t) = std::env::var("BAL_THRESHOLDS") {
        let v: Vec<f64> = t
            .split(',')
            .map(|x| {
                x.trim()
                    .parse()
                    .expect("BAL_THRESHOLDS: three numbers U,H,O")
            })
            .collect();
        let [u, h, o] = v[..] else {
            panic!("BAL_THRESHOLDS: three numbers U,H,O, got `{t}`");
        };
        (on.underloaded, on.high, on.overloaded) = (u, h, o);
    }
    // The runs that chart imbalance over time hold a round every period (no backoff), so
    // both sample the same steps.
    let every_period = BalanceConfig {
        backoff: false,
        ..on.clone()
    };
    let monitor = BalanceConfig {
        underloaded: 1e-12,
        high: 1e12,
        overloaded: 1e12,
        ..every_period.clone()
    };
    let run = |balance: &BalanceConfig| -> ThreadedReport<soda::EventKind> {
        let config = KernelConfig::new(worlds)
            .mode(RollbackMode::Cell)
            .window(16)
            .ghosts(ghosts)
            .partition(partition.clone())
            .balance(balance.clone());
        run_threaded_with::<_, StdFacade>(
            ThreadedSetup::new(scene.model(), scene.grid(), scene.initial_bodies()),
            &ThreadedOptions::new(&config, threads, steps).lead(lead),
            |_, _| {},
        )
        .expect("threaded run")
    };
    println!(
        "skewed, {objects} cubes, {steps} steps, {worlds} worlds on {threads} threads, \
         partition {partition}, balancing period {period}"
    );
    println!(
        "run  balance  wall s  imbalance  rounds  cells moved  famines  busy s  idle s  gvt s  \
         other cores  hash"
    );
    let mut hash = None;
    let mut walls = [Vec::new(), Vec::new()];
    // Per pair, whether other processes left the machine to this bench (see `OtherCpu`).
    let mut quiet_pairs = Vec::new();
    for r in 0..repeats {
        let mut quiet = true;
        for (k, balance) in [BalanceConfig::default(), on.clone()].iter().enumerate() {
            let other = OtherCpu::start();
            let rep = run(balance);
            let other_cores = other.cores();
            quiet &= other_cores.is_some_and(|c| c < QUIET_CORES);
            let last = rep.frames.last().map(|f| f.hash).unwrap_or(0);
            assert_eq!(
                *hash.get_or_insert(last),
                last,
                "balancing changed the result"
            );
            let b = &rep.counters.balance;
            println!(
                "{r:>3}  {:>7}  {:>6.3}  {:>9.3}  {:>6}  {:>11}  {:>7}  {:>6.2}  {:>6.2}  {:>5.2}  \
                 {:>11}  {last:016x}",
                if balance.enabled { "on" } else { "off" },
                rep.wall_seconds,
                b.imbalance,
                b.rounds,
                b.cells_moved,
                b.famines,
                rep.times.busy_seconds,
                rep.times.idle_seconds,
                rep.times.gvt_seconds,
                other_cores.map_or("?".to_string(), |c| format!("{c:.2}")),
            );
            walls[k].push(rep.wall_seconds);
        }
        quiet_pairs.push(quiet);
    }
    let off_m = median(&walls[0]);
    let on_m = median(&walls[1]);
    println!(
        "median wall: off {off_m:.3} s, on {on_m:.3} s, speed-up with balancing {:.2}x \
         (median of the {repeats} pair speed-ups {:.2}x)",
        off_m / on_m,
        median_ratio(&walls[0], &walls[1])
    );
    let quiet_walls = |k: usize| -> Vec<f64> {
        walls[k]
            .iter()
            .zip(&quiet_pairs)
            .filter(|(_, &q)| q)
            .map(|(&w, _)| w)
            .collect()
    };
    let (quiet_off, quiet_on) = (quiet_walls(0), quiet_walls(1));
    if quiet_off.is_empty() {
        println!("no pair ran with other processes below {QUIET_CORES} cores");
    } else {
        let (q_off, q_on) = (median(&quiet_off), median(&quiet_on));
        println!(
            "median wall of the {} of {repeats} pairs with other processes below {QUIET_CORES} \
             cores: off {q_off:.3} s, on {q_on:.3} s, {:.2}x",
            quiet_off.len(),
            q_off / q_on
        );
    }
    let watched = run(&monitor);
    let balanced = run(&every_period);
    let dir = std::path::Path::new("target/balance");
    std::fs::create_dir_all(dir).expect("target/balance");
    let path = dir.join("imbalance.csv");
    let mut f = std::fs::File::create(&path).expect("imbalance.csv");
    writeln!(
        f,
        "step,imbalance_off,imbalance_on,cells_moved_on,famines_on"
    )
    .expect("write");
    // The time T threads need at best for each period's measured per-world CPU seconds:
    // the busiest world, or the total shared by T threads, whichever is longer.
    let modelled = |rounds: &[soda::kernel::RoundRecord]| -> f64 {
        let mut last = 0;
        let mut total = 0.0;
        for r in rounds {
            let span = (r.step - last) as f64;
            let max = r.loads.iter().copied().fold(0.0, f64::max);
            let sum: f64 = r.loads.iter().sum();
            total += span * max.max(sum / threads as f64);
            last = r.step;
        }
        total
    };
    let (m_off, m_on) = (modelled(&watched.balance), modelled(&balanced.balance));
    let cpu = |rounds: &[soda::kernel::RoundRecord]| -> f64 {
        let mut last = 0;
        let mut total = 0.0;
        for r in rounds {
            total += (r.step - last) as f64 * r.loads.iter().sum::<f64>();
            last = r.step;
        }
        total
    };
    println!(
        "CPU seconds of the worlds' actions, steps 1..={}: off {:.3} s, on {:.3} s",
        watched.balance.last().map_or(0, |r| r.step),
        cpu(&watched.balance),
        cpu(&balanced.balance)
    );
    println!(
        "modelled {threads}-thread time of steps 1..={} from per-world CPU seconds: off {m_off:.3} s, \
         on {m_on:.3} s, speed-up {:.2}x (wall: monitor-off {:.3} s, on {:.3} s)",
        watched.balance.last().map_or(0, |r| r.step),
        m_off / m_on.max(1e-12),
        watched.wall_seconds,
        balanced.wall_seconds
    );
    println!("step  imbalance off  imbalance on  cells moved  famines");
    for (a, b) in watched.balance.iter().zip(&balanced.balance) {
        writeln!(
            f,
            "{},{:.4},{:.4},{},{}",
            a.step, a.imbalance, b.imbalance, b.cells_moved, b.famines
        )
        .expect("write");
        println!(
            "{:>4}  {:>13.3}  {:>12.3}  {:>11}  {:>7}",
            a.step, a.imbalance, b.imbalance, b.cells_moved, b.famines
        );
    }
    println!("wrote {}", path.display());
}

/// Other processes' CPU below which a pair of runs counts as quiet, in cores.
const QUIET_CORES: f64 = 0.1;

/// CPU time other processes took while a run ran, from `/proc` (Linux; `None` elsewhere):
/// the machine's busy ticks minus this process's, over the elapsed ticks of all cores. On a
/// 2-core machine a single-threaded neighbour (a compiler, a profiler) takes the core the
/// balanced run needs and none that the unbalanced, effectively serial run needs, so its
/// wall-time ratio is only meaningful beside this.
struct OtherCpu {
    start: Option<(u64, u64, u64)>,
}

impl OtherCpu {
    fn start() -> Self {
        OtherCpu {
            start: Self::ticks(),
        }
    }

    /// Cores' worth of CPU other processes used since `start`.
    fn cores(&self) -> Option<f64> {
        let (busy0, all0, own0) = self.start?;
        let (busy1, all1, own1) = Self::ticks()?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        let other = (busy1 - busy0).saturating_sub(own1 - own0) as f64;
        Some(other / (all1 - all0).max(1) as f64 * cores)
    }

    /// (busy ticks of all cores, all ticks of all cores, this process's user + system ticks).
    fn ticks() -> Option<(u64, u64, u64)> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let cpu: Vec<u64> = stat
            .lines()
            .next()?
            .split_whitespace()
            .skip(1)
            .filter_map(|x| x.parse().ok())
            .collect();
        // user nice system idle iowait irq softirq steal (guest time is inside user).
        let all: u64 = cpu.iter().take(8).sum();
        let busy = all - cpu.get(3)? - cpu.get(4)?;
        let me = std::fs::read_to_string("/proc/self/stat").ok()?;
        // Fields after the parenthesised name: utime and stime are the 12th and 13th.
        let rest: Vec<&str> = me.rsplit_once(')')?.1.split_whitespace().collect();
        let own = rest.get(11)?.parse::<u64>().ok()? + rest.get(12)?.parse::<u64>().ok()?;
        Some((busy, all, own))
    }
}
