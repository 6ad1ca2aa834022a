//! The example SIR epidemic among flocking agents (births, deaths, model events) on every
//! executor: the same hash, and the epidemic's course from the model's own events.
//! `cargo run --release --example epidemic [AGENTS] [STEPS]`.

use soda::models::epidemic::Epidemic;
use soda::prelude::*;

fn main() -> Result<(), ExecError> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (agents, steps) = (
        args.first().copied().unwrap_or(2000),
        args.get(1).copied().unwrap_or(300),
    );
    let scene = || Epidemic::default().scene(agents as usize, 10, [16, 4, 16], 42);
    let kernel = KernelConfig::new(8).window(16);
    for options in [
        RunOptions::reference(),
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::threaded(kernel, 2),
    ] {
        let (model, grid, initial) = scene();
        let report = Runner::new(model, grid, initial)
            .options(options.clone())
            .run_quiet(steps)?;
        println!(
            "{:<9} {steps} steps  hash {}  {} agents  {:.0} agent-steps/s  events {:?}",
            options.executor,
            report.hash,
            report.entities,
            report.entity_steps_per_second,
            report.events
        );
    }
    Ok(())
}
