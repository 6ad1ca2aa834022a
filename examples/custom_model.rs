//! Your own model on SODA: heat spreading between walkers in a corridor, run on the three
//! executors (the same hash) with an input injected during the run, then checked by
//! `verify`. `cargo run --release --example custom_model`.

use soda::prelude::*;

/// Each step a walker moves by its speed (turning at the corridor's ends) and takes a tenth
/// of the temperature difference to every walker within 0.8 m.
#[derive(Clone)]
struct Heat {
    length: f32,
}

#[derive(Clone, Debug, PartialEq)]
struct Walker {
    id: u64,
    pos: [f32; 3],
    speed: f32,
    temperature: f32,
}

impl CellModel for Heat {
    type State = Walker;
    type Event = LeftGrid; // no events of its own

    fn id(w: &Walker) -> BodyId {
        w.id
    }

    fn position(w: &Walker) -> [f32; 3] {
        w.pos
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
            let mut t = w.temperature;
            // Slots come in a fixed order, each sorted by id: the sum's order is fixed.
            for o in nb.iter().filter(|o| self.may_affect(w, o) && o.id != w.id) {
                t += 0.1 * (o.temperature - w.temperature);
            }
            let x = w.pos[0] + w.speed;
            let speed = if x < 0.0 || x >= self.length {
                -w.speed
            } else {
                w.speed
            };
            let pos = [x.clamp(0.0, self.length * 0.9999), w.pos[1], w.pos[2]];
            out.push(Walker {
                pos,
                speed,
                temperature: t,
                ..w.clone()
            });
        }
    }

    fn may_affect(&self, reader: &Walker, other: &Walker) -> bool {
        (reader.pos[0] - other.pos[0]).abs() < 0.8
    }

    fn hash_state(w: &Walker, h: &mut StateHash) {
        h.u64(w.id);
        w.pos
            .iter()
            .chain([&w.speed, &w.temperature])
            .for_each(|&v| h.f32(v));
    }
}

fn main() -> Result<(), ExecError> {
    let (min, max) = (
        soda::math::Vec3::zeros(),
        soda::math::Vec3::new(32.0, 1.0, 1.0),
    );
    let grid = Grid::covering(min, max, 1.0);
    let walker = |i: u64, temperature| Walker {
        id: i,
        pos: [(i as f32 * 0.37) % 32.0, 0.5, 0.5],
        speed: 0.05 + 0.001 * (i % 100) as f32,
        temperature,
    };
    let walkers: Vec<Walker> = (0..200).map(|i| walker(i, (i % 7) as f32 * 10.0)).collect();
    let kernel = KernelConfig::new(8);
    for options in [
        RunOptions::reference(),
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::threaded(kernel, 2),
    ] {
        let report = Runner::new(Heat { length: 32.0 }, grid.clone(), walkers.clone())
            .options(options.clone())
            .run(200, |frame, _, control| {
                if frame.step == 50 {
                    // A live input: a hot walker appears at step 60 (still open at 50).
                    let hot = walker(1000, 90.0);
                    control.input(60, Input::Spawn(hot)).expect("open");
                }
            })?;
        println!(
            "{:<9} hash {}  {} walkers",
            options.executor, report.hash, report.entities
        );
    }
    let options = VerifyOptions {
        steps: 60,
        schedules: 4,
        repeats: 2,
        ..Default::default()
    };
    let report = verify(
        &VerifySetup::new(Heat { length: 32.0 }, grid, walkers),
        &options,
    );
    print!("{}", report.summary());
    assert!(report.passed());
    Ok(())
}
