//! The PHOLD-like workload: committed entity-steps per second per core on the reference and
//! the threaded executor, beside ROSS's published PHOLD rate (about 256 k committed events
//! per second per core). The workloads differ: a PHOLD event is one job processed at one
//! logical process with a random timestamp increment; here every job is processed at every
//! step, with `grain` rounds of mixing and a `coupling` read of its neighbours.
//! `cargo run --release --example phold [PER_CELL] [REMOTE] [GRAIN] [COUPLING] [STEPS]`.

use soda::models::phold::{Phold, PholdParams};
use soda::prelude::*;

fn main() -> Result<(), ExecError> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |k: usize, d: f64| a.get(k).and_then(|s| s.parse().ok()).unwrap_or(d);
    let params = PholdParams {
        dims: [32, 32, 4],
        per_cell: get(0, 4.0) as usize,
        remote: get(1, 0.1) as f32,
        grain: get(2, 64.0) as u32,
        coupling: get(3, 0.5) as f32,
        seed: 7,
    };
    let steps = get(4, 200.0) as u64;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    println!("PHOLD-like: {params:?}, {steps} steps");
    println!("executor   cores  entity-steps/s   per core   hash");
    for (options, cores) in [
        (RunOptions::reference(), 1),
        (
            RunOptions::threaded(KernelConfig::new(4 * threads), threads),
            threads,
        ),
    ] {
        let (model, grid, initial) = Phold::scene(params.clone());
        let r = Runner::new(model, grid, initial)
            .options(options.clone())
            .run_quiet(steps)?;
        let rate = r.entity_steps_per_second;
        println!(
            "{:<10} {cores:>5}  {rate:>14.0}  {:>9.0}   {}",
            options.executor,
            rate / cores as f64,
            r.hash
        );
    }
    println!("ROSS PHOLD (published): ~256,000 committed events/s per core");
    Ok(())
}
