//! Reference hash sequences of every built-in scene at a small size, pinned with insta.
//! A physics change shows up as a reviewed snapshot diff (`cargo insta review`); in CI
//! (`CI=true`) a missing or changed snapshot fails.

use soda::hash::hex;
use soda::scene::builtin::{builtin, BUILTINS};
use soda::sim::Simulation;

/// Small sizes that still exercise contacts, and the steps to run.
fn size(name: &str) -> usize {
    match name {
        "falling-cubes" => 27,
        "sparse-gas" => 27,
        "dense-pile" => 32,
        "skewed" => 27,
        _ => 12,
    }
}

const STEPS: u64 = 150;

#[test]
fn reference_hashes_of_builtin_scenes_match_snapshots() {
    for b in BUILTINS {
        let scene = builtin(b.name, Some(size(b.name)), 7).unwrap();
        let mut sim = Simulation::new(scene);
        let mut lines = vec![format!("scene {} objects {} seed 7", b.name, size(b.name))];
        for _ in 0..STEPS {
            let f = sim.step();
            if f.step % 10 == 0 || f.step == STEPS {
                lines.push(format!(
                    "step {:4} bodies {:3} hash {}",
                    f.step,
                    f.bodies,
                    hex(f.hash)
                ));
            }
        }
        insta::assert_snapshot!(b.name.to_string(), lines.join("\n"));
    }
}
