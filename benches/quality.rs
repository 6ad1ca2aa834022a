//! Physics quality side by side: SODA's reference run against the newest Rapier (0.36,
//! `rapier3d_new`, single-threaded, its default integration parameters with the scene's `dt`)
//! on the same bodies (issue 23). Five scenes:
//!
//! - `elastic-gas`: 512 frictionless balls (r 0.3 m, restitution 1) with random velocities
//!   (±3 m/s per axis) in a closed box, no gravity, 1,000 steps: kinetic energy drift;
//! - `cluster-collision`: two clusters of 27 balls and boxes meeting head-on at ±3 m/s in free
//!   space (restitution 0.3, friction 0.5), 300 steps: momentum error over Σ m·|v|, kinetic
//!   energy kept;
//! - `rolling-ball`: a ball (r 0.2 m) rolling at 0.1 m/s on the ground (friction 0.5), 600
//!   steps: final over initial speed;
//! - `gas-settling`: 512 balls (r 0.3 m, restitution 0.5, friction 0.5) with random velocities
//!   falling into a walled box under gravity, 600 steps: final kinetic energy, max speed, exact
//!   max penetration;
//! - `cube-pile`: `falling-cubes` (`QUALITY_PILE` cubes, default 1,000), 600 steps: max speed,
//!   exact max penetration, highest centre (benches/vs_rapier.rs compares the pile's speed).
//!
//! Static surfaces in Rapier: fixed cuboids (1 m thick) outside the domain's faces, with the
//! scene's friction and restitution; friction and restitution combine by average in both
//! engines. Only stepping is timed. Energies are computed by the same code for both engines
//! (SODA's `Body::kinetic_energy` on bodies rebuilt from Rapier's state).
//!
//! Then `settling-sweep` (benches/common/settling_sweep.rs): one settling scene is a lottery,
//! so `QUALITY_SEEDS` (default 8) random mixed piles (150 balls and boxes), ball piles (225
//! balls of random radii and densities; both as the physics-law tests' piles) and ball gases
//! under gravity (`gas-settling` with other seeds), 1,800 steps each: the largest rise of kinetic + potential energy after 5 s, and how many are still
//! moving at 10 s and at 30 s, worst and median over the seeds, per engine.
//!
//! `cargo bench --bench quality` prints a markdown table (and writes target/quality.json);
//! without `--bench` it runs a 20-step smoke version. `QUALITY_CASES=gas-settling,cube-pile`
//! runs only those scenes, `QUALITY_ENGINES=soda` (or `rapier`) only that engine, and
//! `QUALITY_SCENES=DIR` also writes each scene as `DIR/NAME.json`, for `soda run --scene`.

#[allow(dead_code)]
mod common;
// Only `insert_body`: the bodies go into Rapier as in the speed benches.
#[path = "common/knobs.rs"]
#[allow(dead_code)]
mod knobs;
#[allow(dead_code)]
#[path = "common/rapier_world.rs"]
mod rapier_world;

use common::{measure_pile, Footprint, PileBody};
#[path = "common/settling_sweep.rs"]
mod settling_sweep;
// The physics-law tests' random scenes: the bench measures the same scenes.
#[path = "../tests/physics_support/mod.rs"]
mod physics_support;
use physics_support::{ball_pile, mixed_pile};
use rapier3d_new::math::Vector;
use rapier3d_new::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyHandle};
use rapier_world::insert_body;
use serde::Serialize;
use settling_sweep::{summary, SettlingRun, SettlingTrack};
use soda::physics::{Body, Material, Shape};
use soda::scene::builtin::builtin;
use soda::scene::{BodySpec, Scene, SceneBuilder};
use soda::sim::Simulation;
use soda::RigidBodyModel;
use std::time::Instant;

/// One engine's figures on one scene.
#[derive(Clone, Debug, Serialize)]
struct Figures {
    engine: &'static str,
    wall_seconds: f64,
    /// Scene-specific measures, in the order of the scene's columns.
    values: Vec<(String, f64)>,
}

/// The bodies of a final (or initial) state as SODA bodies, whatever engine produced them.
type State = Vec<Body>;

fn kinetic(s: &State) -> f64 {
    soda::physics::metrics::kinetic_energy(s.iter())
}

fn momentum(s: &State) -> [f64; 3] {
    let mut p = [0.0; 3];
    for b in s {
        for (k, pk) in p.iter_mut().enumerate() {
            *pk += b.mass() as f64 * b.linvel[k] as f64;
        }
    }
    p
}

fn pile(s: &State) -> Vec<PileBody> {
    s.iter().map(PileBody::from_soda).collect()
}

/// Called with the step number and the bodies after every step (the settling sweep's measure);
/// building that state is inside the timed loop.
type Observer<'a> = Option<&'a mut dyn FnMut(u64, &State)>;

fn soda_state(sim: &Simulation) -> State {
    sim.state()
        .sorted::<RigidBodyModel>()
        .into_iter()
        .cloned()
        .collect()
}

/// Runs `scene` in SODA for `steps` steps: wall time, states at step 0 and at the end;
/// `observe` sees the state after every step (its time is counted).
fn run_soda(scene: &Scene, steps: u64, mut observe: Observer) -> (f64, State, State) {
    let mut sim = Simulation::new(scene.clone());
    let first = scene.initial_bodies();
    let start = Instant::now();
    for step in 1..=steps {
        sim.step();
        if let Some(f) = observe.as_mut() {
            f(step, &soda_state(&sim));
        }
    }
    let wall = start.elapsed().as_secs_f64();
    (wall, first, soda_state(&sim))
}

/// Runs `scene` in Rapier 0.36 for `steps` steps: wall time, states at step 0 and at the end;
/// `observe` as for [`run_soda`].
fn run_rapier(scene: &Scene, steps: u64, mut observe: Observer) -> (f64, State, State) {
    let mut w = PhysicsWorld::new();
    w.gravity = Vector::new(scene.gravity[0], scene.gravity[1], scene.gravity[2]);
    w.integration_parameters.dt = scene.dt;
    let env = &scene.environment;
    let (lo, hi) = (scene.domain.min, scene.domain.max);
    let mid = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let half = [0, 1, 2].map(|k| 0.5 * (hi[k] - lo[k]) + 2.0);
    let mut fixed = |centre: [f32; 3], h: [f32; 3]| {
        w.insert_collider(
            ColliderBuilder::cuboid(h[0], h[1], h[2])
                .translation(Vector::new(centre[0], centre[1], centre[2]))
                .friction(env.friction)
                .restitution(env.restitution),
            None,
        );
    };
    if let Some(y) = env.ground {
        let wide = half[0].max(half[2]).max(50.0);
        fixed([mid[0], y - 1.0, mid[2]], [wide, 1.0, wide]);
    }
    if env.walls {
        fixed([lo[0] - 1.0, mid[1], mid[2]], [1.0, half[1], half[2]]);
        fixed([hi[0] + 1.0, mid[1], mid[2]], [1.0, half[1], half[2]]);
        fixed([mid[0], mid[1], lo[2] - 1.0], [half[0], half[1], 1.0]);
        fixed([mid[0], mid[1], hi[2] + 1.0], [half[0], half[1], 1.0]);
    }
    if env.ceiling {
        fixed([mid[0], hi[1] + 1.0, mid[2]], [half[0], 1.0, half[2]]);
    }
    let first = scene.initial_bodies();
    let handles: Vec<RigidBodyHandle> = first.iter().map(|b| insert_body(&mut w, b)).collect();
    let state = |w: &PhysicsWorld| -> State {
        handles
            .iter()
            .zip(&first)
            .map(|(&h, b)| {
                let rb = &w.bodies[h];
                let (t, q, lv, av) = (rb.translation(), *rb.rotation(), rb.linvel(), rb.angvel());
                let mut s = b.clone();
                s.position = soda::math::Vec3::new(t.x, t.y, t.z);
                s.rotation = soda::math::Quat::from_quaternion(nalgebra::Quaternion::new(
                    q.w, q.x, q.y, q.z,
                ));
                s.linvel = soda::math::Vec3::new(lv.x, lv.y, lv.z);
                s.angvel = soda::math::Vec3::new(av.x, av.y, av.z);
                s
            })
            .collect()
    };
    let start = Instant::now();
    for step in 1..=steps {
        w.step();
        if let Some(f) = observe.as_mut() {
            f(step, &state(&w));
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let last = state(&w);
    (wall, first, last)
}

/// The single-scene cases' ball box: [`physics_support::ball_box`] drawn with seed 23.
fn ball_box(restitution: f32, friction: f32, gravity: bool) -> Scene {
    physics_support::ball_box(23, restitution, friction, gravity)
}

/// Settling over seeds (`settling-sweep`, [`settling_sweep`]): `seeds` mixed piles, ball
/// piles and ball gases under gravity, `steps` steps each, in each wanted engine. Returns the
/// markdown rows.
fn settling_sweep(seeds: u64, steps: u64, engines: &[(&str, &'static str)]) -> String {
    type Run = fn(&Scene, u64, Observer) -> (f64, State, State);
    type Build = fn(u64) -> Scene;
    let gas: Build = |seed| physics_support::ball_box(seed, 0.5, 0.5, true);
    let kinds = [
        ("mixed piles (150 balls and boxes)", mixed_pile as Build),
        ("ball piles (225 balls)", ball_pile as Build),
        ("ball gas under gravity (512 balls)", gas),
    ];
    let mut table = String::from(
        "| scenes | seeds | steps | engine | wall s (sum) | settling |\n|---|---:|---:|---|---:|---|\n",
    );
    for (kind, build) in kinds {
        for &(key, engine) in engines {
            let run: Run = if key == "soda" { run_soda } else { run_rapier };
            let mut runs: Vec<SettlingRun> = Vec::new();
            let mut wall_sum = 0.0;
            for seed in 1..=seeds {
                let scene = build(seed);
                let ten_s = (10.0 / scene.dt).round() as u64;
                let five_s = (5.0 / scene.dt).round() as u64;
                let mut track = SettlingTrack::new(scene.gravity, five_s, ten_s);
                let (wall, _, _) = run(
                    &scene,
                    steps,
                    Some(&mut |step, state: &State| track.observe(step, state)),
                );
                wall_sum += wall;
                let r = track.finish();
                eprintln!(
                    "quality: settling-sweep {kind} seed {seed} {engine}: rise {:.5} J, kinetic {:.2e} J at 10 s, {:.2e} J at the end",
                    r.rise, r.kinetic_10s, r.kinetic_end
                );
                runs.push(r);
            }
            table += &format!(
                "| {kind} | {seeds} | {steps} | {engine} | {wall_sum:.2} | {} |\n",
                summary(&runs)
            );
        }
    }
    table
}

fn clusters() -> Scene {
    let mut b = SceneBuilder::new([-40.0; 3], [40.0; 3])
        .gravity([0.0; 3])
        .ground(None);
    let mut id = 0;
    for side in [-1.0f32, 1.0] {
        for k in 0..27 {
            let c = [k % 3, (k / 3) % 3, k / 9].map(|c| c as f32 - 1.0);
            let shape = if k % 2 == 0 {
                Shape::Ball { radius: 0.4 }
            } else {
                Shape::Cuboid {
                    half_extents: [0.35, 0.4, 0.3],
                }
            };
            b = b.body_spec(BodySpec {
                id,
                shape,
                material: Material {
                    density: 1.0,
                    friction: 0.5,
                    restitution: 0.3,
                },
                position: [side * (2.5 + c[0]) + 0.05 * c[1], c[1] + 0.1 * c[2], c[2]],
                rotation: [0.1 * c[0], 0.2 * c[1], 0.3 * c[2]],
                velocity: [-side * 3.0, 0.0, 0.0],
                angular_velocity: [0.0; 3],
            });
            id += 1;
        }
    }
    b.build().expect("the clusters build")
}

fn rolling_ball() -> Scene {
    SceneBuilder::new([-30.0, -1.0, -30.0], [30.0, 5.0, 30.0])
        .body_spec(BodySpec {
            id: 0,
            shape: Shape::Ball { radius: 0.2 },
            material: Material::default(),
            position: [0.0, 0.2, 0.0],
            rotation: [0.0; 3],
            velocity: [0.1, 0.0, 0.0],
            angular_velocity: [0.0, 0.0, -0.5],
        })
        .build()
        .expect("the rolling ball builds")
}

/// A scene, how long to run it, and its measures from the states at step 0 and at the end.
struct Case {
    name: &'static str,
    scene: Scene,
    steps: u64,
    measure: fn(&Scene, &State, &State) -> Vec<(String, f64)>,
}

fn energy_drift(_: &Scene, first: &State, last: &State) -> Vec<(String, f64)> {
    let spin = last
        .iter()
        .map(|b| b.angvel.norm() as f64)
        .fold(0.0, f64::max);
    vec![
        (
            "kinetic energy drift %".into(),
            100.0 * (kinetic(last) / kinetic(first) - 1.0),
        ),
        ("max spin rad/s".into(), spin),
    ]
}

fn momentum_error(_: &Scene, first: &State, last: &State) -> Vec<(String, f64)> {
    let (p0, p1) = (momentum(first), momentum(last));
    let scale: f64 = first
        .iter()
        .map(|b| b.mass() as f64 * b.linvel.norm() as f64)
        .sum();
    let err = ((p1[0] - p0[0]).powi(2) + (p1[1] - p0[1]).powi(2) + (p1[2] - p0[2]).powi(2)).sqrt();
    vec![
        ("momentum error / Σ m·speed".into(), err / scale),
        (
            "kinetic energy kept %".into(),
            100.0 * kinetic(last) / kinetic(first),
        ),
    ]
}

fn rolling(_: &Scene, first: &State, last: &State) -> Vec<(String, f64)> {
    vec![(
        "final / initial speed".into(),
        (last[0].linvel.norm() / first[0].linvel.norm()) as f64,
    )]
}

fn settled(scene: &Scene, first: &State, last: &State) -> Vec<(String, f64)> {
    let ground = scene.environment.ground.unwrap_or(f32::NEG_INFINITY);
    let m = measure_pile(&pile(last), ground, &Footprint::of(first));
    vec![
        ("kinetic energy J".into(), kinetic(last)),
        ("max speed m/s".into(), m.max_speed as f64),
        ("max penetration m".into(), m.max_penetration as f64),
        ("highest centre m".into(), m.highest_centre as f64),
        ("bodies".into(), last.len() as f64),
    ]
}

fn main() {
    let quick = knobs::quick();
    let steps = |n: u64| if quick { 20 } else { n };
    let pile_n = knobs::env("QUALITY_PILE", 1000, 125) as usize;
    let cases = vec![
        Case {
            name: "elastic-gas",
            scene: ball_box(1.0, 0.0, false),
            steps: steps(1000),
            measure: energy_drift,
        },
        Case {
            name: "cluster-collision",
            scene: clusters(),
            steps: steps(300),
            measure: momentum_error,
        },
        Case {
            name: "rolling-ball",
            scene: rolling_ball(),
            steps: steps(600),
            measure: rolling,
        },
        Case {
            name: "gas-settling",
            scene: ball_box(0.5, 0.5, true),
            steps: steps(600),
            measure: settled,
        },
        Case {
            name: "cube-pile",
            scene: builtin("falling-cubes", Some(pile_n), 0).expect("falling-cubes builds"),
            steps: steps(600),
            measure: settled,
        },
    ];
    let wanted_cases = knobs::list("QUALITY_CASES");
    let wanted_engines = knobs::list("QUALITY_ENGINES");
    for w in wanted_cases.iter().flatten() {
        assert!(
            w == "settling-sweep" || cases.iter().any(|c| c.name == w),
            "QUALITY_CASES: {w:?} is not one of {:?}",
            cases.iter().map(|c| c.name).collect::<Vec<_>>()
        );
    }
    for w in wanted_engines.iter().flatten() {
        assert!(
            w == "soda" || w == "rapier",
            "QUALITY_ENGINES: {w:?} is not `soda` or `rapier`"
        );
    }
    let cases: Vec<Case> = cases
        .into_iter()
        .filter(|c| {
            wanted_cases
                .as_ref()
                .is_none_or(|w| w.iter().any(|n| n == c.name))
        })
        .collect();
    if let Some(dir) = std::env::var_os("QUALITY_SCENES") {
        let dir = std::path::PathBuf::from(dir);
        for case in &cases {
            let path = dir.join(format!("{}.json", case.name));
            let text = soda::scene::SceneFormat::Json
                .render(&case.scene)
                .expect("a built scene renders");
            std::fs::write(&path, text)
                .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
            eprintln!("quality: scene written to {}", path.display());
        }
    }
    let mut rows = Vec::new();
    let mut table =
        String::from("| scene | steps | engine | wall s | measures |\n|---|---:|---|---:|---|\n");
    for case in &cases {
        let mut figures = Vec::new();
        for (key, engine, run) in [
            (
                "soda",
                "SODA",
                run_soda as fn(&Scene, u64, Observer) -> (f64, State, State),
            ),
            ("rapier", "Rapier 0.36", run_rapier),
        ] {
            if wanted_engines
                .as_ref()
                .is_some_and(|w| !w.iter().any(|n| n == key))
            {
                continue;
            }
            let (wall, first, last) = run(&case.scene, case.steps, None);
            let values = (case.measure)(&case.scene, &first, &last);
            eprintln!("quality: {} {engine}: {wall:.3} s, {values:?}", case.name);
            let shown: Vec<String> = values
                .iter()
                .map(|(k, x)| format!("{k} {}", fmt(*x)))
                .collect();
            table += &format!(
                "| {} | {} | {engine} | {wall:.3} | {} |\n",
                case.name,
                case.steps,
                shown.join("; ")
            );
            figures.push(Figures {
                engine,
                wall_seconds: wall,
                values,
            });
        }
        rows.push(serde_json::json!({"scene": case.name, "steps": case.steps, "figures": figures}));
    }
    println!("\n{table}");
    if wanted_cases
        .as_ref()
        .is_none_or(|w| w.iter().any(|n| n == "settling-sweep"))
    {
        let engines: Vec<(&str, &'static str)> = [("soda", "SODA"), ("rapier", "Rapier 0.36")]
            .into_iter()
            .filter(|(key, _)| {
                wanted_engines
                    .as_ref()
                    .is_none_or(|w| w.iter().any(|n| n == key))
            })
            .collect();
        let seeds = knobs::env("QUALITY_SEEDS", 8, 1);
        let sweep = settling_sweep(seeds, steps(1800), &engines);
        println!("{sweep}");
        table += "\n";
        table += &sweep;
    }
    if !quick {
        let path = std::env::var_os("CARGO_TARGET_DIR")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target"))
            .join("quality.json");
        let json = serde_json::json!({"rows": rows, "table_markdown": table});
        std::fs::write(
            &path,
            serde_json::to_string_pretty(&json).expect("serialises"),
        )
        .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        println!("written to {}", path.display());
    }
}

/// Four significant digits, plain.
fn fmt(x: f64) -> String {
    if x == 0.0 || (x.abs() >= 1e-3 && x.abs() < 1e5) {
        format!("{x:.4}")
    } else {
        format!("{x:.3e}")
    }
}
