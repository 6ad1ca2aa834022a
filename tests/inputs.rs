//! Input scripts (`soda run --inputs FILE`): spawn, remove, push and set-velocity at given
//! steps commit the same bits on every executor, survive checkpoint and resume, mean what
//! they say physically, and bad entries are refused naming the entry and the field.

mod cli_support;

use cli_support::{fails, hash_of, ok, soda};
use soda::prelude::*;
use soda::scene::{parse_inputs, SceneBuilder, SceneFormat};
use soda::{Body, RigidBodyModel};

const SCRIPT: &str = r#"
[[inputs]]
step = 30
action = "push"
id = 3
impulse = [0.0, 8.0, 2.0]
angular_impulse = [0.0, 0.0, 1.0]

[[inputs]]
step = 45
action = "spawn"
body = { id = 5000, shape = { type = "cuboid", half_extents = [0.5, 0.5, 0.5] }, position = [0.0, 9.0, 0.0] }

[[inputs]]
step = 60
action = "remove"
id = 7

[[inputs]]
step = 70
action = "set-velocity"
id = 5000
velocity = [1.0, 0.0, 0.0]
"#;

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn scripted_inputs_commit_the_same_hash_on_every_executor_and_after_resume() {
    let dir = tempfile::tempdir().unwrap();
    let script = write(&dir, "in.toml", SCRIPT);
    let base = [
        "run",
        "--objects",
        "300",
        "--steps",
        "100",
        "--inputs",
        &script,
    ];
    let reference = hash_of(&ok(&base));
    let untouched = hash_of(&ok(&["run", "--objects", "300", "--steps", "100"]));
    assert_ne!(reference, untouched, "the inputs changed the run");
    for executor in [
        vec!["--executor", "virtual", "--worlds", "5", "--mode", "world"],
        vec!["--executor", "virtual", "--mode", "conservative"],
        vec![
            "--executor",
            "virtual",
            "--partition",
            "random",
            "--schedule-seed",
            "4",
        ],
        vec!["--executor", "threaded", "--threads", "2", "--worlds", "3"],
    ] {
        let out = ok(&[&base[..], &executor[..]].concat());
        assert_eq!(hash_of(&out), reference, "{executor:?}");
    }
    // Stopped at step 40 (before every input but the push), resumed on threaded to 100:
    // the checkpoint carries the script, and the entries after step 40 still apply.
    let ckpt = dir.path().join("run.ckpt");
    ok(&[
        "run",
        "--objects",
        "300",
        "--steps",
        "40",
        "--inputs",
        &script,
        "--checkpoint",
        ckpt.to_str().unwrap(),
    ]);
    let resumed = ok(&[
        "resume",
        ckpt.to_str().unwrap(),
        "--steps",
        "100",
        "--executor",
        "threaded",
        "--threads",
        "2",
    ]);
    assert_eq!(hash_of(&resumed), reference);
}

#[test]
fn bad_input_scripts_are_refused_naming_the_entry_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &str)] = &[
        ("id = 3\n", "id = 99999\n", "inputs[0].id` = 99999"),
        ("step = 30", "step = 0", "step 0 is the initial state"),
        (
            "step = 70\naction = \"set-velocity\"\nid = 5000",
            "step = 45\naction = \"set-velocity\"\nid = 5000",
            "spawns the body at the same step",
        ),
        (
            "id = 7\n",
            "id = 7\nvelocity = [1.0, 0.0, 0.0]\n",
            "inputs[2].velocity",
        ),
        ("impulse = [0.0, 8.0, 2.0]\n", "", "needs `impulse`"),
        (
            "velocity = [1.0, 0.0, 0.0]",
            "velocity = [1000.0, 0.0, 0.0]",
            "max_speed",
        ),
        (
            "impulse = [0.0, 8.0, 2.0]",
            "impulse = [0.0, nan, 2.0]",
            "finite",
        ),
        // Beyond the caps (a huge push overflowed the rotation to NaN in the step).
        (
            "impulse = [0.0, 8.0, 2.0]",
            "impulse = [1e30, 8.0, 2.0]",
            "inputs[0].impulse` = [1e30, 8, 2] is invalid: would change body 3's speed",
        ),
        (
            "impulse = [0.0, 8.0, 2.0]",
            "impulse = [0.0, 8.0e19, 2.0]",
            "more than solver.max_speed = 30",
        ),
        (
            "angular_impulse = [0.0, 0.0, 1.0]",
            "angular_impulse = [0.0, 0.0, 1e30]",
            "inputs[0].angular_impulse",
        ),
        (
            "velocity = [1.0, 0.0, 0.0]",
            "velocity = [1.0, 0.0, 0.0]\nangular_velocity = [0.0, 1e30, 0.0]",
            "angular speed must not exceed 60 rad/s for this body: the larger of solver.max_angular_speed = 60",
        ),
        ("id = 5000, shape", "id = 5, shape", "must not be in use"),
        (
            "[0.5, 0.5, 0.5]",
            "[3.0, 0.5, 0.5]",
            "no bigger than the scene's largest",
        ),
        (
            "position = [0.0, 9.0, 0.0]",
            "position = [0.0, 900.0, 0.0]",
            "inside the domain",
        ),
        // Into the ground (a scene's body may overlap it by 1 mm at most; so may a spawn).
        (
            "position = [0.0, 9.0, 0.0]",
            "position = [0.0, 0.3, 0.0]",
            "inputs[1].body.position` = [0, 0.3, 0] is invalid: the body overlaps the static environment by 0.2000 m",
        ),
        (
            "action = \"remove\"",
            "action = \"explode\"",
            "unknown variant `explode`",
        ),
    ];
    for (from, to, expected) in cases {
        assert!(SCRIPT.contains(from), "{from}");
        let path = write(&dir, "bad.toml", &SCRIPT.replacen(from, to, 1));
        let err = fails(&["run", "--objects", "300", "--steps", "5", "--inputs", &path]);
        assert!(err.contains(expected), "{from} -> {to}: {err}");
        assert!(err.contains("bad.toml"), "names the file: {err}");
    }
    // A resumed run cannot be given inputs before its checkpoint: the script comes with it,
    // so only the library path can name a committed step; check that refusal there.
    let scene = SceneBuilder::new([-5.0; 3], [5.0; 3])
        .body_spec(ball(1, [0.0, 2.0, 0.0], [0.0; 3]))
        .build()
        .unwrap();
    let script = parse_inputs(
        "[[inputs]]\nstep = 3\naction = \"remove\"\nid = 1\n",
        SceneFormat::Toml,
        "script",
    )
    .unwrap();
    let err = script
        .to_inputs(&scene, "script", 10)
        .unwrap_err()
        .to_string();
    assert!(err.contains("must be 10 or more"), "{err}");
}

/// The committed state at `step` of `scene` with `inputs` on the executor of `options`.
fn state_at(
    scene: &soda::Scene,
    inputs: &[(u64, Input<Body>)],
    step: u64,
    options: RunOptions,
) -> Vec<Body> {
    let mut got: Vec<Body> = Vec::new();
    Runner::new(scene.model(), scene.grid(), scene.initial_bodies())
        .options(options)
        .inputs(inputs.to_vec())
        .states(StatesWanted::at(step))
        .run(step, |f, states, _| {
            if let (true, Some(s)) = (f.step == step, states) {
                got = s.iter().map(|b| (*b).clone()).collect();
            }
        })
        .unwrap();
    got
}

fn ball(id: u64, position: [f32; 3], velocity: [f32; 3]) -> soda::scene::BodySpec {
    soda::scene::BodySpec {
        id,
        shape: soda::Shape::Ball { radius: 0.5 },
        material: soda::physics::Material {
            density: 2.0,
            friction: 0.5,
            restitution: 0.0,
        },
        position,
        rotation: [0.3, 0.2, 0.1],
        velocity,
        angular_velocity: [0.0; 3],
    }
}

/// A push adds impulse / mass to the velocity and I⁻¹·L to the angular velocity, at its step,
/// on every executor; set-velocity sets it.
#[test]
fn push_changes_momentum_by_the_impulse_and_set_velocity_sets_it() {
    let scene = SceneBuilder::new([-20.0; 3], [20.0; 3])
        .gravity([0.0; 3])
        .body_spec(ball(1, [-3.0, 5.0, 0.0], [1.0, 0.0, 0.0]))
        .body_spec(ball(2, [3.0, 5.0, 0.0], [0.0, 0.5, 0.0]))
        .build()
        .unwrap();
    let script = parse_inputs(
        "[[inputs]]\nstep = 5\naction = \"push\"\nid = 1\nimpulse = [2.0, -1.0, 0.5]\n\
         angular_impulse = [0.0, 0.3, 0.0]\n\n[[inputs]]\nstep = 5\naction = \"set-velocity\"\n\
         id = 2\nvelocity = [0.0, 0.0, -2.0]\n",
        SceneFormat::Toml,
        "script",
    )
    .unwrap();
    let inputs = script.to_inputs(&scene, "script", 1).unwrap();
    let at = |step: u64, options: RunOptions| state_at(&scene, &inputs, step, options);
    let before = at(4, RunOptions::reference());
    let after = at(5, RunOptions::reference());
    let (b1, a1) = (&before[0], &after[0]);
    let mass = b1.mass();
    for k in 0..3 {
        let expected = b1.linvel[k] + [2.0, -1.0, 0.5][k] / mass;
        assert!(
            (a1.linvel[k] - expected).abs() < 1e-5,
            "axis {k}: {} vs {expected}",
            a1.linvel[k]
        );
    }
    let inertia = 0.4 * mass * 0.25; // a solid ball: I = 2/5 m r²
    assert!((a1.angvel.y - (b1.angvel.y + 0.3 / inertia)).abs() < 1e-4);
    assert_eq!(after[1].linvel, soda::math::Vec3::new(0.0, 0.0, -2.0));
    let hash = |bodies: &[Body]| soda::state::canonical_hash::<RigidBodyModel>(bodies.iter());
    let threaded = at(5, RunOptions::threaded(KernelConfig::new(2), 2));
    assert_eq!(hash(&threaded), hash(&after));
}

/// Entries after the run's last step are valid (a longer run applies them) but say so.
#[test]
fn inputs_after_the_last_step_are_named_in_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "late.toml", SCRIPT);
    let out = soda(&[
        "run",
        "--objects",
        "300",
        "--steps",
        "40",
        "--inputs",
        &path,
    ]);
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("3 of its inputs (the first: inputs[1] at step 45)")
            && err.contains("give --steps 70"),
        "{err}"
    );
}

fn cube(id: u64, y: f32) -> soda::scene::BodySpec {
    soda::scene::BodySpec {
        id,
        shape: soda::Shape::Cuboid {
            half_extents: [0.5; 3],
        },
        material: soda::physics::Material::default(),
        position: [0.0, y, 0.0],
        rotation: [0.0; 3],
        velocity: [0.0; 3],
        angular_velocity: [0.0; 3],
    }
}

/// Removing the bottom cube of a sleeping stack of three wakes the cube it carried, and that
/// one the cube above it: both fall and land a cube lower, on every executor with the same
/// bits. The removed cube is in the state of the removal's step (marked as leaving) and gone
/// from the next. Before, a `remove` woke nothing and the stack stayed in mid-air.
#[test]
fn removing_a_support_wakes_what_rested_on_it_and_it_falls() {
    let scene = SceneBuilder::new([-4.0, 0.0, -4.0], [4.0, 8.0, 4.0])
        .ground(Some(0.0))
        .body_spec(cube(1, 0.5))
        .body_spec(cube(2, 1.5))
        .body_spec(cube(3, 2.5))
        .build()
        .unwrap();
    let sleep_steps = scene.solver.sleep_steps;
    let script = parse_inputs(
        "[[inputs]]\nstep = 150\naction = \"remove\"\nid = 1\n",
        SceneFormat::Toml,
        "script",
    )
    .unwrap();
    let inputs = script.to_inputs(&scene, "script", 1).unwrap();
    let at = |step: u64, options: RunOptions| state_at(&scene, &inputs, step, options);
    let before = at(149, RunOptions::reference());
    assert_eq!(before.len(), 3);
    assert!(
        before
            .iter()
            .all(|b| u32::from(b.rest_steps) == sleep_steps),
        "the stack is asleep before the removal: {before:?}"
    );
    let removing = at(150, RunOptions::reference());
    assert_eq!(removing.len(), 3, "the removed cube is in its step's state");
    assert!(removing[0].is_leaving() && !removing[1].is_leaving());
    let after = at(151, RunOptions::reference());
    assert_eq!(after.iter().map(|b| b.id()).collect::<Vec<_>>(), [2, 3]);
    assert_eq!(after[0].rest_steps, 0, "the cube it carried woke");
    let end = at(330, RunOptions::reference());
    for (b, y) in end.iter().zip([0.5f32, 1.5]) {
        assert!(
            (b.position.y - y).abs() < 0.02,
            "body {} rests at y = {}, expected {y}",
            b.id(),
            b.position.y
        );
    }
    let hash = |bodies: &[Body]| soda::state::canonical_hash::<RigidBodyModel>(bodies.iter());
    for options in [
        RunOptions::threaded(KernelConfig::new(2), 2),
        RunOptions::virtual_exec(KernelConfig::new(4).mode(RollbackMode::Cell)),
        RunOptions::virtual_exec(KernelConfig::new(3).mode(RollbackMode::World)),
    ] {
        assert_eq!(hash(&at(330, options)), hash(&end));
    }
}

/// A body removed at a step is still in that step's state, so spawning its id again at
/// the same step, or removing a body spawned at that step, is refused naming the entry.
#[test]
fn a_removal_and_a_spawn_of_one_id_at_one_step_are_refused() {
    let scene = SceneBuilder::new([-4.0, 0.0, -4.0], [4.0, 8.0, 4.0])
        .body_spec(cube(1, 0.5))
        .build()
        .unwrap();
    let spawn = "[[inputs]]\nstep = 5\naction = \"spawn\"\nbody = { id = 1, shape = { type = \"ball\", radius = 0.3 }, position = [2.0, 3.0, 0.0] }\n";
    let remove = "[[inputs]]\nstep = 5\naction = \"remove\"\nid = 1\n";
    for (text, expected) in [
        (
            format!("{remove}\n{spawn}"),
            "inputs[1].step` = 5 is invalid: inputs[0] removes body 1 at the same step",
        ),
        (
            format!(
                "{}\n{}",
                spawn.replace("id = 1,", "id = 9,"),
                remove.replace("id = 1", "id = 9")
            ),
            "inputs[1].step` = 5 is invalid: inputs[0] spawns the body at the same step",
        ),
    ] {
        let script = parse_inputs(&text, SceneFormat::Toml, "script").unwrap();
        let err = script
            .to_inputs(&scene, "script", 1)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{err}");
    }
}

/// A script whose only entry sets a spin is held to the body's spin cap as a script with a
/// push is: the bodies' shapes were gathered only for pushes, so a `set-velocity` alone
/// went unchecked, and 1e20 rad/s made the orientation NaN in the step (a panic).
#[test]
fn a_set_velocity_alone_is_held_to_the_spin_cap() {
    let scene = SceneBuilder::new([-5.0; 3], [5.0; 3])
        .body_spec(ball(0, [0.0, 2.0, 0.0], [0.0; 3]))
        .build()
        .unwrap();
    for spin in ["1e20", "1000.0"] {
        let text = format!(
            "[[inputs]]\nstep = 5\naction = \"set-velocity\"\nid = 0\nvelocity = [0.0, 0.0, 0.0]\nangular_velocity = [{spin}, 0.0, 0.0]\n"
        );
        let script = parse_inputs(&text, SceneFormat::Toml, "spin.toml").unwrap();
        let err = script
            .to_inputs(&scene, "spin.toml", 0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("inputs[0].angular_velocity")
                && err.contains("angular speed must not exceed"),
            "{spin}: {err}"
        );
    }
    let ok = parse_inputs(
        "[[inputs]]\nstep = 5\naction = \"set-velocity\"\nid = 0\nvelocity = [0.0, 0.0, 0.0]\nangular_velocity = [10.0, 0.0, 0.0]\n",
        SceneFormat::Toml,
        "spin.toml",
    )
    .unwrap();
    assert!(ok.to_inputs(&scene, "spin.toml", 0).is_ok());
}
