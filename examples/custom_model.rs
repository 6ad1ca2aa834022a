//! Your own model on SODA: heat spreading between walkers in a corridor, run on the three
//! executors (the same hash) with a scripted input, then with an input injected during the
//! run and replayed, then checked by `verify`. `cargo run --release --example custom_model`.

use soda::prelude::*;

/// A walker moves by its speed (turning at the ends) and takes a tenth of the temperature
/// difference to every walker within 0.8 m.
#[derive(Clone)]
struct Heat;

#[derive(Clone, Debug, PartialEq)]
struct Walker {
    id: u64,
    x: f32,
    speed: f32,
    heat: f32,
}

const LENGTH: f32 = 32.0;

impl CellModel for Heat {
    type State = Walker;
    type Event = LeftGrid; // no events of its own

    fn id(w: &Walker) -> BodyId {
        w.id
    }

    fn position(w: &Walker) -> [f32; 3] {
        [w.x, 0.5, 0.5]
    }

    fn step_cell(
        &self,
        _step: Step,
        _grid: &Grid,
        nb: &Neighbourhood<'_, Walker>,
        out: &mut Vec<Walker>,
        _events: &mut Vec<Event<LeftGrid>>,
    ) {
        for w in nb.own() {
            // Slots come in a fixed order, each sorted by id: the sum's order is fixed.
            let near = nb
                .iter()
                .filter(|o| o.id != w.id && (o.x - w.x).abs() < 0.8);
            let heat = w.heat + near.map(|o| 0.1 * (o.heat - w.heat)).sum::<f32>();
            let x = w.x + w.speed;
            let speed = if (0.0..LENGTH).contains(&x) {
                w.speed
            } else {
                -w.speed
            };
            let x = x.clamp(0.0, LENGTH * 0.9999);
            out.push(Walker {
                x,
                speed,
                heat,
                ..w.clone()
            });
        }
    }

    fn hash_state(w: &Walker, h: &mut StateHash) {
        h.u64(w.id);
        [w.x, w.speed, w.heat].into_iter().for_each(|v| h.f32(v));
    }
}

/// Runs the example (public so that `tests/examples.rs` runs it too).
pub fn main() -> Result<(), ExecError> {
    let grid = Grid::covering(Default::default(), [LENGTH, 1.0, 1.0].into(), 1.0);
    let walker = |i: u64, heat| Walker {
        id: i,
        x: (i as f32 * 0.37) % LENGTH,
        speed: 0.05 + 0.001 * (i % 100) as f32,
        heat,
    };
    let walkers: Vec<Walker> = (0..200).map(|i| walker(i, (i % 7) as f32 * 10.0)).collect();
    let kernel = KernelConfig::new(8);
    let all = [
        RunOptions::reference(),
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::threaded(kernel, 2),
    ];
    // A scripted input: a hot walker appears at step 60, the same bits on every executor.
    let hot = || Input::Spawn(walker(1000, 90.0));
    for options in all {
        let run = Runner::new(Heat, grid.clone(), walkers.clone()).options(options.clone());
        let report = run.input(60, hot()).run(200, |_, _, _| {})?;
        println!("{:<9} hash {}", options.executor, report.hash);
    }
    // A live input, decided while the run goes: when step 50 is committed, a hot walker
    // appears ten steps later, or at the earliest step still open: on the threaded executor
    // the worlds may have moved past any fixed step by then (GVT runs ahead of the frames
    // handed over). `input_from` returns the step the input was stamped at.
    let mut stamped = None;
    let threaded = RunOptions::threaded(KernelConfig::new(8), 2);
    let live = Runner::new(Heat, grid.clone(), walkers.clone())
        .options(threaded)
        .run(200, |frame, _, control| {
            if frame.step == 50 {
                let step = control.input_from(frame.step + 10, hot());
                stamped = Some(step.expect("a walker inside the corridor"));
            }
        })?;
    // The step it was stamped at is all a replay needs: the same input, scripted at that
    // step, gives the live run's bits on any executor.
    let step = stamped.expect("step 50 was committed");
    let replay = Runner::new(Heat, grid.clone(), walkers.clone())
        .input(step, hot())
        .run(200, |_, _, _| {})?;
    println!(
        "live input stamped at step {step}: threaded hash {}, replayed on the reference {}",
        live.hash, replay.hash
    );
    assert_eq!(live.hash, replay.hash);
    let options = VerifyOptions {
        steps: 60,
        schedules: 4,
        repeats: 2,
        ..Default::default()
    };
    let report = verify(&VerifySetup::new(Heat, grid, walkers), &options);
    print!("{}", report.summary());
    assert!(report.passed());
    Ok(())
}
